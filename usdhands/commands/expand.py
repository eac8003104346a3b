"""``usdhands expand IN --model MODEL.json -o OUT``: rebuild a full hand from its controlling curves.

Reads the finger curves the model names from IN, keeps the free (controlling) curves,
sets the constants and rebuilds every dependent curve as ``scale * controlling +
offset``; writes the result into a copy of IN. Applied to the animation ``usdhands reduce
-o`` wrote, it reproduces it; applied to a clip where an animator keyed only the
controlling curves, it fills in the rest.
"""

from __future__ import annotations

import sys
from pathlib import Path

from usdhands.commands._common import add_layer_argument, print_json


def register(sub) -> None:
    p = sub.add_parser("expand", help="rebuild every finger curve from the controlling curves of a reduction model",
                       description="Rebuild the constant and dependent finger curves of a clip from its "
                                   "controlling curves, with a model written by 'usdhands reduce --model'.")
    p.add_argument("file", type=Path, help="input animation (.usd/.usda/.usdc/.usdz, .gltf/.glb, .bvh)")
    p.add_argument("--model", type=Path, required=True, help="reduction model JSON from 'usdhands reduce --model'")
    p.add_argument("-o", "--output", type=Path, required=True, help="output file (same format as the input)")
    add_layer_argument(p)
    p.add_argument("--animation", default=None, help="animation name or index in the file (default the first)")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=run)


def run(args) -> int:
    from usdhands.jobs.expansion import ExpandOptions, expand

    result = expand(args.file, args.model, args.output, ExpandOptions(animation=args.animation, as_layer=args.layer))
    for note in result.notes:
        print(f"usdhands: note: {note}", file=sys.stderr)
    if args.json:
        print_json(result.to_json())
    else:
        print(f"{args.file}: rebuilt {result.dependent} dependent curves from "
              f"{len(result.controlling)} controlling curves and set {result.constants} constants "
              f"({result.free} of {result.curves} curves kept as keyed), {result.frames} frames")
        print(f"wrote {result.output}")
    return 0

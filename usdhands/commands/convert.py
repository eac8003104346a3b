"""``usdhands convert IN -o OUT [--animation NAME] [--json]``: between USD, glTF and BVH.

The output may also be given as a second positional argument (``convert IN OUT``), as in
earlier versions, so existing scripts keep working. The work is the convert job
(:func:`usdhands.jobs.conversion.convert`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from usdhands.commands._common import print_json
from usdhands.errors import UsdHandsError


def register(sub) -> None:
    p = sub.add_parser("convert", help="convert between USD, glTF and BVH",
                       description="Convert a skeleton, its animations and (USD<->glTF) skinned meshes "
                                   "between USD, glTF and BVH. Units and up axis are converted to the "
                                   "target's conventions (glTF: metres, +Y; BVH: centimetres, +Y; USD "
                                   "keeps the source's). BVH files carry no unit: --bvh-units says which "
                                   "one a BVH input is in and which one a BVH output is written in.")
    p.add_argument("input", type=Path, help="input file (.usd*, .gltf/.glb, .bvh)")
    p.add_argument("output_positional", type=Path, nargs="?", default=None, metavar="OUT",
                   help="output file; the same as -o OUT (kept for existing scripts)")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="output file; its extension chooses the format")
    p.add_argument("--animation", default=None,
                   help="only this animation (name or 0-based index); default: all (BVH: the first)")
    p.add_argument("--fps", type=float, default=None, help="resample animations to this rate")
    p.add_argument("--bvh-units", type=_bvh_units, default="cm", metavar="UNIT",
                   help="unit of the numbers of a BVH input or output: cm (default), m, mm, dm, in, ft")
    p.add_argument("--json", action="store_true", help="print what was written as JSON")
    p.set_defaults(func=run)


def _bvh_units(text: str) -> str:
    """A --bvh-units value; the BVH module (and its imports) is loaded only when the option is given."""
    from usdhands.jobs.conversion import BVH_UNITS

    if text not in BVH_UNITS:
        raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from {', '.join(BVH_UNITS)})")
    return text


def _output(args) -> Path:
    """The output from -o OUT or the positional OUT (one of them, or both the same)."""
    given = [p for p in (args.output, args.output_positional) if p is not None]
    if not given:
        raise UsdHandsError("no output file given (-o OUT)")
    if len(given) == 2 and given[0] != given[1]:
        raise UsdHandsError(f"two outputs given: -o {given[0]} and {given[1]}; give one")
    return given[0]


def run(args) -> int:
    from usdhands.jobs.conversion import ConvertOptions, convert

    output = _output(args)
    result = convert(args.input, output, ConvertOptions(args.animation, args.fps, args.bvh_units))
    if args.json:
        print_json({"input": str(args.input), **result.to_json()})
        return 0
    for note in result.notes:
        print(f"usdhands: {note}", file=sys.stderr)
    print(f"wrote {result.output}: {len(result.skeletons)} skeleton(s), {len(result.animations)} animation(s), "
          f"{result.meshes} mesh(es)", file=sys.stderr)
    return 0

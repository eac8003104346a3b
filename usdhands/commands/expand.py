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

from usdhands.commands._common import print_json
from usdhands.commands._output import MAIN_INPUT, add_layer_argument, check_paths, layer_options
from usdhands.errors import JointMismatchError, UsdHandsError


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


def model_joints(model) -> list[str]:
    """The joints a model's curves belong to, in curve order (``"LeftHandIndex2.y"`` → ``LeftHandIndex2``)."""
    joints: list[str] = []
    for c in model.curves:
        j = c.rsplit(".", 1)[0]
        if j not in joints:
            joints.append(j)
    return joints


def _names(items: list[str], most: int = 6) -> str:
    return ", ".join(items[:most]) + (f", ... ({len(items)} in all)" if len(items) > most else "")


def _without_joints(model, absent: list[str], args):
    """The model without the curves of joints the file lacks; an error when a controlling curve is among them."""
    gone = {c for c in model.curves if c.rsplit(".", 1)[0] in absent}
    if len(gone) == len(model.curves):
        raise JointMismatchError(f"none of the joints of the reduction model {args.model.name} is in the file "
                                 f"(the model has {_names(absent)})", path=args.file)
    lost = [r for r in model.relations if r.controlling in gone and r.dependent not in gone]
    if lost:
        ctrl = [j for j in absent if any(r.controlling.rsplit(".", 1)[0] == j for r in lost)]
        raise JointMismatchError(f"controlling joint{'s' if len(ctrl) > 1 else ''} {_names(ctrl)} of the reduction "
                                 f"model {args.model.name} {'are' if len(ctrl) > 1 else 'is'} not in the file "
                                 f"(needed to rebuild {_names([r.dependent for r in lost])})", path=args.file)
    print(f"usdhands: note: joints of the reduction model {args.model.name} that {args.file.name} lacks are "
          f"skipped: {_names(absent)}", file=sys.stderr)
    return model.subset(c for c in model.curves if c not in gone)


def run(args) -> int:
    from usdhands.algorithms.reduction.reduce import curve_names, expand_clip
    from usdhands.algorithms.reduction.model import ReductionModel
    from usdhands.formats.io import read_clip, write_clip

    check_paths({MAIN_INPUT: args.file, "--model": args.model}, {"-o": args.output})
    write_opts = layer_options(args.layer, args.file, args.output)
    model = ReductionModel.load(args.model)
    clip = read_clip(args.file, animation=args.animation)
    joints, absent = [], []
    for name in model_joints(model):
        try:
            joints.append(clip.skeleton.index(name))
        except KeyError:
            absent.append(name)
    if absent:
        model = _without_joints(model, absent, args)
        joints = [clip.skeleton.index(name) for name in model_joints(model)]
    names = set(curve_names(clip.skeleton, joints, model.order))
    missing = [c for c in model.curves if c not in names]
    if missing:  # only when the model's axis letters do not match its Euler order
        raise UsdHandsError(f"curves {missing[:3]} of the model do not match its Euler order {model.order}",
                            path=args.model)
    from usdhands.model.provenance import provenance_record

    record = provenance_record("reduction", database=args.model, parameters={
        "controlling": list(model.controlling_curves), "curves": len(model.curves)})
    out = write_clip(args.file, expand_clip(clip, joints, model), args.output, provenance=record, **write_opts)
    summary = {
        "file": str(args.file), "model": str(args.model), "output": str(out),
        "frames": int(clip.num_frames), "curves": len(model.curves),
        "controlling": list(model.controlling_curves), "free": len(model.free_curves),
        "dependent": len(model.relations), "constants": len(model.constants),
    }
    if args.json:
        print_json(summary)
    else:
        print(f"{args.file}: rebuilt {len(model.relations)} dependent curves from "
              f"{len(model.controlling_curves)} controlling curves and set {len(model.constants)} constants "
              f"({len(model.free_curves)} of {len(model.curves)} curves kept as keyed), {clip.num_frames} frames")
        print(f"wrote {out}")
    return 0

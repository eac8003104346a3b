"""``usdhands expand IN --model MODEL.json -o OUT``: rebuild a full hand from its controlling curves.

Reads the finger curves the model names from IN, keeps the free (controlling) curves,
sets the constants and rebuilds every dependent curve as ``scale * controlling +
offset``; writes the result into a copy of IN. Applied to the animation ``usdhands reduce
-o`` wrote, it reproduces it; applied to a clip where an animator keyed only the
controlling curves, it fills in the rest.
"""

from __future__ import annotations

from pathlib import Path

from usdhands.commands._common import print_json
from usdhands.errors import JointMismatchError, UsdHandsError


def register(sub) -> None:
    p = sub.add_parser("expand", help="rebuild every finger curve from the controlling curves of a reduction model",
                       description="Rebuild the constant and dependent finger curves of a clip from its "
                                   "controlling curves, with a model written by 'usdhands reduce --model'.")
    p.add_argument("file", type=Path, help="input animation (.usd/.usda/.usdc/.usdz, .gltf/.glb, .bvh)")
    p.add_argument("--model", type=Path, required=True, help="reduction model JSON from 'usdhands reduce --model'")
    p.add_argument("-o", "--output", type=Path, required=True, help="output file (same format as the input)")
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


def run(args) -> int:
    from usdhands.algorithms.reduction import continuous_euler_curves
    from usdhands.algorithms.reduction_model import ReductionModel
    from usdhands.formats.io import read_clip, write_clip
    from usdhands.model.finger_dofs import apply_finger_curves, finger_curves

    model = ReductionModel.load(args.model)
    clip = read_clip(args.file, animation=args.animation)
    joints = []
    for name in model_joints(model):
        try:
            joints.append(clip.skeleton.index(name))
        except KeyError:
            raise JointMismatchError(f"joint {name!r} of the reduction model {args.model.name} is not in the file",
                                     path=args.file) from None
    curves = finger_curves(clip, joints, model.order)
    curves = curves.with_values(continuous_euler_curves(curves.values))  # as 'reduce' reads them
    missing = [c for c in model.curves if c not in set(curves.names)]
    if missing:  # only when the model's axis letters do not match its Euler order
        raise UsdHandsError(f"curves {missing[:3]} of the model do not match its Euler order {model.order}",
                            path=args.model)
    rebuilt = model.apply(curves.values, curves.names)
    out = write_clip(args.file, apply_finger_curves(clip, curves.with_values(rebuilt)), args.output)
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

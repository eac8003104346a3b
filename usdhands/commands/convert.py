"""``usdhands convert IN OUT [--animation NAME]``: between USD, glTF and BVH."""

from __future__ import annotations

import logging
import sys
from dataclasses import replace
from pathlib import Path

from usdhands.commands._common import check_fps
from usdhands.commands._output import MAIN_INPUT, check_paths
from usdhands.errors import AssetReadError, NoSkeletonError
from usdhands.formats.bvh import UNITS, units_to_meters
from usdhands.formats.io import read_asset, write_asset
from usdhands.formats.registry import check_output_path, handler_for
from usdhands.model.asset import Asset
from usdhands.model.units import asset_to

_log = logging.getLogger(__name__)

# what each target format is defined in: (metres per unit, up axis); None keeps the source's
TARGET_CONVENTIONS = {
    "gltf": (1.0, "Y"),
    "bvh": (0.01, "Y"),
    "usd": (None, None),
}


def register(sub) -> None:
    p = sub.add_parser("convert", help="convert between USD, glTF and BVH",
                       description="Convert a skeleton, its animations and (USD<->glTF) skinned meshes "
                                   "between USD, glTF and BVH. Units and up axis are converted to the "
                                   "target's conventions (glTF: metres, +Y; BVH: centimetres, +Y; USD "
                                   "keeps the source's). BVH files carry no unit: --bvh-units says which "
                                   "one a BVH input is in and which one a BVH output is written in.")
    p.add_argument("input", type=Path)
    p.add_argument("output", type=Path)
    p.add_argument("--animation", default=None,
                   help="only this animation (name or 0-based index); default: all (BVH: the first)")
    p.add_argument("--fps", type=float, default=None, help="resample animations to this rate")
    p.add_argument("--bvh-units", choices=sorted(UNITS), default="cm",
                   help="unit of the numbers of a BVH input or output (default: cm)")
    p.set_defaults(func=run)


def convert(src: Path, dst: Path, animation: str | None = None, fps: float | None = None,
            bvh_units: str = "cm", notes: list[str] | None = None) -> Asset:
    """Read ``src``, convert units and axes to ``dst``'s format, write ``dst``; returns what was written.

    ``bvh_units`` is the unit of a BVH ``src`` (read with it) and of a BVH ``dst``
    (written in it): ``"cm"``, ``"m"``, ``"mm"``, ``"in"``, ... What the target cannot
    hold (BVH: one skeleton, one animation, no mesh) is left out, and a sentence saying
    what was taken and what was left is appended to ``notes`` when given.
    """
    check_output_path(dst, src)
    target = handler_for(dst, "write")
    source = handler_for(src, "read")
    asset = read_asset(src, fps=fps, **({"units": bvh_units} if source.name == "bvh" else {}))
    if not asset.skeletons:
        raise NoSkeletonError("no skeleton in file", path=src)
    if asset.left_out:
        _log.warning("%s: not converted (usdhands reads skeletons, animations and skinned meshes): %s",
                     src, "; ".join(asset.left_out))
    clips = asset.clips
    if animation is not None:
        try:
            clips = (asset.clip(animation),)
        except KeyError as e:
            raise AssetReadError(str(e.args[0]).split(": ", 1)[-1], path=src) from None
    if target.name == "bvh":
        if not clips:
            raise AssetReadError("BVH needs an animation and the file has none", path=src)
        taken = clips[0]
        left = [f"{len(clips) - 1} other animation(s)" if len(clips) > 1 else "",
                f"{len(asset.skeletons) - 1} other skeleton(s)" if len(asset.skeletons) > 1 else "",
                f"{len(asset.meshes)} mesh(es)" if asset.meshes else ""]
        left = [x for x in left if x]
        if left and notes is not None:
            hint = " (choose another with --animation)" if len(clips) > 1 or len(asset.skeletons) > 1 else ""
            notes.append(f"BVH holds one skeleton and one animation: took animation {taken.name!r} of skeleton "
                         f"{taken.skeleton.name!r}; left out {', '.join(left)}{hint}")
        asset = replace(asset, skeletons=(taken.skeleton,), clips=(taken,), meshes=())
    else:
        asset = replace(asset, clips=clips)
    mpu, up = TARGET_CONVENTIONS.get(target.name, (None, None))
    options = {}
    if target.name == "bvh":
        mpu = units_to_meters(bvh_units)
        options["units"] = bvh_units
    asset = asset_to(asset, mpu, up)
    write_asset(asset, dst, inputs=(src,), **options)
    return asset


def run(args) -> int:
    check_fps(args.fps)
    check_paths({MAIN_INPUT: args.input}, {"OUT": args.output})
    notes: list[str] = []
    asset = convert(args.input, args.output, args.animation, args.fps, args.bvh_units, notes)
    for note in notes:
        print(f"usdhands: {note}", file=sys.stderr)
    print(f"wrote {args.output}: {len(asset.skeletons)} skeleton(s), {len(asset.clips)} animation(s), "
          f"{len(asset.meshes)} mesh(es)", file=sys.stderr)
    return 0

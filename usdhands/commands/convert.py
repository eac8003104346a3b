"""``usdhands convert IN -o OUT [--animation NAME] [--json]``: between USD, glTF and BVH.

The output may also be given as a second positional argument (``convert IN OUT``), as in
earlier versions, so existing scripts keep working.
"""

from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import replace
from pathlib import Path

from usdhands.commands._common import check_fps, print_json
from usdhands.commands._output import MAIN_INPUT, check_paths
from usdhands.errors import AssetReadError, NoSkeletonError, UsdHandsError
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
    from usdhands.formats.bvh import UNITS

    if text not in UNITS:
        raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from {', '.join(sorted(UNITS))})")
    return text


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
        from usdhands.formats.bvh import units_to_meters

        mpu = units_to_meters(bvh_units)
        options["units"] = bvh_units
    asset = asset_to(asset, mpu, up)
    write_asset(asset, dst, inputs=(src,), **options)
    return asset


def run(args) -> int:
    check_fps(args.fps)
    output = _output(args)
    check_paths({MAIN_INPUT: args.input}, {"OUT": output})
    notes: list[str] = []
    asset = convert(args.input, output, args.animation, args.fps, args.bvh_units, notes)
    if args.json:
        print_json({"input": str(args.input), "output": str(output),
                    "skeletons": [sk.name for sk in asset.skeletons],
                    "animations": [{"name": c.name, "frames": int(c.num_frames), "fps": float(c.fps)}
                                   for c in asset.clips],
                    "meshes": len(asset.meshes), "notes": notes})
        return 0
    for note in notes:
        print(f"usdhands: {note}", file=sys.stderr)
    print(f"wrote {output}: {len(asset.skeletons)} skeleton(s), {len(asset.clips)} animation(s), "
          f"{len(asset.meshes)} mesh(es)", file=sys.stderr)
    return 0


def _output(args) -> Path:
    """The output from -o OUT or the positional OUT (one of them, or both the same)."""
    given = [p for p in (args.output, args.output_positional) if p is not None]
    if not given:
        raise UsdHandsError("no output file given (-o OUT)")
    if len(given) == 2 and given[0] != given[1]:
        raise UsdHandsError(f"two outputs given: -o {given[0]} and {given[1]}; give one")
    return given[0]

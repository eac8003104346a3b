"""``usdhands convert IN OUT [--animation NAME]``: between USD, glTF and BVH."""

from __future__ import annotations

import sys
from pathlib import Path

from usdhands.errors import AssetReadError, NoSkeletonError
from usdhands.formats.io import read_asset, write_asset
from usdhands.formats.registry import check_output_path, handler_for
from usdhands.model.asset import Asset
from usdhands.model.units import asset_to

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
                                   "keeps the source's).")
    p.add_argument("input", type=Path)
    p.add_argument("output", type=Path)
    p.add_argument("--animation", default=None,
                   help="only this animation (name or 0-based index); default: all (BVH: the first)")
    p.add_argument("--fps", type=float, default=None, help="resample animations to this rate")
    p.set_defaults(func=run)


def convert(src: Path, dst: Path, animation: str | None = None, fps: float | None = None) -> Asset:
    """Read ``src``, convert units and axes to ``dst``'s format, write ``dst``; returns what was written."""
    check_output_path(dst, src)
    target = handler_for(dst, "write")
    asset = read_asset(src, fps=fps)
    if not asset.skeletons:
        raise NoSkeletonError("no skeleton in file", path=src)
    clips = asset.clips
    if animation is not None:
        try:
            clips = (asset.clip(animation),)
        except KeyError as e:
            raise AssetReadError(str(e.args[0]).split(": ", 1)[-1], path=src) from None
    if target.name == "bvh":
        if not clips:
            raise AssetReadError("BVH needs an animation and the file has none", path=src)
        clips = clips[:1]
        skeletons = (clips[0].skeleton,)
        asset = Asset(asset.path, skeletons, clips, ())
    else:
        asset = Asset(asset.path, asset.skeletons, clips, asset.meshes)
    mpu, up = TARGET_CONVENTIONS.get(target.name, (None, None))
    asset = asset_to(asset, mpu, up)
    write_asset(asset, dst, inputs=(src,))
    return asset


def run(args) -> int:
    asset = convert(args.input, args.output, args.animation, args.fps)
    dropped = ""
    print(f"wrote {args.output}: {len(asset.skeletons)} skeleton(s), {len(asset.clips)} animation(s), "
          f"{len(asset.meshes)} mesh(es){dropped}", file=sys.stderr)
    return 0

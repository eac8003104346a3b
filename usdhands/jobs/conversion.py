"""The convert job: a skeleton, its animations and (USD<->glTF) skinned meshes between USD, glTF and BVH.

Units and up axis are converted to the target's conventions (glTF: metres, +Y; BVH: the
unit ``bvh_units`` names, +Y; USD keeps the source's). What the target cannot hold (BVH:
one skeleton, one animation, no mesh) is left out and said in ``result.notes``.

::

    import usdhands
    result = usdhands.convert("take.glb", "take.usda")
    print(result.animations, result.notes)
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from usdhands.errors import AssetReadError, NoSkeletonError
from usdhands.formats.bvh import UNITS
from usdhands.model.asset import Asset

_log = logging.getLogger(__name__)

#: the units a BVH file's numbers can be in (``ConvertOptions.bvh_units``)
BVH_UNITS = tuple(sorted(UNITS))

# what each target format is defined in: (metres per unit, up axis); None keeps the source's
TARGET_CONVENTIONS = {
    "gltf": (1.0, "Y"),
    "bvh": (0.01, "Y"),
    "usd": (None, None),
}



@dataclass(frozen=True)
class ConvertOptions:
    """Options of :func:`convert`; the defaults are the command line's.

    Attributes
    ----------
    animation : str or None
        Only this animation (name or 0-based index); None: all (BVH output: the first).
    fps : float or None
        Resample animations to this rate (frames per second, above 0 and at most 1000).
    bvh_units : str
        Unit of the numbers of a BVH input or output: ``"cm"``, ``"m"``, ``"mm"``, ``"in"``, ...
    """

    animation: str | None = None
    fps: float | None = None
    bvh_units: str = "cm"


@dataclass(frozen=True)
class ConvertResult:
    """What :func:`convert` wrote: the output, its skeletons (names), animations (``{"name", "frames",
    "fps"}``), the number of meshes, and notes on what was left out."""

    output: Path
    skeletons: tuple[str, ...]
    animations: tuple[dict, ...]
    meshes: int
    notes: tuple[str, ...] = ()

    def to_json(self) -> dict:
        """The ``usdhands convert --json`` report (without the input)."""
        return {"output": str(self.output), "skeletons": list(self.skeletons), "animations": list(self.animations),
                "meshes": self.meshes, "notes": list(self.notes)}


def convert(source: str | os.PathLike, output: str | os.PathLike, options: ConvertOptions = ConvertOptions(),
            progress: Callable[[int, int, str], None] | None = None) -> ConvertResult:
    """Convert ``source`` to the format of ``output``'s extension and write it (atomically).

    Raises
    ------
    UsdHandsError
        Unreadable input, no skeleton, an unknown animation, a bad frame rate or unit, an
        output equal to the input; nothing is written then.
    """
    from usdhands.jobs.option_checks import check_fps
    from usdhands.jobs.outputs import MAIN_INPUT, check_paths
    from usdhands.errors import UsdHandsError

    check_fps(options.fps)
    check_paths({MAIN_INPUT: source}, {"OUT": output})
    if options.bvh_units not in UNITS:
        raise UsdHandsError(f"unknown BVH unit {options.bvh_units!r}; expected one of {', '.join(sorted(UNITS))}")
    if progress:
        progress(0, 1, "converting")
    notes: list[str] = []
    asset = _convert_asset(Path(source), Path(output), options.animation, options.fps, options.bvh_units, notes)
    if progress:
        progress(1, 1, "done")
    return ConvertResult(Path(output), tuple(sk.name for sk in asset.skeletons),
                         tuple({"name": c.name, "frames": int(c.num_frames), "fps": float(c.fps)} for c in asset.clips),
                         len(asset.meshes), tuple(notes))


def _convert_asset(src: Path, dst: Path, animation: str | None = None, fps: float | None = None,
                   bvh_units: str = "cm", notes: list[str] | None = None) -> Asset:
    """Read ``src``, convert units and axes to ``dst``'s format, write ``dst``; returns what was written.

    ``bvh_units`` is the unit of a BVH ``src`` (read with it) and of a BVH ``dst``
    (written in it): ``"cm"``, ``"m"``, ``"mm"``, ``"in"``, ... What the target cannot
    hold (BVH: one skeleton, one animation, no mesh) is left out, and a sentence saying
    what was taken and what was left is appended to ``notes`` when given.
    """
    from usdhands.formats.bvh import units_to_meters
    from usdhands.formats.io import read_asset, write_asset
    from usdhands.formats.registry import check_output_path, handler_for
    from usdhands.model.units import asset_to

    check_output_path(dst, src)
    target = handler_for(dst, "write")
    source = handler_for(src, "read")
    asset = read_asset(src, fps=fps, **({"units": bvh_units} if source.name == "bvh" else {}))
    if not asset.skeletons:
        raise NoSkeletonError("no skeleton in file", path=src)
    if asset.left_out:
        _log.warning("%s: not converted (usdhands carries skeletons, animations, the meshes on them with their "
                     "materials and blend shapes): %s",
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



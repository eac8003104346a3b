"""Reading and writing any supported file by its extension."""

from __future__ import annotations

import contextlib
import math
import os
from pathlib import Path

from usdhands.errors import AssetReadError, NoSkeletonError
from usdhands.input_files import check_regular_file
from usdhands.formats.registry import atomic_output, check_output_path, handler_for, new_files_removed_on_failure
from usdhands.model.asset import Asset
from usdhands.model.clip import Clip

__all__ = ["read_asset", "read_clip", "write_asset", "write_clip"]


def read_asset(path: str | os.PathLike, *, fps: float | None = None, **options) -> Asset:
    """Read every skeleton, clip and skinned mesh of a file.

    Parameters
    ----------
    path : path-like
    fps : float, optional
        Resample animations to this rate (formats with free key times pick a rate
        of their own when omitted).
    **options
        Passed to the format's reader: BVH takes ``units`` (``"cm"`` by default,
        ``"m"``, ``"mm"``, ``"in"``, ... or metres per unit); USD and glTF take none
        (a TypeError names an unexpected one).

    Raises
    ------
    AssetReadError
        Missing file, a folder, a FIFO or device, unknown extension, corrupt content.
    """
    if fps is not None and not (fps > 0 and math.isfinite(fps)):
        raise ValueError(f"Expected fps > 0 and finite, got {fps}")
    path = check_regular_file(path)  # a named pipe blocked forever, /dev/zero ran out of memory
    asset = handler_for(path, "read").read(path, fps=fps, **options)
    for clip in asset.clips:
        clip.validate(str(path))
    return asset


def read_clip(path: str | os.PathLike, *, animation: str | int | None = None,
              fps: float | None = None, **options) -> Clip:
    """Read one animation (by name or index, default the first) of a file.

    ``options`` go to the format's reader as in :func:`read_asset` (BVH: ``units``).

    Raises
    ------
    NoSkeletonError
        The file holds no skeleton.
    AssetReadError
        No animation of that name, or the file cannot be read.
    """
    asset = read_asset(path, fps=fps, **options)
    if not asset.skeletons:
        raise NoSkeletonError("no skeleton in file", path=path)
    try:
        return asset.clip(animation)
    except KeyError as e:
        raise AssetReadError(str(e.args[0]).split(": ", 1)[-1], path=path) from None


def write_asset(asset: Asset, path: str | os.PathLike, *, inputs: tuple = (), **options) -> Path:
    """Write ``asset`` as a standalone file (atomically; never onto one of ``inputs``)."""
    path = check_output_path(path, asset.path, *inputs)
    handler = handler_for(path, "write")
    for clip in asset.clips:
        clip.validate(str(path))
    textures = contextlib.nullcontext()
    if asset.images and handler.name in ("usd", "gltf"):  # textures are placed relative to the final file
        options = {**options, "final_path": path}
        if handler.name == "usd":  # image files beside the output: gone with it when it fails
            from usdhands.formats.usd_materials import texture_folder

            textures = new_files_removed_on_failure(texture_folder(path))
    with textures, atomic_output(path) as tmp:
        handler.write(asset, tmp, **options)
    return path


def write_clip(source: str | os.PathLike, clip: Clip, path: str | os.PathLike, **options) -> Path:
    """Write ``source`` to ``path`` with ``clip``'s animation put into it.

    Everything else in the file is kept. ``source`` and ``path`` must have the same
    format (convert first otherwise). Options go to the handler (``animation``,
    ``as_layer`` for USD).
    """
    source = Path(source)
    path = check_output_path(path, source)
    handler = handler_for(path, "write")
    if handler is not handler_for(source, "read"):
        raise AssetReadError(f"cannot write {source.suffix} content as {path.suffix}; use 'usdhands convert' first",
                             path=path)
    clip.validate(str(path))  # a NaN compared as 'unchanged' and the source's keys were kept silently
    with atomic_output(path) as tmp:
        handler.write_clip(source, clip, tmp, final_path=path, **options)
    return path

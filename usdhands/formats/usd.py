"""USD (UsdSkel) format handler: ``.usd .usda .usdc .usdz`` in, ``.usd .usda .usdc`` out.

The reader is :mod:`usdhands.formats.usd_read`, the writers
:mod:`usdhands.formats.usd_write`; :mod:`usdhands.formats.usd_validate` checks written
files with USD's own validators. See ``docs/format-usd.md``.
"""

from __future__ import annotations

import os
from pathlib import Path

from usdhands.formats.usd_read import read_usd
from usdhands.formats.usd_write import write_usd, write_usd_clip
from usdhands.model.asset import Asset
from usdhands.model.clip import Clip

__all__ = ["HANDLER", "UsdHandler"]


class UsdHandler:
    """Reads and writes UsdSkel content (see the module docs of usd_read and usd_write)."""

    name = "usd"
    read_extensions = (".usd", ".usda", ".usdc", ".usdz")
    write_extensions = (".usd", ".usda", ".usdc")

    def read(self, path: Path, *, fps: float | None = None) -> Asset:
        """Every Skeleton, SkelAnimation and skinned Mesh of a file (:func:`read_usd`)."""
        return read_usd(path, fps=fps)

    def write(self, asset: Asset, path: Path, *, provenance: dict | None = None,
              final_path: str | os.PathLike | None = None, **options) -> None:
        """A standalone stage (:func:`write_usd`); ``provenance`` becomes every animation's
        ``UsdHandsFingerMotionAPI``; texture images go beside ``final_path``."""
        if options:
            raise TypeError(f"Unexpected options for USD write: {sorted(options)}")
        write_usd(asset, path, provenance=provenance, final_path=final_path)

    def write_clip(self, source: Path, clip: Clip, path: Path, *, final_path: str | os.PathLike | None = None,
                   animation: str | None = None, as_layer: bool = False, hand_map=None, provenance=None,
                   finger_motion=None, **options) -> None:
        """``source`` with ``clip`` put into its animation (:func:`write_usd_clip`); ``provenance``
        (``finger_motion`` is its older name) becomes the animation's ``UsdHandsFingerMotionAPI``."""
        if options:
            raise TypeError(f"Unexpected options for USD write_clip: {sorted(options)}")
        write_usd_clip(source, clip, path, final_path=final_path, animation=animation, as_layer=as_layer,
                       hand_map=hand_map, finger_motion=provenance if provenance is not None else finger_motion)


HANDLER = UsdHandler()

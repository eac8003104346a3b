"""glTF 2.0 (``.gltf``, ``.glb``): the format handler of the registry.

Reading is in :mod:`.gltf_read`, writing in :mod:`.gltf_write`, the container
(GLB chunks, buffers, typed accessors) in :mod:`.gltf_container`. See
docs/format-gltf.md for what is read and written and the decisions taken.
"""

from __future__ import annotations

import os
from pathlib import Path

from usdhands.formats.gltf_read import read_gltf
from usdhands.formats.gltf_write import write_clip_gltf, write_gltf
from usdhands.model.asset import Asset
from usdhands.model.clip import Clip

__all__ = ["GltfHandler", "HANDLER"]


class GltfHandler:
    """Reads and writes glTF 2.0 files (JSON with external or data-URI buffers, and GLB)."""

    name = "gltf"
    read_extensions = (".gltf", ".glb")
    write_extensions = (".gltf", ".glb")

    def read(self, path: str | os.PathLike, *, fps: float | None = None) -> Asset:
        """Skeletons (one per group of skins sharing joints), clips and skinned meshes.

        Parameters
        ----------
        fps : float, optional
            Sample animations at this rate; by default one found from the key times
            (30, 24, 25, 60, ... fps when the keys sit on that grid, else 30).
        """
        return read_gltf(Path(path), fps=fps)

    def write(self, asset: Asset, path: str | os.PathLike, **options) -> None:
        """A new file from ``asset`` (metres, +Y up); see :func:`.gltf_write.write_gltf`."""
        write_gltf(asset, path, **options)

    def write_clip(self, source: str | os.PathLike, clip: Clip, path: str | os.PathLike, *,
                   final_path: str | os.PathLike | None = None, animation: str | int | None = None,
                   **options) -> None:
        """``source`` with ``clip``'s channels put into one animation; see :func:`.gltf_write.write_clip_gltf`."""
        write_clip_gltf(source, clip, path, final_path=final_path, animation=animation, **options)


HANDLER = GltfHandler()

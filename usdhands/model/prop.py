"""A prop for interaction clips: a triangle mesh, and how it moves over time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usdhands.model.skeleton import readonly

__all__ = ["PropMesh"]


@dataclass(frozen=True, eq=False)
class PropMesh:
    """A rigid triangle mesh, in the units and up axis of the clip it is used with.

    Parameters
    ----------
    name : str
        The prop's name (the file stem, or the prim path in a USD file).
    vertices : (V, 3) float
        Positions in the prop's own frame, asset units of the clip.
    faces : (F, 3) int
        Triangles, indices into ``vertices``.
    times : (K,) float, optional
        Seconds of the keys of an animated prop, increasing; None for a static prop.
    xforms : (K, 4, 4) float, optional
        Prop-to-world transform at each key (column vectors, clip units); with ``times``.
        A static prop's transform is baked into ``vertices``.
    path : str
        The file it came from.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    times: np.ndarray | None = None
    xforms: np.ndarray | None = None
    path: str = ""

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=np.float64)
        f = np.asarray(self.faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"Expected vertices of shape (V, 3), got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"Expected faces of shape (F, 3), got {f.shape}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError("face indices out of range")
        object.__setattr__(self, "vertices", readonly(v))
        object.__setattr__(self, "faces", readonly(f, np.int64))
        if (self.times is None) != (self.xforms is None):
            raise ValueError("times and xforms go together")
        if self.times is not None:
            t = np.asarray(self.times, dtype=np.float64)
            x = np.asarray(self.xforms, dtype=np.float64)
            if t.ndim != 1 or x.shape != (len(t), 4, 4) or len(t) == 0:
                raise ValueError(f"Expected times (K,) and xforms (K, 4, 4), got {t.shape} and {x.shape}")
            if np.any(np.diff(t) <= 0):
                raise ValueError("prop key times must increase")
            object.__setattr__(self, "times", readonly(t))
            object.__setattr__(self, "xforms", readonly(x))

    @property
    def animated(self) -> bool:
        """Whether the prop moves (has keyed transforms)."""
        return self.times is not None

    def xforms_at(self, times: np.ndarray) -> np.ndarray:
        """Prop-to-world transforms ``(T, 4, 4)`` at ``times`` (seconds).

        Linear interpolation of the keyed matrices, re-orthonormalised; held before the
        first and after the last key. Identity for a static prop.
        """
        times = np.asarray(times, dtype=np.float64)
        if not self.animated:
            return np.broadcast_to(np.eye(4), (len(times), 4, 4)).copy()
        k = self.times
        if len(k) == 1:
            return np.broadcast_to(self.xforms[0], (len(times), 4, 4)).copy()
        i = np.clip(np.searchsorted(k, times, side="right") - 1, 0, len(k) - 2)
        w = np.clip((times - k[i]) / (k[i + 1] - k[i]), 0.0, 1.0)[:, None, None]
        m = self.xforms[i] * (1 - w) + self.xforms[i + 1] * w
        u, s, vt = np.linalg.svd(m[:, :3, :3])
        scale = s.mean(axis=1)[:, None, None]
        m[:, :3, :3] = (u @ vt) * scale
        return m

"""What fingers can touch: props (rigid meshes, static, animated or held) and the body.

Every collider answers one question, vectorised over (frame, point) pairs: the signed
distance from a point at a frame of the clip to its surface (negative inside), clip
units. A broad phase skips the exact query for points whose distance to the collider's
bounding box already exceeds what the caller cares about (``cutoff``); those get the
box distance, a lower bound, which is all a clearance test needs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usdhands.algorithms.interaction.proximity import MeshProximity
from usdhands.model.prop import PropMesh

__all__ = ["MeshCollider", "CapsuleCollider", "Colliders", "mesh_collider", "attached_xforms",
           "segment_distance"]


def _rigid_inverse(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse transforms ``(T, 4, 4)`` and the uniform scale ``(T,)`` of each."""
    inv = np.linalg.inv(m)
    scale = np.cbrt(np.abs(np.linalg.det(m[:, :3, :3])))
    return inv, scale


@dataclass(eq=False)
class MeshCollider:
    """A rigid mesh placed at every frame of a clip.

    Parameters
    ----------
    name : str
    proximity : MeshProximity
        Distances in the mesh's own frame.
    world : (T, 4, 4) float
        Mesh-to-world transform per clip frame (rigid, optionally uniformly scaled).
    """

    name: str
    proximity: MeshProximity
    world: np.ndarray

    def __post_init__(self) -> None:
        self.world = np.asarray(self.world, dtype=np.float64)
        self._inv, self._scale = _rigid_inverse(self.world)
        self._static = bool(np.all(self.world == self.world[:1]))
        self.exact_queries = 0  # points measured exactly so far (benchmarks count them)

    def frame_bounds(self) -> np.ndarray:
        """Axis-aligned world bounding box of the mesh at each frame, ``(T, 2, 3)``."""
        lo, hi = self.proximity.bounds
        corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        pts = np.einsum("tij,cj->tci", self.world, corners)[..., :3]
        return np.stack([pts.min(axis=1), pts.max(axis=1)], axis=1)

    def signed_distance(self, frames: np.ndarray, points: np.ndarray, cutoff: np.ndarray | float = np.inf) -> np.ndarray:
        """Signed distance ``(N,)`` from ``points`` ``(N, 3)`` at ``frames`` ``(N,)``, clip units.

        Points farther than ``cutoff`` from the bounding box get the box distance (a lower bound).
        """
        local, scale = self._local(frames, points)
        out = self.proximity.bbox_distance(local) * scale
        near = out < cutoff
        if near.any():
            out[near] = self.proximity.signed_distance(local[near]) * scale[near]
            self.exact_queries += int(near.sum())
        return out

    def within(self, frames: np.ndarray, points: np.ndarray, r: float) -> np.ndarray:
        """Whether the signed distance of each of ``points`` ``(N, 3)`` at ``frames`` ``(N,)`` is below ``r``
        (clip units), ``(N,)`` bool: ``signed_distance(frames, points, r) < r``, the same answers, measuring
        exactly only the points that neither the box distance (a lower bound) nor the distance to a few
        of the mesh's vertices (an upper bound, :meth:`MeshProximity.upper_distance`) decides."""
        local, scale = self._local(frames, points)
        out = np.zeros(len(local), dtype=bool)
        idx = np.nonzero(self.proximity.bbox_distance(local) * scale < r)[0]
        if len(idx):
            # by a relative 1e-9 short of r: the exact query's rounding cannot fall on the other side
            sure = self.proximity.upper_distance(local[idx]) * scale[idx] < r - 1e-9 * abs(r)
            out[idx[sure]] = True
            ask = idx[~sure]
            if len(ask):
                out[ask] = self.proximity.signed_distance(local[ask]) * scale[ask] < r
                self.exact_queries += len(ask)
        return out

    def _local(self, frames: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``points`` ``(N, 3)`` at ``frames`` ``(N,)`` in the mesh's frame and each one's scale ``(N,)``."""
        frames = np.asarray(frames, dtype=np.int64)
        p = np.asarray(points, dtype=np.float64)
        if self._static:
            inv, scale = self._inv[0], self._scale[0]
            return p @ inv[:3, :3].T + inv[:3, 3], np.full(len(p), scale)
        inv = self._inv[frames]
        return np.einsum("nij,nj->ni", inv[:, :3, :3], p) + inv[:, :3, 3], self._scale[frames]


def segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from ``points`` ``(..., 3)`` to segments ``a``-``b`` ``(..., 3)`` (broadcast)."""
    ab = b - a
    t = np.einsum("...i,...i->...", points - a, ab) / np.maximum(np.einsum("...i,...i->...", ab, ab), 1e-30)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(points - (a + t[..., None] * ab), axis=-1)


@dataclass(eq=False)
class CapsuleCollider:
    """Capsules that move with the skeleton (the body: torso, head, upper arms, thighs).

    Parameters
    ----------
    name : str
    a, b : (T, K, 3) float
        Axis end points of the K capsules at each frame, clip units.
    radii : (K,) float
        Radii, clip units.
    parts : tuple of str, optional
        What each capsule is (``"torso"``, ``"left upper arm"``, ...).
    """

    name: str
    a: np.ndarray
    b: np.ndarray
    radii: np.ndarray
    parts: tuple = ()

    def without(self, parts) -> "CapsuleCollider | None":
        """These capsules but the ``parts`` named (None when nothing is left)."""
        keep = [k for k in range(len(self.radii)) if k >= len(self.parts) or self.parts[k] not in parts]
        if len(keep) == len(self.radii):
            return self
        if not keep:
            return None
        return CapsuleCollider(self.name, self.a[:, keep], self.b[:, keep], self.radii[keep],
                               tuple(self.parts[k] for k in keep))

    def signed_distance(self, frames: np.ndarray, points: np.ndarray, cutoff: np.ndarray | float = np.inf) -> np.ndarray:
        """Signed distance ``(N,)`` to the union of the capsules (exact for one capsule, a lower bound
        of the union's inside depth otherwise), clip units."""
        frames = np.asarray(frames, dtype=np.int64)
        p = np.asarray(points, dtype=np.float64)[:, None, :]
        d = segment_distance(p, self.a[frames], self.b[frames]) - self.radii
        return d.min(axis=1)

    def frame_bounds(self) -> np.ndarray:
        """Axis-aligned world bounding box of the capsules at each frame, ``(T, 2, 3)``."""
        r = float(np.max(self.radii))
        pts = np.concatenate([self.a, self.b], axis=1)
        return np.stack([pts.min(axis=1) - r, pts.max(axis=1) + r], axis=1)


class Colliders:
    """Several colliders as one: the signed distance to the nearest."""

    def __init__(self, colliders: list):
        self.items = list(colliders)

    def __len__(self) -> int:
        return len(self.items)

    def signed_distance(self, frames: np.ndarray, points: np.ndarray, cutoff: np.ndarray | float = np.inf) -> np.ndarray:
        """Signed distance ``(N,)`` to the nearest collider (lower bounds beyond ``cutoff``)."""
        out = np.full(len(points), np.inf)
        for c in self.items:
            out = np.minimum(out, c.signed_distance(frames, points, cutoff))
        return out

    def within(self, frames: np.ndarray, points: np.ndarray, r: float) -> np.ndarray:
        """Whether each of ``points`` ``(N, 3)`` at ``frames`` ``(N,)`` is nearer than ``r`` to some collider
        (signed distance below ``r``, clip units), ``(N,)`` bool: ``signed_distance(frames, points, r) < r``."""
        frames, points = np.asarray(frames, dtype=np.int64), np.asarray(points, dtype=np.float64)
        out = np.zeros(len(points), dtype=bool)
        for c in self.items:
            rest = np.nonzero(~out)[0]
            if len(rest) == 0:
                break
            f, p = frames[rest], points[rest]
            out[rest] = c.within(f, p, r) if hasattr(c, "within") else c.signed_distance(f, p, r) < r
        return out

    def without_parts(self, parts) -> "Colliders":
        """The same colliders without the body capsules named in ``parts`` (``CapsuleCollider.parts``)."""
        items = [c.without(parts) if isinstance(c, CapsuleCollider) else c for c in self.items]
        if all(c is d for c, d in zip(items, self.items)):
            return self
        return Colliders([c for c in items if c is not None])

    def bbox_gap(self, frames: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Distance ``(N,)`` from boxes ``lo``-``hi`` ``(N, 3)`` at ``frames`` ``(N,)`` to the nearest collider's box."""
        out = np.full(len(lo), np.inf)
        for c in self.items:
            if not hasattr(c, "_bounds"):
                c._bounds = c.frame_bounds()
            b = c._bounds[np.asarray(frames, dtype=np.int64)]
            gap = np.maximum(0.0, np.maximum(b[:, 0] - hi, lo - b[:, 1]))
            out = np.minimum(out, np.linalg.norm(gap, axis=-1))
        return out


def attached_xforms(prop_world: np.ndarray, joint_world: np.ndarray, start: int, stop: int) -> np.ndarray:
    """Prop-to-world transforms ``(T, 4, 4)`` of a prop held by a joint from ``start`` to ``stop``.

    Before ``start`` the prop is where its file puts it; from ``start`` to ``stop``
    (inclusive) it keeps the offset to the joint it had at ``start``; after ``stop`` it
    stays where it was left.

    Parameters
    ----------
    prop_world : (T, 4, 4) float
        The prop's own transforms per frame.
    joint_world : (T, 4, 4) float
        The holding joint's world transforms per frame.
    start, stop : int
        Frame range held, ``0 <= start <= stop < T``.
    """
    out = np.array(prop_world, dtype=np.float64)
    offset = np.linalg.inv(joint_world[start]) @ prop_world[start]
    out[start:stop + 1] = joint_world[start:stop + 1] @ offset
    out[stop + 1:] = out[stop]
    return out


def mesh_collider(prop: PropMesh, times: np.ndarray, world: np.ndarray | None = None,
                  proximity: MeshProximity | None = None) -> MeshCollider:
    """A collider for ``prop`` at each of the clip's frame ``times`` (seconds).

    ``world`` ``(T, 4, 4)`` overrides the prop's own motion (an attached prop); ``proximity``: the
    prop's :class:`MeshProximity` when the caller has built it already (the same prop at another rate).
    """
    prox = MeshProximity(prop.vertices, prop.faces) if proximity is None else proximity
    xf = prop.xforms_at(times) if world is None else np.asarray(world, dtype=np.float64)
    return MeshCollider(prop.name, prox, xf)

"""Exact signed distance from points to a triangle mesh, built once per prop.

Choice (measured on the 24,544-triangle ``mug.obj``, 100k points within 2 cm of its
surface, one core of this machine): libigl's ``AABB.squared_distance`` 2.5 µs per point
plus ``FastWindingNumberBVH.winding_number`` 2.1 µs per point (4.7 µs, exact distances,
the sign from the generalised winding number, so it stays right on meshes with holes),
against trimesh's ``proximity.signed_distance`` 380 µs per point (and a wrong sign near
holes). A trilinear distance grid is faster per query but approximate (mm errors at
usable cell sizes) and slow to build finely; open3d is a 1 GB install. trimesh remains
the loader and the reference the tests hold this against.

Sign convention: **negative inside**, positive outside (trimesh's is the opposite).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MeshProximity"]


class MeshProximity:
    """Signed distances to one triangle mesh.

    Parameters
    ----------
    vertices : (V, 3) float
        Positions, any units (distances come back in the same units).
    faces : (F, 3) int
        Triangles.

    Notes
    -----
    Inside is where the winding number exceeds 0.5: right for closed meshes, and the
    sensible answer for meshes with small holes (the teapot's 96 open edges).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        import igl

        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3 or len(self.faces) == 0:
            raise ValueError(f"Expected vertices (V, 3) and at least one face, got {self.vertices.shape}, "
                             f"{self.faces.shape}")
        self._tree = igl.AABB()
        self._tree.init(self.vertices, self.faces)
        self._winding = igl.FastWindingNumberBVH()
        self._winding.init(self.vertices, self.faces, 2)
        self.bounds = np.array([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Unsigned distance ``(N,)`` from each of ``points`` ``(N, 3)`` to the surface."""
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0)
        d2, _, _ = self._tree.squared_distance(self.vertices, self.faces, p)
        return np.sqrt(np.maximum(d2, 0.0))

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Whether each of ``points`` ``(N, 3)`` is inside (winding number above 0.5), ``(N,)`` bool."""
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if len(p) == 0:
            return np.zeros(0, dtype=bool)
        return self._winding.winding_number(p) > 0.5

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance ``(N,)``: negative inside, positive outside, mesh units."""
        d = self.distance(points)
        return np.where(self.inside(points), -d, d)

    def bbox_distance(self, points: np.ndarray) -> np.ndarray:
        """A lower bound on :meth:`distance`: the distance to the mesh's bounding box ``(N,)`` (0 inside it)."""
        p = np.asarray(points, dtype=np.float64)
        gap = np.maximum(0.0, np.maximum(self.bounds[0] - p, p - self.bounds[1]))
        return np.linalg.norm(gap, axis=-1)

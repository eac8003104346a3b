"""Exact signed distance from points to a triangle mesh, built once per prop.

Choice (measured on the 24,544-triangle ``mug.obj``, 100k points within 2 cm of its
surface, one core of this machine): libigl's ``AABB.squared_distance`` 2.5 µs per point
plus ``FastWindingNumberBVH.winding_number`` 2.1 µs per point (4.7 µs, exact distances,
the sign from the generalised winding number, so it stays right on meshes with holes),
against trimesh's ``proximity.signed_distance`` 380 µs per point (and a wrong sign near
holes). A trilinear distance grid is faster per query but approximate (mm errors at
usable cell sizes) and slow to build finely; open3d is a 1 GB install. trimesh remains
the loader and the reference the tests hold this against.

Where the package's compiled module was built, its own tree takes the nearest points instead of
libigl's (``TriangleTree``: exact too; 0.88 µs a query against libigl's 1.74 on the 51,720 queries
of a ``synthesize --props`` of the 60 s benchmark clip), because libigl's module imports SciPy's
sparse module (about 0.1 s of a fresh process) and a closed shell needs nothing else of it. The
winding number of open shells, and of the rare point a closed shell's side tests leave, is
libigl's.

The sign: a closed shell's from the side of its nearest face (free); open shells' from the
fast winding number (see :class:`MeshProximity`). Convention: **negative inside**,
positive outside (trimesh's is the opposite).
"""

from __future__ import annotations

import numpy as np

from usdhands.jit import kernels_running

__all__ = ["MeshProximity"]


def _shells(faces: np.ndarray, n_vertices: int) -> list[np.ndarray]:
    """Face indices of each connected shell (faces sharing vertices), in order of each shell's first face,
    each in increasing order.

    The components of the vertices joined by the faces' edges (a face's vertices are one component,
    and faces sharing a vertex share it), each face labelled by its first vertex's: the same shells
    as the components of faces joined by shared vertices, without that graph's ``F x F`` product
    (5.9 -> 0.9 ms on the mug)."""
    built = _compiled_geometry()
    if built is not None:  # union-find, compiled ahead of time: no SciPy to import
        vertex_labels = built.vertex_components(np.ascontiguousarray(faces, dtype=np.int64), n_vertices)
    else:
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        a = faces.reshape(-1)
        b = faces[:, [1, 2, 0]].reshape(-1)
        graph = coo_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(n_vertices, n_vertices)).tocsr()
        _, vertex_labels = connected_components(graph, directed=False)
    labels = vertex_labels[faces[:, 0]]
    found, first = np.unique(labels, return_index=True)
    rank = np.empty(int(found.max(initial=-1)) + 1, dtype=np.int64)
    rank[found[np.argsort(first, kind="stable")]] = np.arange(len(found))  # shells in order of their first face
    labels = rank[labels]
    order = np.argsort(labels, kind="stable")
    return np.split(order, np.cumsum(np.bincount(labels, minlength=len(found)))[:-1])


def _closed(faces: np.ndarray) -> bool:
    """Whether every edge is shared by exactly two faces, in opposite directions (a closed, oriented shell)."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).astype(np.int64)
    key = np.minimum(e[:, 0], e[:, 1]) * (int(e.max(initial=0)) + 1) + np.maximum(e[:, 0], e[:, 1])  # one int per edge
    _, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    if np.any(counts != 2):
        return False
    forward = (e[:, 0] < e[:, 1]).astype(int)
    per_edge = np.bincount(inv.reshape(-1), weights=forward, minlength=len(counts))
    return bool(np.all(per_edge == 1))


class _Part:
    """One closed shell (sign from the nearest face's side) or all open shells together (winding number)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, closed: bool):
        used = np.unique(faces)
        remap = np.full(len(vertices), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        self.vertices = np.ascontiguousarray(vertices[used])
        self.faces = np.ascontiguousarray(remap[faces])
        if closed and _signed_volume(self.vertices, self.faces) < 0:
            self.faces = np.ascontiguousarray(self.faces[:, ::-1])  # wound inward: the side test needs outward
        self.closed = closed
        self.bounds = np.array([self.vertices.min(axis=0), self.vertices.max(axis=0)])
        built = _compiled_geometry()
        self._tree = None
        if built is not None:  # compiled ahead of time: libigl (and SciPy, which it imports) stay unloaded
            self._tree = built.TriangleTree(self.vertices, self.faces)
        else:
            import igl

            self._igl = igl.AABB()
            self._igl.init(self.vertices, self.faces)
        self.winding = None
        self._fwn = None
        self._edges = None  # per face: first corner, edges, their dot products (the side test's, on first use)
        self._around = None  # per vertex, its faces' normals (the corner side test's, on first use)
        if not closed:
            import igl

            self.winding = igl.FastWindingNumberBVH()
            self.winding.init(self.vertices, self.faces, 2)
        tri = self.vertices[self.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area2 = np.linalg.norm(n, axis=1, keepdims=True)
        self.normals = n / np.maximum(area2, 1e-300)
        self.neighbours = _edge_neighbours(self.faces) if closed else None
        scale = float(np.abs(self.bounds).max(initial=1.0))
        self.flat = area2[:, 0] <= 1e-12 * scale * scale  # no usable normal

    def bbox_distance(self, p: np.ndarray) -> np.ndarray:
        gap = np.maximum(0.0, np.maximum(self.bounds[0] - p, p - self.bounds[1]))
        return np.linalg.norm(gap, axis=-1)

    def distance(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._tree is not None:  # the compiled tree orders a batch itself
            d2, face, closest = self._tree.squared_distance(p, SORT_FROM)
        elif len(p) < SORT_FROM:
            d2, face, closest = self._igl.squared_distance(self.vertices, self.faces, p)
        else:  # in Morton order (each point's answer is its own: the same values, fewer cache misses)
            order = morton_order(p, self.bounds)
            d2s, fs, cs = self._igl.squared_distance(self.vertices, self.faces, np.ascontiguousarray(p[order]))
            d2, face, closest = np.empty_like(d2s), np.empty_like(fs), np.empty_like(cs)
            d2[order], face[order], closest[order] = d2s, fs, cs
        return np.sqrt(np.maximum(d2, 0.0)), np.asarray(face, dtype=np.int64), closest

    def inside(self, p: np.ndarray) -> np.ndarray:
        if self.winding is not None:
            return self.winding.winding_number(p) > 0.5
        return self.signed_distance(p) < 0

    def signed_distance(self, p: np.ndarray) -> np.ndarray:
        d, face, closest = self.distance(p)
        if self.winding is not None:
            return np.where(self.winding.winding_number(p) > 0.5, -d, d)
        signs = _compiled_side_test()
        if signs is not None:  # the same test compiled
            out, rest = signs(p, closest, face, d, self.normals, self.vertices, self.faces, self.neighbours,
                              self.flat)
            if rest.any():
                out[rest] = np.where(self._undecided_inside(p[rest], face[rest], closest[rest], d[rest]),
                                     -d[rest], d[rest])
            return out
        return self._closed_signed(p, d, face, closest)

    def _closed_signed(self, p: np.ndarray, d: np.ndarray, face: np.ndarray, closest: np.ndarray) -> np.ndarray:
        """Signed distances on a closed shell from the nearest points, in NumPy."""
        # a closed shell: the point is inside iff it lies behind the nearest face, where the
        # nearest point is inside that face; on an edge its pseudonormal decides, at a vertex the
        # faces around it where they agree, and the fast winding number what is left
        diff = p - closest
        side = np.einsum("ij,ij->i", diff, self.normals[face])
        u, v, w = self._barycentric(closest, face)
        on0, on1, on2 = u <= 1e-6, v <= 1e-6, w <= 1e-6  # the nearest point on an edge or a corner
        count = on0.astype(np.int8) + on1 + on2
        decided = (count == 0) & (np.abs(side) > 1e-12 * (1.0 + d)) & ~self.flat[face]
        inside = side < 0
        # nearest on an edge's inside: the side of the edge's pseudonormal, the sum of its two faces'
        # normals, decides (Baerentzen and Aanaes 2005: exact for a closed, oriented manifold edge)
        edge = np.nonzero((count == 1) & (d > 0))[0]
        if len(edge):
            f = face[edge]
            g = self.neighbours[f, np.where(on0[edge], 0, np.where(on1[edge], 1, 2))]  # across that edge
            s = np.einsum("ij,ij->i", diff[edge], self.normals[f] + self.normals[g])
            sure = (np.abs(s) > 1e-12 * (1.0 + d[edge])) & ~self.flat[f] & ~self.flat[g]
            idx = edge[sure]
            decided[idx] = True
            inside[idx] = s[sure] < 0
        rest = ~decided & (d > 0)
        if rest.any():
            inside[rest] = self._undecided_inside(p[rest], face[rest], closest[rest], d[rest],
                                                  (u[rest], v[rest], w[rest]))
        return np.where(inside, -d, d)

    def _undecided_inside(self, p: np.ndarray, face: np.ndarray, closest: np.ndarray, d: np.ndarray,
                          bary: tuple | None = None) -> np.ndarray:
        """Whether each of the points ``p`` ``(N, 3)`` the side test left undecided is inside, ``(N,)`` bool: a
        point whose nearest point is a corner by the faces around that vertex where they agree
        (:meth:`_corner_sides`), every other by the winding number (:meth:`_parity`); ``bary``: the
        nearest points' barycentric coordinates ``(u, v, w)`` when the caller has them."""
        built = _compiled_geometry()
        if built is not None and bary is None:  # the same tests compiled, in one pass
            normals, pad, unusable = self._corners_around()
            inside, todo = built.undecided_sides(p, closest, face, d, self.vertices, self.faces, normals, pad, unusable)
            if todo.any():
                inside[todo] = self._parity(p[todo])
            return inside
        u, v, w = self._barycentric(closest, face) if bary is None else bary
        corner = ((u <= 1e-6).astype(np.int8) + (v <= 1e-6) + (w <= 1e-6)) >= 2
        inside = np.zeros(len(p), dtype=bool)
        todo = ~corner
        if corner.any():
            k = np.nonzero(corner)[0]
            uk, vk, wk = u[k], v[k], w[k]
            slot = np.where(uk >= vk, np.where(uk >= wk, 0, 2), np.where(vk >= wk, 1, 2))  # the corner it is at
            sure, behind = self._corner_sides(p[k], closest[k], d[k], self.faces[face[k], slot])
            inside[k] = behind
            todo[k[~sure]] = True
        if todo.any():
            inside[todo] = self._parity(p[todo])
        return inside

    def _corner_sides(self, p: np.ndarray, closest: np.ndarray, d: np.ndarray,
                      vertex: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points ``p`` ``(N, 3)`` whose nearest point ``closest`` is (within ``1e-6`` in barycentric
        coordinates) the shell's vertex ``vertex`` ``(N,)``: whether the faces around it decide the side
        and whether that side is inside, ``(N,)`` bool each.

        On a closed, outward-oriented shell, a direction from a vertex in front of the planes of every
        face around it (positive dot product with each normal) leaves the solid there, and one behind
        all of them enters it: the cone the solid fills at the vertex is bounded by those faces, and a
        direction inside that cone is behind the plane of the face it is nearest to. The segment from
        the nearest point to ``p`` crosses no surface, so ``p`` is on that side. The products are taken
        from the vertex itself and must clear, besides rounding, how far the nearest point lies from it
        (so the signs are those from the nearest point); faces without a usable normal, or faces that
        disagree, leave the point to the winding number.
        """
        normals, pad, unusable = self._corners_around()
        x = p - self.vertices[vertex]
        dots = np.einsum("nkj,nj->nk", normals[vertex], x)
        slack = (np.linalg.norm(closest - self.vertices[vertex], axis=1) + 1e-12 * (1.0 + d))[:, None]
        padded = pad[vertex]
        front = np.all((dots > slack) | padded, axis=1)
        behind = np.all((dots < -slack) | padded, axis=1)
        return (front | behind) & ~unusable[vertex], behind

    def _corners_around(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each vertex's faces' normals ``(V, W, 3)`` padded with zeros to the largest count ``W``, the padding
        ``(V, W)`` bool, and the vertices the corner test cannot use ``(V,)`` bool (a face around them
        without a usable normal, or no face); built on first use."""
        if self._around is None:
            # a zero normal's product, 0, is on no side: the padding is masked
            corners = self.faces.reshape(-1)
            order = np.argsort(corners, kind="stable")
            count = np.bincount(corners, minlength=len(self.vertices))
            rank = np.arange(len(order)) - np.repeat(np.cumsum(count) - count, count)
            width = max(int(count.max(initial=0)), 1)
            normals = np.zeros((len(self.vertices), width, 3))
            pad = np.ones((len(self.vertices), width), dtype=bool)
            normals[corners[order], rank] = self.normals[order // 3]
            pad[corners[order], rank] = False
            flat = np.bincount(corners, weights=np.repeat(self.flat, 3), minlength=len(self.vertices)) > 0
            self._around = (normals, pad, flat | (count == 0))
        return self._around

    def _barycentric(self, x: np.ndarray, face: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The columns of :func:`_barycentric` of points ``x`` ``(N, 3)`` in faces ``face`` ``(N,)``, from the
        faces' edges and their products computed once (the same values: the same operations, gathered)."""
        if self._edges is None:
            tri = self.vertices[self.faces]
            e0, e1 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
            d00, d01, d11 = (np.einsum("ij,ij->i", e0, e0), np.einsum("ij,ij->i", e0, e1),
                             np.einsum("ij,ij->i", e1, e1))
            self._edges = (tri[:, 0], e0, e1, d00, d01, d11, d00 * d11 - d01 * d01)
        corner, e0, e1, d00, d01, d11, den = (a[face] for a in self._edges)
        r = x - corner
        d20 = np.einsum("ij,ij->i", r, e0)
        d21 = np.einsum("ij,ij->i", r, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.where(den > 0, (d11 * d20 - d01 * d21) / den, -1.0)
            w = np.where(den > 0, (d00 * d21 - d01 * d20) / den, -1.0)
        return 1.0 - v - w, v, w

    def _parity(self, p: np.ndarray) -> np.ndarray:
        """Inside test by the fast winding number (its hierarchy built on first use), for the ambiguous points."""
        if self._fwn is None:
            import igl

            self._fwn = igl.FastWindingNumberBVH()
            self._fwn.init(self.vertices, self.faces, 2)
        return self._fwn.winding_number(np.ascontiguousarray(p)) > 0.5


def _compiled_geometry():
    """The interaction's module compiled ahead of time (its ``TriangleTree`` for the nearest points, its
    union-find for the shells, its corner side test), or None where it was not built: then libigl's
    ``AABB``, SciPy's ``connected_components`` and the NumPy corner test (the same distances to rounding,
    the same shells, the same sides)."""
    from usdhands.compiled import kernel_module

    return kernel_module("algorithms.interaction._interaction_compiled")


def _compiled_side_test():
    """The compiled twin of the closed-shell side test this process runs, or None for the NumPy test: the one
    compiled ahead of time where it was built (:mod:`usdhands.compiled`: nothing to start), else numba's
    (:mod:`._proximity_kernel`) where a kernel of the package already runs (:func:`usdhands.jit.kernels_running`)."""
    from usdhands.compiled import kernel_module

    built = kernel_module("algorithms.interaction._interaction_compiled")
    if built is not None:
        return built.closed_shell_signs
    if kernels_running():
        from usdhands.algorithms.interaction._proximity_kernel import closed_shell_signs

        return closed_shell_signs
    return None


#: Vertices :meth:`MeshProximity.upper_distance` measures to (evenly through the used vertices
#: order): on the mug, 64 put the benchmark's wrist within 1.1 cm of its true distance (the cut's reach is 30 cm).
UPPER_SAMPLES = 64

#: Batches of at least this many points are queried in Morton order (sorting costs less than the
#: tree's cache misses it saves: on the synthesize --props benchmark's 67,577 queries, 2.7 -> 2.2 µs each).
SORT_FROM = 64


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """The low 10 bits of each of ``v`` (int64) spread two zeros apart (for a 3-D Morton code)."""
    v = v & 0x3FF
    v = (v | (v << 16)) & 0x030000FF
    v = (v | (v << 8)) & 0x0300F00F
    v = (v | (v << 4)) & 0x030C30C3
    return (v | (v << 2)) & 0x09249249


def morton_order(p: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """The order ``(N,)`` of points ``p`` ``(N, 3)`` along the Z-order curve over ``bounds`` ``(2, 3)``
    (1,024 cells an axis; points outside take the nearest cell): neighbours in space come together."""
    lo, hi = bounds
    q = np.clip((p - lo) * (1023.0 / np.maximum(hi - lo, 1e-300)), 0.0, 1023.0).astype(np.int64)
    code = _spread_bits(q[:, 0]) | (_spread_bits(q[:, 1]) << 1) | (_spread_bits(q[:, 2]) << 2)
    return np.argsort(code, kind="stable")


def _signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by a closed shell, negative when its faces are wound inward."""
    t = vertices[faces]
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def _edge_neighbours(faces: np.ndarray) -> np.ndarray:
    """For each face and corner ``k``, the face across the edge opposite corner ``k``, ``(F, 3)``
    (every edge shared by exactly two faces: a closed shell)."""
    F = len(faces)
    a = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]]).astype(np.int64)  # edge opposite corner 0, 1, 2
    b = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]]).astype(np.int64)
    key = np.minimum(a, b) * (int(faces.max(initial=0)) + 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    pairs = order.reshape(-1, 2)  # each key exactly twice
    slot = np.empty(3 * F, dtype=np.int64)
    slot[pairs[:, 0]] = pairs[:, 1]
    slot[pairs[:, 1]] = pairs[:, 0]
    out = np.empty((F, 3), dtype=np.int64)
    out[:, 0], out[:, 1], out[:, 2] = slot[:F] % F, slot[F:2 * F] % F, slot[2 * F:] % F
    return out


def _barycentric(x: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentric coordinates ``(N, 3)`` of points ``x`` ``(N, 3)`` in triangles ``tri`` ``(N, 3, 3)``."""
    e0 = tri[:, 1] - tri[:, 0]
    e1 = tri[:, 2] - tri[:, 0]
    r = x - tri[:, 0]
    d00 = np.einsum("ij,ij->i", e0, e0)
    d01 = np.einsum("ij,ij->i", e0, e1)
    d11 = np.einsum("ij,ij->i", e1, e1)
    d20 = np.einsum("ij,ij->i", r, e0)
    d21 = np.einsum("ij,ij->i", r, e1)
    den = d00 * d11 - d01 * d01
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.where(den > 0, (d11 * d20 - d01 * d21) / den, -1.0)
        w = np.where(den > 0, (d00 * d21 - d01 * d20) / den, -1.0)
    return np.stack([1.0 - v - w, v, w], axis=1)


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
    The mesh is split into connected shells. Each closed, consistently oriented shell
    gets its own AABB tree and takes its sign from the side of the nearest face (free,
    and right for any closed shell); the open shells together get one tree and the
    sign from the fast winding number (inside where it exceeds 0.5), which is right on
    meshes with holes (the teapot's 96 open edges, its lid resting on an open body).
    The distance to the mesh is the least over the parts: exact outside, and negative
    inside any part (overlapping closed shells, the cup's handle entering its wall,
    count as inside). On the 192-triangle test cylinder the winding number alone cost
    24 µs per point; the side test, under 3.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3 or len(self.faces) == 0:
            raise ValueError(f"Expected vertices (V, 3) and at least one face, got {self.vertices.shape}, "
                             f"{self.faces.shape}")
        self.bounds = np.array([self.vertices.min(axis=0), self.vertices.max(axis=0)])
        self._samples = None  # the vertices :meth:`upper_distance` measures to (on first use)
        closed, open_ = [], []
        for shell in _shells(self.faces, len(self.vertices)):
            (closed if _closed(self.faces[shell]) else open_).append(shell)
        self.parts = [_Part(self.vertices, self.faces[s], True) for s in closed]
        if open_:
            self.parts.append(_Part(self.vertices, self.faces[np.concatenate(open_)], False))

    def _each(self, points: np.ndarray, fn) -> np.ndarray:
        p = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.full(len(p), np.inf)
        if len(p) == 0:
            return np.zeros(0)
        for part in self.parts:
            near = part.bbox_distance(p) < np.abs(out)
            if near.any():
                out[near] = np.minimum(out[near], fn(part, np.ascontiguousarray(p[near])))
        return out

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Unsigned distance ``(N,)`` from each of ``points`` ``(N, 3)`` to the surface."""
        return self._each(points, lambda part, q: part.distance(q)[0])

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance ``(N,)``: negative inside, positive outside, mesh units."""
        return self._each(points, lambda part, q: part.signed_distance(q))

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Whether each of ``points`` ``(N, 3)`` is inside, ``(N,)`` bool."""
        return self.signed_distance(points) < 0

    def upper_distance(self, points: np.ndarray) -> np.ndarray:
        """An upper bound on :meth:`distance` (and so on :meth:`signed_distance`): the distance from each of
        ``points`` ``(N, 3)`` to the nearest of :data:`UPPER_SAMPLES` vertices of the faces, ``(N,)`` mesh units."""
        if self._samples is None:
            used = np.unique(self.faces)  # vertices of no face are not on the surface
            self._samples = np.ascontiguousarray(
                self.vertices[used[np.unique(np.linspace(0, len(used) - 1, UPPER_SAMPLES).astype(np.int64))]])
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.full(len(p), np.inf)
        for s in self._samples:
            np.minimum(out, np.einsum("ij,ij->i", p - s, p - s), out=out)
        return np.sqrt(out)

    def bbox_distance(self, points: np.ndarray) -> np.ndarray:
        """A lower bound on :meth:`distance`: the distance to the mesh's bounding box ``(N,)`` (0 inside it)."""
        p = np.asarray(points, dtype=np.float64)
        gap = np.maximum(0.0, np.maximum(self.bounds[0] - p, p - self.bounds[1]))
        return np.linalg.norm(gap, axis=-1)

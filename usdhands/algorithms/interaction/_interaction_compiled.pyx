# cython: language_level=3, boundscheck=False, wraparound=False, initializedcheck=False, cdivision=True
"""The interaction's kernels of :mod:`._proximity_kernel` and :mod:`._recursion_kernel`, compiled ahead of time.

The same functions with the same arguments and the same results to the bit (see
:mod:`usdhands.compiled`: no fused multiply-adds, each sum in the numba kernel's order), so a
correction or ``synthesize --props`` in a process that never starts numba (one command, a batch
worker) runs them instead of their NumPy twins. Tests hold each to its numba twin.
"""

from libc.math cimport INFINITY, NAN, fabs, sqrt
from libc.stdint cimport int64_t

import numpy as np


cdef inline void _barycentric_of(const double* V, const int64_t* F, int64_t f, double x, double y, double z,
                                 double* out) noexcept nogil:
    """The barycentric coordinates ``(u, v, w)`` into ``out`` of point ``(x, y, z)`` in face ``f`` of the
    vertices ``V`` ``(V, 3)`` and faces ``F`` ``(F, 3)`` (row-major), ``(2, -1, -1)`` for a face without area:
    the arithmetic of ``proximity._barycentric``, its sums x, y, z in order."""
    cdef int64_t a = 3 * F[3 * f], b = 3 * F[3 * f + 1], c = 3 * F[3 * f + 2]
    cdef double e00 = V[b] - V[a], e01 = V[b + 1] - V[a + 1], e02 = V[b + 2] - V[a + 2]
    cdef double e10 = V[c] - V[a], e11 = V[c + 1] - V[a + 1], e12 = V[c + 2] - V[a + 2]
    cdef double q0 = x - V[a], q1 = y - V[a + 1], q2 = z - V[a + 2]
    cdef double d00 = e00 * e00 + e01 * e01 + e02 * e02
    cdef double d01 = e00 * e10 + e01 * e11 + e02 * e12
    cdef double d11 = e10 * e10 + e11 * e11 + e12 * e12
    cdef double d20 = q0 * e00 + q1 * e01 + q2 * e02
    cdef double d21 = q0 * e10 + q1 * e11 + q2 * e12
    cdef double den = d00 * d11 - d01 * d01, v, w
    if den > 0:
        v = (d11 * d20 - d01 * d21) / den
        w = (d00 * d21 - d01 * d20) / den
    else:
        v = -1.0
        w = -1.0
    out[0] = 1.0 - v - w
    out[1] = v
    out[2] = w


def closed_shell_signs(const double[:, ::1] p, const double[:, ::1] closest, const int64_t[::1] face,
                       const double[::1] d, const double[:, ::1] normals, const double[:, ::1] vertices,
                       const int64_t[:, ::1] faces, const int64_t[:, ::1] neighbours, flat):
    """:func:`usdhands.algorithms.interaction._proximity_kernel.closed_shell_signs`: signed distances ``(N,)``
    and whether each is left undecided ``(N,)`` bool (``flat``: the faces without a usable normal, bool,
    as the numba kernel takes it)."""
    cdef Py_ssize_t n = p.shape[0], i
    cdef const unsigned char[::1] is_flat = np.asarray(flat, dtype=np.bool_).view(np.uint8)
    out_arr = np.empty(n)
    undecided_arr = np.zeros(n, dtype=np.bool_)
    cdef double[::1] out = out_arr
    cdef unsigned char[::1] undecided = undecided_arr.view(np.uint8)
    cdef int64_t f, g, k
    cdef double r0, r1, r2, side, v, w, u, di, s
    cdef double bary[3]
    cdef bint on0, on1, on2, decided, inside
    cdef int count
    with nogil:
        for i in range(n):
            f = face[i]
            r0 = p[i, 0] - closest[i, 0]
            r1 = p[i, 1] - closest[i, 1]
            r2 = p[i, 2] - closest[i, 2]
            side = r0 * normals[f, 0] + r1 * normals[f, 1] + r2 * normals[f, 2]
            _barycentric_of(&vertices[0, 0], &faces[0, 0], f, closest[i, 0], closest[i, 1], closest[i, 2], bary)
            u = bary[0]
            v = bary[1]
            w = bary[2]
            on0 = u <= 1e-6
            on1 = v <= 1e-6
            on2 = w <= 1e-6
            count = <int>on0 + <int>on1 + <int>on2
            di = d[i]
            decided = count == 0 and fabs(side) > 1e-12 * (1.0 + di) and not is_flat[f]
            inside = side < 0
            if count == 1 and di > 0:
                k = 0 if on0 else (1 if on1 else 2)
                g = neighbours[f, k]
                s = r0 * (normals[f, 0] + normals[g, 0]) + r1 * (normals[f, 1] + normals[g, 1]) + \
                    r2 * (normals[f, 2] + normals[g, 2])
                if fabs(s) > 1e-12 * (1.0 + di) and not is_flat[f] and not is_flat[g]:
                    decided = True
                    inside = s < 0
            if not decided and di > 0:
                undecided[i] = 1
            out[i] = -di if inside else di
    return out_arr, undecided_arr


def undecided_sides(const double[:, ::1] p, const double[:, ::1] closest, const int64_t[::1] face,
                    const double[::1] d, const double[:, ::1] vertices, const int64_t[:, ::1] faces,
                    const double[:, :, ::1] around, around_pad, unusable_vertex):
    """:meth:`usdhands.algorithms.interaction.proximity._Part._undecided_inside` short of the winding number,
    in one pass: for the points ``p`` ``(N, 3)`` the side test left undecided (their nearest points
    ``closest``, faces ``face``, distances ``d``), whether each is inside ``(N,)`` bool and whether the
    winding number must still decide it ``(N,)`` bool. A point whose nearest point is a corner (two
    barycentric coordinates within ``1e-6``) takes the side of the faces around that vertex where
    they all agree beyond the slack (``around`` ``(V, W, 3)``: each vertex's faces' normals, padded;
    ``around_pad`` ``(V, W)`` bool: the padding; ``unusable_vertex`` ``(V,)`` bool: a vertex with a
    face without a usable normal). The same formulas as the NumPy method (its products summed x, y,
    z in order), which the tests hold it to."""
    cdef Py_ssize_t n = p.shape[0], W = around.shape[1], i, k
    cdef const unsigned char[:, ::1] pad = np.ascontiguousarray(around_pad, dtype=np.bool_).view(np.uint8)
    cdef const unsigned char[::1] unusable = np.ascontiguousarray(unusable_vertex, dtype=np.bool_).view(np.uint8)
    inside_arr = np.zeros(n, dtype=np.bool_)
    todo_arr = np.zeros(n, dtype=np.bool_)
    cdef unsigned char[::1] inside = inside_arr.view(np.uint8)
    cdef unsigned char[::1] todo = todo_arr.view(np.uint8)
    cdef int64_t f, vx
    cdef double u, v, w
    cdef double bary[3]
    cdef double x0, x1, x2, g0, g1, g2, slack, dot
    cdef bint front, behind
    cdef int slot
    with nogil:
        for i in range(n):
            f = face[i]
            _barycentric_of(&vertices[0, 0], &faces[0, 0], f, closest[i, 0], closest[i, 1], closest[i, 2], bary)
            u = bary[0]
            v = bary[1]
            w = bary[2]
            if <int>(u <= 1e-6) + <int>(v <= 1e-6) + <int>(w <= 1e-6) < 2:
                todo[i] = 1  # not at a corner: the winding number
                continue
            if u >= v:
                slot = 0 if u >= w else 2
            else:
                slot = 1 if v >= w else 2
            vx = faces[f, slot]
            x0 = p[i, 0] - vertices[vx, 0]
            x1 = p[i, 1] - vertices[vx, 1]
            x2 = p[i, 2] - vertices[vx, 2]
            g0 = closest[i, 0] - vertices[vx, 0]
            g1 = closest[i, 1] - vertices[vx, 1]
            g2 = closest[i, 2] - vertices[vx, 2]
            slack = sqrt(g0 * g0 + g1 * g1 + g2 * g2) + 1e-12 * (1.0 + d[i])
            front = True
            behind = True
            for k in range(W):
                if pad[vx, k]:
                    continue
                dot = around[vx, k, 0] * x0 + around[vx, k, 1] * x1 + around[vx, k, 2] * x2
                if not dot > slack:
                    front = False
                if not dot < -slack:
                    behind = False
            inside[i] = behind
            if not ((front or behind) and not unusable[vx]):
                todo[i] = 1
    return inside_arr, todo_arr


def second_order(const double[:, ::1] x, double a1, double a2, const double[:, ::1] zi):
    """:func:`usdhands.algorithms.interaction._recursion_kernel.second_order`: ``lfilter([1.0], [1.0, a1, a2],
    x, axis=0, zi=zi)[0]`` for ``x`` ``(n, C)`` and ``zi`` ``(2, C)``, a new ``(n, C)`` array."""
    cdef Py_ssize_t n = x.shape[0], C = x.shape[1], c, k
    y_arr = np.empty((n, C))
    cdef double[:, ::1] y = y_arr
    cdef double b1 = 0.0, b2 = 0.0, z0, z1, xn, yn
    with nogil:
        for c in range(C):
            z0 = zi[0, c]
            z1 = zi[1, c]
            for k in range(n):
                xn = x[k, c]
                yn = z0 + 1.0 * xn
                z0 = z1 + xn * b1 - yn * a1
                z1 = xn * b2 - yn * a2
                y[k, c] = yn
    return y_arr


# ---- the props' geometry without SciPy or libigl (a process that corrects against closed props
# imports neither: SciPy's sparse module alone cost a fresh ``synthesize --props`` about 0.11 s) ----


cdef int64_t _root(int64_t[::1] parent, int64_t v) noexcept nogil:
    cdef int64_t r = v, nxt
    while parent[r] != r:
        r = parent[r]
    while parent[v] != r:  # path compression
        nxt = parent[v]
        parent[v] = r
        v = nxt
    return r


def vertex_components(const int64_t[:, ::1] faces, Py_ssize_t n_vertices):
    """The connected component of each vertex ``(n_vertices,)`` int64, vertices joined by the faces'
    edges (``faces`` ``(F, 3)``): union-find, each component labelled by its smallest vertex (vertices
    of no face are components of their own). The components of
    ``scipy.sparse.csgraph.connected_components`` on the same graph, other labels."""
    parent_arr = np.arange(n_vertices, dtype=np.int64)
    cdef int64_t[::1] parent = parent_arr
    cdef Py_ssize_t f, k, F = faces.shape[0]
    cdef int64_t a, b
    with nogil:
        for f in range(F):
            for k in range(2):
                a = _root(parent, faces[f, k])
                b = _root(parent, faces[f, k + 1])
                if a < b:
                    parent[b] = a
                elif b < a:
                    parent[a] = b
        for k in range(n_vertices):
            parent[k] = _root(parent, k)
    return parent_arr


def solve_pentadiagonal_spd(const double[:, ::1] ab, const double[::1] b):
    """``scipy.linalg.solveh_banded(ab, b)`` for a symmetric positive definite pentadiagonal matrix in
    its upper form ``ab`` ``(3, n)`` (``ab[2]`` the diagonal, ``ab[1, 1:]`` and ``ab[0, 2:]`` the first
    and second superdiagonals): the solution ``(n,)`` by the banded Cholesky factorisation ``U.T U``
    (LAPACK's ``dpbtf2``: the column scaled by the reciprocal of its pivot, the trailing block updated),
    then the two triangular solves. Raises ``numpy.linalg.LinAlgError`` where the matrix is not
    positive definite, as SciPy does."""
    cdef Py_ssize_t n = ab.shape[1], j
    u_arr = np.array(ab, dtype=np.float64, copy=True)  # U in the same layout, factored in place
    x_arr = np.array(b, dtype=np.float64, copy=True)
    cdef double[:, ::1] u = u_arr
    cdef double[::1] x = x_arr
    cdef double ajj, r, x1 = 0.0, x2
    cdef Py_ssize_t bad = -1
    if b.shape[0] != n or ab.shape[0] != 3:
        raise ValueError(f"expected ab (3, n) and b (n,), got ({ab.shape[0]}, {n}) and ({b.shape[0]},)")
    with nogil:
        for j in range(n):
            ajj = u[2, j]
            if not ajj > 0.0:
                bad = j
                break
            ajj = sqrt(ajj)
            u[2, j] = ajj
            r = 1.0 / ajj
            if j + 1 < n:
                u[1, j + 1] = u[1, j + 1] * r
                x1 = u[1, j + 1]
                u[2, j + 1] = u[2, j + 1] - x1 * x1
            if j + 2 < n:
                u[0, j + 2] = u[0, j + 2] * r
                x2 = u[0, j + 2]
                u[1, j + 2] = u[1, j + 2] - x1 * x2
                u[2, j + 2] = u[2, j + 2] - x2 * x2
        if bad < 0:
            for j in range(n):  # U.T z = b
                if j >= 1:
                    x[j] = x[j] - u[1, j] * x[j - 1]
                if j >= 2:
                    x[j] = x[j] - u[0, j] * x[j - 2]
                x[j] = x[j] / u[2, j]
            for j in range(n - 1, -1, -1):  # U x = z
                if j + 1 < n:
                    x[j] = x[j] - u[1, j + 1] * x[j + 1]
                if j + 2 < n:
                    x[j] = x[j] - u[0, j + 2] * x[j + 2]
                x[j] = x[j] / u[2, j]
    if bad >= 0:
        raise np.linalg.LinAlgError(f"{bad + 1}th leading minor not positive definite")  # SciPy's words
    return x_arr


cdef enum:
    LEAF = 4  # triangles in a leaf of TriangleTree
    STACK = 128  # depth of its stacks (a median split halves every node: 2**64 triangles would not fill them)


cdef inline double _box_d2(const double* b, double x, double y, double z) noexcept nogil:
    """Squared distance from ``(x, y, z)`` to the box ``b`` (its low corner, then its high corner); without
    branches (which way a point lies from a box is a coin toss for the branch predictor)."""
    cdef double gx = _gap(b[0] - x, x - b[3]), gy = _gap(b[1] - y, y - b[4]), gz = _gap(b[2] - z, z - b[5])
    return gx * gx + gy * gy + gz * gz


cdef inline double _gap(double below, double above) noexcept nogil:
    """The larger of the two and 0 (``maxsd`` instructions, where libm's ``fmax`` is a call)."""
    cdef double g = below if below > above else above
    return g if g > 0.0 else 0.0


cdef inline void _segment_closest(double px, double py, double pz, double ax, double ay, double az,
                                  double bx, double by, double bz, double* out) noexcept nogil:
    """The point of segment ``a b`` nearest ``p`` into ``out[0:3]``, its squared distance into ``out[3]``."""
    cdef double ex = bx - ax, ey = by - ay, ez = bz - az
    cdef double ee = ex * ex + ey * ey + ez * ez, t = 0.0, dx, dy, dz
    if ee > 0.0:
        t = ((px - ax) * ex + (py - ay) * ey + (pz - az) * ez) / ee
        if t < 0.0:
            t = 0.0
        elif t > 1.0:
            t = 1.0
    out[0] = ax + t * ex
    out[1] = ay + t * ey
    out[2] = az + t * ez
    dx = px - out[0]
    dy = py - out[1]
    dz = pz - out[2]
    out[3] = dx * dx + dy * dy + dz * dz


cdef inline void _triangle_edges(double px, double py, double pz, double ax, double ay, double az, double bx,
                                 double by, double bz, double cx, double cy, double cz, double* out) noexcept nogil:
    cdef double tmp[4]
    _segment_closest(px, py, pz, ax, ay, az, bx, by, bz, out)
    _segment_closest(px, py, pz, bx, by, bz, cx, cy, cz, tmp)
    if tmp[3] < out[3]:
        out[0] = tmp[0]; out[1] = tmp[1]; out[2] = tmp[2]; out[3] = tmp[3]
    _segment_closest(px, py, pz, cx, cy, cz, ax, ay, az, tmp)
    if tmp[3] < out[3]:
        out[0] = tmp[0]; out[1] = tmp[1]; out[2] = tmp[2]; out[3] = tmp[3]


cdef inline void _triangle_closest(double px, double py, double pz, const double* T, double* out) noexcept nogil:
    """The point of triangle ``T`` (its corners' 9 coordinates) nearest ``p`` into ``out[0:3]`` and its
    squared distance into ``out[3]``: the Voronoi regions of the corners, edges and face in turn
    (Ericson, Real-Time Collision Detection, 5.1.5); a triangle without area by its three edges."""
    cdef double ax = T[0], ay = T[1], az = T[2]
    cdef double bx = T[3], by = T[4], bz = T[5]
    cdef double cx = T[6], cy = T[7], cz = T[8]
    cdef double abx = bx - ax, aby = by - ay, abz = bz - az
    cdef double acx = cx - ax, acy = cy - ay, acz = cz - az
    cdef double apx = px - ax, apy = py - ay, apz = pz - az
    cdef double d1 = abx * apx + aby * apy + abz * apz, d2 = acx * apx + acy * apy + acz * apz
    cdef double bpx, bpy, bpz, cpx, cpy, cpz, d3, d4, d5, d6, va, vb, vc, v, w, denom, dx, dy, dz
    cdef double nx = aby * acz - abz * acy, ny = abz * acx - abx * acz, nz = abx * acy - aby * acx
    if nx * nx + ny * ny + nz * nz <= 0.0:  # no area: the nearest of its edges
        _triangle_edges(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz, out)
        return
    if d1 <= 0.0 and d2 <= 0.0:
        out[0] = ax; out[1] = ay; out[2] = az
    else:
        bpx = px - bx; bpy = py - by; bpz = pz - bz
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        if d3 >= 0.0 and d4 <= d3:
            out[0] = bx; out[1] = by; out[2] = bz
        else:
            vc = d1 * d4 - d3 * d2
            if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
                v = d1 / (d1 - d3)
                out[0] = ax + v * abx; out[1] = ay + v * aby; out[2] = az + v * abz
            else:
                cpx = px - cx; cpy = py - cy; cpz = pz - cz
                d5 = abx * cpx + aby * cpy + abz * cpz
                d6 = acx * cpx + acy * cpy + acz * cpz
                if d6 >= 0.0 and d5 <= d6:
                    out[0] = cx; out[1] = cy; out[2] = cz
                else:
                    vb = d5 * d2 - d1 * d6
                    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
                        w = d2 / (d2 - d6)
                        out[0] = ax + w * acx; out[1] = ay + w * acy; out[2] = az + w * acz
                    else:
                        va = d3 * d6 - d5 * d4
                        if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
                            w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                            out[0] = bx + w * (cx - bx); out[1] = by + w * (cy - by); out[2] = bz + w * (cz - bz)
                        else:
                            denom = va + vb + vc
                            if not denom > 0.0:  # rounding on a sliver: by its edges
                                _triangle_edges(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz, out)
                                return
                            v = vb / denom
                            w = vc / denom
                            out[0] = ax + abx * v + acx * w
                            out[1] = ay + aby * v + acy * w
                            out[2] = az + abz * v + acz * w
    dx = px - out[0]
    dy = py - out[1]
    dz = pz - out[2]
    out[3] = dx * dx + dy * dy + dz * dz


cdef void _select(int64_t[::1] idx, const double[:, ::1] key, int axis, Py_ssize_t lo, Py_ssize_t hi,
                  Py_ssize_t nth) noexcept nogil:
    """Reorder ``idx[lo:hi]`` so that ``idx[nth]`` has the rank it would have sorted by ``key[idx, axis]``, the
    smaller before it and the larger after (quickselect, median-of-three pivots; ties in index order)."""
    cdef Py_ssize_t i, j, mid
    cdef int64_t t
    cdef double pivot
    hi -= 1
    while hi > lo:
        mid = lo + (hi - lo) // 2
        # the median of three to idx[mid], by (key, index)
        if _before(key, axis, idx[mid], idx[lo]):
            t = idx[mid]; idx[mid] = idx[lo]; idx[lo] = t
        if _before(key, axis, idx[hi], idx[lo]):
            t = idx[hi]; idx[hi] = idx[lo]; idx[lo] = t
        if _before(key, axis, idx[hi], idx[mid]):
            t = idx[hi]; idx[hi] = idx[mid]; idx[mid] = t
        t = idx[mid]; idx[mid] = idx[hi]; idx[hi] = t  # the pivot to the end
        j = lo
        for i in range(lo, hi):
            if _before(key, axis, idx[i], idx[hi]):
                t = idx[i]; idx[i] = idx[j]; idx[j] = t
                j += 1
        t = idx[j]; idx[j] = idx[hi]; idx[hi] = t
        if j == nth:
            return
        if nth < j:
            hi = j - 1
        else:
            lo = j + 1


cdef inline bint _before(const double[:, ::1] key, int axis, int64_t a, int64_t b) noexcept nogil:
    return key[a, axis] < key[b, axis] or (key[a, axis] == key[b, axis] and a < b)


cdef inline int64_t _spread(int64_t v) noexcept nogil:
    v = v & 0x3FF
    v = (v | (v << 16)) & 0x030000FF
    v = (v | (v << 8)) & 0x0300F00F
    v = (v | (v << 4)) & 0x030C30C3
    return (v | (v << 2)) & 0x09249249


def morton_codes(const double[:, ::1] p, const double[:, ::1] bounds):
    """The 30-bit Z-order code ``(N,)`` int64 of each of ``p`` ``(N, 3)`` over ``bounds`` ``(2, 3)``, 1,024
    cells an axis, points outside in the nearest cell (a NaN coordinate in cell 0): the codes of
    :func:`usdhands.algorithms.interaction.proximity.morton_order`, one pass."""
    cdef Py_ssize_t n = p.shape[0], i
    cdef int a
    cdef double scale[3]
    cdef double x
    cdef int64_t q[3]
    codes_arr = np.empty(n, dtype=np.int64)
    cdef int64_t[::1] codes = codes_arr
    for a in range(3):
        x = bounds[1, a] - bounds[0, a]
        scale[a] = 1023.0 / (x if x > 1e-300 else 1e-300)
    with nogil:
        for i in range(n):
            for a in range(3):
                x = (p[i, a] - bounds[0, a]) * scale[a]
                if not x > 0.0:  # below, or NaN
                    x = 0.0
                elif x > 1023.0:
                    x = 1023.0
                q[a] = <int64_t>x
            codes[i] = _spread(q[0]) | (_spread(q[1]) << 1) | (_spread(q[2]) << 2)
    return codes_arr


cdef class TriangleTree:
    """A bounding-box tree over a triangle mesh, for the exact nearest point of the surface to points.

    Built once per shell: each node's triangles split at the median of their centroids along the
    longest side of the centroids' box, leaves of up to ``LEAF`` (4) triangles. The query visits nodes
    nearest first and drops any whose box is farther than the nearest triangle found, so its answers
    are exact: the least squared distance over all triangles, a tie going to the lowest face index
    (the same answer whatever the order of the points). It stands in for libigl's
    ``AABB.squared_distance`` where this module was built (the same distances to rounding; see the
    tests), so that correcting against closed props imports neither libigl nor, through it, SciPy's
    sparse module.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64, F >= 1
    """

    cdef readonly object vertices, faces, bounds, boxes, child, start, count, order, corners, tri_boxes
    cdef readonly Py_ssize_t nodes

    def __init__(self, vertices, faces):
        V = np.ascontiguousarray(vertices, dtype=np.float64)
        Fa = np.ascontiguousarray(faces, dtype=np.int64)
        if V.ndim != 2 or V.shape[1] != 3 or Fa.ndim != 2 or Fa.shape[1] != 3 or len(Fa) == 0:
            raise ValueError(f"expected vertices (V, 3) and faces (F, 3), F >= 1; got {V.shape}, {Fa.shape}")
        if Fa.min() < 0 or Fa.max() >= len(V):
            raise ValueError("faces index vertices that do not exist")
        self.vertices, self.faces = V, Fa
        self.bounds = np.ascontiguousarray([V.min(axis=0), V.max(axis=0)])
        c0, c1, c2 = V[Fa[:, 0]], V[Fa[:, 1]], V[Fa[:, 2]]  # (reductions over an axis of 3 cost NumPy 20x more)
        tri_box_arr = np.ascontiguousarray(np.concatenate([np.minimum(np.minimum(c0, c1), c2),
                                                           np.maximum(np.maximum(c0, c1), c2)], axis=1))
        cen_arr = (c0 + c1 + c2) / 3.0
        cdef Py_ssize_t F = len(Fa), cap = 2 * F + 1
        self.boxes = np.empty((cap, 6))
        self.child = np.full(cap, -1, dtype=np.int64)
        self.start = np.zeros(cap, dtype=np.int64)
        self.count = np.zeros(cap, dtype=np.int64)
        self.order = np.arange(F, dtype=np.int64)
        cdef double[:, ::1] box = self.boxes, tbox = tri_box_arr, cen = cen_arr
        cdef int64_t[::1] child = self.child, start = self.start, count = self.count, order = self.order
        cdef Py_ssize_t stack[STACK]
        cdef Py_ssize_t sp = 1, used = 1, node, s, e, k, mid
        cdef int axis, a
        cdef double clo[3]
        cdef double chi[3]
        cdef double ext, widest
        stack[0] = 0
        start[0] = 0
        count[0] = F
        with nogil:
            while sp > 0:  # split top-down (children numbered after their parent)
                sp -= 1
                node = stack[sp]
                s = start[node]
                e = s + count[node]
                if e - s <= LEAF:
                    continue
                for a in range(3):
                    clo[a] = cen[order[s], a]
                    chi[a] = cen[order[s], a]
                for k in range(s + 1, e):
                    for a in range(3):
                        if cen[order[k], a] < clo[a]:
                            clo[a] = cen[order[k], a]
                        if cen[order[k], a] > chi[a]:
                            chi[a] = cen[order[k], a]
                axis = 0
                widest = chi[0] - clo[0]
                for a in range(1, 3):
                    ext = chi[a] - clo[a]
                    if ext > widest:
                        widest = ext
                        axis = a
                mid = s + (e - s) // 2
                _select(order, cen, axis, s, e, mid)
                child[node] = used
                start[used] = s
                count[used] = mid - s
                start[used + 1] = mid
                count[used + 1] = e - mid
                stack[sp] = used
                stack[sp + 1] = used + 1
                sp += 2
                used += 2
            for node in range(used - 1, -1, -1):  # boxes bottom-up: a leaf's of its triangles, a node's of its two
                if child[node] < 0:
                    s = start[node]
                    for a in range(6):
                        box[node, a] = tbox[order[s], a]
                    for k in range(s + 1, s + count[node]):
                        for a in range(3):
                            if tbox[order[k], a] < box[node, a]:
                                box[node, a] = tbox[order[k], a]
                            if tbox[order[k], a + 3] > box[node, a + 3]:
                                box[node, a + 3] = tbox[order[k], a + 3]
                else:
                    k = child[node]
                    for a in range(3):
                        box[node, a] = box[k, a] if box[k, a] < box[k + 1, a] else box[k + 1, a]
                        box[node, a + 3] = box[k, a + 3] if box[k, a + 3] > box[k + 1, a + 3] else box[k + 1, a + 3]
        self.nodes = used
        # the triangles' corners and boxes in the leaves' order: a leaf's triangles are read from one place
        self.corners = np.ascontiguousarray(V[Fa[self.order]].reshape(F, 9))
        self.tri_boxes = np.ascontiguousarray(tri_box_arr[self.order])

    def squared_distance(self, points, Py_ssize_t sort_from=-1):
        """The squared distance ``(N,)``, the nearest face ``(N,)`` int64 and the nearest point ``(N, 3)`` of
        the surface to each of ``points`` ``(N, 3)`` (libigl's ``AABB.squared_distance``'s three results;
        a point with a NaN coordinate gets NaN, face 0). With ``sort_from >= 0``, a batch of at least that
        many points is visited in Z order over the mesh's box (neighbours together: fewer cache misses
        and a tighter first bound; each point's answer is its own, so the answers are the same)."""
        P_arr = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        cdef Py_ssize_t n = P_arr.shape[0], i, node, c, k, sp, slot
        d2_arr = np.empty(n)
        face_arr = np.zeros(n, dtype=np.int64)
        near_arr = np.empty((n, 3))
        if 0 <= sort_from <= n:
            visit_arr = np.argsort(morton_codes(P_arr, self.bounds), kind="stable")
        else:
            visit_arr = np.arange(n, dtype=np.int64)
        cdef const int64_t[::1] visit = visit_arr
        cdef const double[:, ::1] P = P_arr
        cdef double[::1] d2 = d2_arr
        cdef int64_t[::1] face = face_arr
        cdef double[:, ::1] near = near_arr
        cdef const double[:, ::1] box_v = self.boxes, tbox_v = self.tri_boxes, T_v = self.corners
        cdef const int64_t[::1] child_v = self.child, start_v = self.start, count_v = self.count, order_v = self.order
        cdef const double* box = &box_v[0, 0]
        cdef const double* tbox = &tbox_v[0, 0]
        cdef const double* T = &T_v[0, 0]
        cdef const int64_t* child = &child_v[0]
        cdef const int64_t* start = &start_v[0]
        cdef const int64_t* count = &count_v[0]
        cdef const int64_t* order = &order_v[0]
        cdef Py_ssize_t stack[STACK]
        cdef double sd[STACK]
        cdef double x, y, z, best, dl, dr, bx, by, bz
        cdef double cand[4]
        cdef int64_t bf, t
        cdef Py_ssize_t seed = -1, bk = -1
        with nogil:
            for slot in range(n):
                i = visit[slot]
                x = P[i, 0]
                y = P[i, 1]
                z = P[i, 2]
                best = INFINITY
                bf = -1
                bx = by = bz = NAN
                if seed >= 0:  # the previous point's nearest triangle bounds this one's from the start
                    _triangle_closest(x, y, z, T + 9 * seed, cand)
                    best = cand[3]
                    bf = order[seed]
                    bk = seed
                    bx = cand[0]
                    by = cand[1]
                    bz = cand[2]
                stack[0] = 0
                sd[0] = 0.0
                sp = 1
                while sp > 0:
                    sp -= 1
                    if sd[sp] > best:  # its box is farther than the nearest triangle found since it was pushed
                        continue
                    node = stack[sp]
                    c = child[node]
                    if c < 0:
                        for k in range(start[node], start[node] + count[node]):
                            if _box_d2(tbox + 6 * k, x, y, z) > best:
                                continue
                            _triangle_closest(x, y, z, T + 9 * k, cand)
                            t = order[k]
                            if cand[3] < best or (cand[3] == best and t < bf):
                                best = cand[3]
                                bf = t
                                bk = k
                                bx = cand[0]
                                by = cand[1]
                                bz = cand[2]
                        continue
                    dl = _box_d2(box + 6 * c, x, y, z)
                    dr = _box_d2(box + 6 * (c + 1), x, y, z)
                    if dl <= dr:  # the nearer box is taken first
                        if dr <= best:
                            stack[sp] = c + 1
                            sd[sp] = dr
                            sp += 1
                        if dl <= best:
                            stack[sp] = c
                            sd[sp] = dl
                            sp += 1
                    else:
                        if dl <= best:
                            stack[sp] = c
                            sd[sp] = dl
                            sp += 1
                        if dr <= best:
                            stack[sp] = c + 1
                            sd[sp] = dr
                            sp += 1
                if bf < 0 or best != best:  # a NaN coordinate
                    d2[i] = NAN
                    face[i] = 0
                    near[i, 0] = NAN
                    near[i, 1] = NAN
                    near[i, 2] = NAN
                    seed = -1
                else:
                    d2[i] = best
                    face[i] = bf
                    near[i, 0] = bx
                    near[i, 1] = by
                    near[i, 2] = bz
                    seed = bk
        return d2_arr, face_arr, near_arr

# cython: language_level=3, boundscheck=False, wraparound=False, initializedcheck=False, cdivision=True
"""The interaction's kernels of :mod:`._proximity_kernel` and :mod:`._recursion_kernel`, compiled ahead of time.

The same functions with the same arguments and the same results to the bit (see
:mod:`usdhands.compiled`: no fused multiply-adds, each sum in the numba kernel's order), so a
correction or ``synthesize --props`` in a process that never starts numba (one command, a batch
worker) runs them instead of their NumPy twins. Tests hold each to its numba twin.
"""

from libc.math cimport fabs
from libc.stdint cimport int64_t

import numpy as np


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
    cdef int64_t f, a, b, c, g, k
    cdef double r0, r1, r2, side, e00, e01, e02, e10, e11, e12, q0, q1, q2, d00, d01, d11, d20, d21, den
    cdef double v, w, u, di, s
    cdef bint on0, on1, on2, decided, inside
    cdef int count
    with nogil:
        for i in range(n):
            f = face[i]
            r0 = p[i, 0] - closest[i, 0]
            r1 = p[i, 1] - closest[i, 1]
            r2 = p[i, 2] - closest[i, 2]
            side = r0 * normals[f, 0] + r1 * normals[f, 1] + r2 * normals[f, 2]
            a = faces[f, 0]
            b = faces[f, 1]
            c = faces[f, 2]
            e00 = vertices[b, 0] - vertices[a, 0]
            e01 = vertices[b, 1] - vertices[a, 1]
            e02 = vertices[b, 2] - vertices[a, 2]
            e10 = vertices[c, 0] - vertices[a, 0]
            e11 = vertices[c, 1] - vertices[a, 1]
            e12 = vertices[c, 2] - vertices[a, 2]
            q0 = closest[i, 0] - vertices[a, 0]
            q1 = closest[i, 1] - vertices[a, 1]
            q2 = closest[i, 2] - vertices[a, 2]
            d00 = e00 * e00 + e01 * e01 + e02 * e02
            d01 = e00 * e10 + e01 * e11 + e02 * e12
            d11 = e10 * e10 + e11 * e11 + e12 * e12
            d20 = q0 * e00 + q1 * e01 + q2 * e02
            d21 = q0 * e10 + q1 * e11 + q2 * e12
            den = d00 * d11 - d01 * d01
            if den > 0:
                v = (d11 * d20 - d01 * d21) / den
                w = (d00 * d21 - d01 * d20) / den
            else:
                v = -1.0
                w = -1.0
            u = 1.0 - v - w
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

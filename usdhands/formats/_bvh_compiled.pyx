# cython: language_level=3, boundscheck=False, wraparound=False, initializedcheck=False, cdivision=True
"""The BVH motion kernels of :mod:`usdhands.formats._bvh_kernel`, compiled ahead of time.

:func:`parse_rows` and :func:`clip_arrays` with the same arguments and the same results
to the bit (the same operations in the same order, the C library's ``cos``/``sin``),
compiled when the package is installed (Cython) instead of by numba: a process that
reads with these never imports numba. The forms read, and the rules for handing text
back, are :mod:`usdhands.formats._bvh_kernel`'s. Tests hold each to its numba twin.
"""

from libc.math cimport cos, sin, M_PI
from libc.stdint cimport int64_t, uint64_t

import numpy as np

#: 10**0 .. 10**22: the powers of ten a double holds exactly (as _bvh_kernel.POW10).
POW10 = np.array([10.0 ** k for k in range(23)])
#: For each axis a (X, Y, Z), ``q * e_a`` as a signed permutation of q's xyzw components (as _bvh_kernel's).
PERM = np.array([[3, 2, 1, 0], [2, 3, 0, 1], [1, 0, 3, 2]], dtype=np.int64)
SIGN = np.array([[1.0, 1.0, -1.0, -1.0], [-1.0, 1.0, 1.0, -1.0], [1.0, -1.0, 1.0, -1.0]])

cdef uint64_t _TWO_53 = 2 ** 53
cdef double _RADIANS = M_PI / 180.0
cdef int64_t _BLOCK = 64


def parse_rows(const unsigned char[::1] buf, int64_t start, int64_t columns, double[:, ::1] out,
               const double[::1] pow10):
    """Parse ``buf[start:]`` (uint8, the motion lines) into ``out (rows, columns)`` float64.

    Returns the number of rows read (``<= out.shape[0]``), or ``-1`` when the text holds
    anything outside :mod:`usdhands.formats._bvh_kernel`'s forms, a row of another length,
    or more rows than ``out``.
    """
    cdef int64_t got
    with nogil:
        got = _parse_rows(buf, start, columns, out, pow10)
    return got


cdef int64_t _parse_rows(const unsigned char[::1] buf, int64_t start, int64_t columns, double[:, ::1] out,
                         const double[::1] pow10) noexcept nogil:
    cdef Py_ssize_t n = buf.shape[0], cap = out.shape[0]
    cdef Py_ssize_t i = start
    cdef int64_t row = 0, col = 0, significant, digits, frac, e, edigits
    cdef unsigned char b, c
    cdef bint neg, point, eneg
    cdef uint64_t w
    cdef double v
    while i < n:
        b = buf[i]
        if b == 32 or b == 9:
            i += 1
            continue
        if b == 10 or b == 13:
            if b == 13:
                if i + 1 < n and buf[i + 1] == 10:
                    i += 1
                else:
                    return -1
            if col != 0:
                if col != columns:
                    return -1
                row += 1
                col = 0
            i += 1
            continue
        if col >= columns or (col == 0 and row >= cap):
            return -1
        neg = False
        if b == 45 or b == 43:
            neg = b == 45
            i += 1
        w = 0
        significant = 0
        digits = 0
        frac = 0
        point = False
        while i < n:
            c = buf[i]
            if 48 <= c <= 57:
                digits += 1
                if point:
                    frac += 1
                if w != 0 or c != 48:
                    significant += 1
                    if significant > 19:
                        return -1
                    w = w * 10 + (c - 48)
                i += 1
            elif c == 46 and not point:
                point = True
                i += 1
            else:
                break
        if digits == 0:
            return -1
        e = 0
        if i < n and (buf[i] == 101 or buf[i] == 69):
            i += 1
            eneg = False
            if i < n and (buf[i] == 45 or buf[i] == 43):
                eneg = buf[i] == 45
                i += 1
            edigits = 0
            while i < n and 48 <= buf[i] <= 57:
                edigits += 1
                if edigits > 6:
                    return -1
                e = e * 10 + (buf[i] - 48)
                i += 1
            if edigits == 0:
                return -1
            if eneg:
                e = -e
        if i < n:
            c = buf[i]
            if not (c == 32 or c == 9 or c == 10 or c == 13):
                return -1
        e -= frac
        v = 0.0
        if w != 0:
            if w > _TWO_53 or e < -22 or e > 22:
                return -1
            v = <double>w
            if e < 0:
                v = v / pow10[-e]
            elif e > 0:
                v = v * pow10[e]
        out[row, col] = -v if neg else v
        col += 1
    if col != 0:
        if col != columns:
            return -1
        row += 1
    return row


def clip_arrays(const double[:, ::1] values, const double[:, ::1] offsets, const int64_t[::1] first,
                const int64_t[::1] count, const int64_t[::1] axes, const int64_t[::1] cols,
                const int64_t[::1] pjoint, const int64_t[::1] paxis, const int64_t[::1] pcol,
                const int64_t[:, ::1] perm, const double[:, ::1] sign, double[:, :, ::1] rot,
                double[:, :, ::1] trans):
    """A clip's rotations ``rot (T, J, 4)`` (xyzw) and translations ``trans (T, J, 3)``: see
    :func:`usdhands.formats._bvh_kernel.clip_arrays` (the same arguments and numbers)."""
    cdef Py_ssize_t T = values.shape[0], J = first.shape[0]
    cdef Py_ssize_t j, i, k, t, t0, t1, p
    cdef int64_t width = 1, f, a, a0, m, op, n
    cdef double h, ci, si
    cdef double q[4]
    cdef double nq[4]
    cdef bint has[4]
    cdef bint nhas[4]
    for j in range(J):
        width = max(width, count[j])
    cdef int64_t[:, :, ::1] plan = np.zeros((J, width, 4), dtype=np.int64)
    for k in range(4):
        nhas[k] = False
    with nogil:
        for j in range(J):
            f = first[j]
            if count[j] == 0:
                continue
            for k in range(4):
                has[k] = k == 3 or k == axes[f]
            for i in range(1, count[j]):
                a = axes[f + i]
                for k in range(4):
                    m = perm[a, k]
                    if not has[m]:
                        plan[j, i, k] = 1 if has[k] else 0
                        nhas[k] = has[k]
                    elif not has[k]:
                        plan[j, i, k] = 3 if sign[a, k] < 0 else 2
                        nhas[k] = True
                    else:
                        plan[j, i, k] = 5 if sign[a, k] < 0 else 4
                        nhas[k] = True
                for k in range(4):
                    has[k] = nhas[k]
        t0 = 0
        while t0 < T:
            t1 = min(T, t0 + _BLOCK)
            for j in range(J):
                f = first[j]
                n = count[j]
                if n == 0:
                    for t in range(t0, t1):
                        rot[t, j, 0] = 0.0
                        rot[t, j, 1] = 0.0
                        rot[t, j, 2] = 0.0
                        rot[t, j, 3] = 1.0
                    continue
                a0 = axes[f]
                for t in range(t0, t1):
                    for k in range(4):
                        q[k] = 0.0
                    h = values[t, cols[f]] * _RADIANS * 0.5
                    q[3] = 1.0 if h == 0.0 else cos(h)
                    q[a0] = h if h == 0.0 else sin(h)
                    for i in range(1, n):
                        a = axes[f + i]
                        h = values[t, cols[f + i]] * _RADIANS * 0.5
                        ci = 1.0 if h == 0.0 else cos(h)
                        si = h if h == 0.0 else sin(h)
                        for k in range(4):
                            op = plan[j, i, k]
                            if op == 0:
                                nq[k] = 0.0
                            elif op == 1:
                                nq[k] = q[k] * ci
                            elif op == 2:
                                nq[k] = q[perm[a, k]] * si
                            elif op == 3:
                                nq[k] = -(q[perm[a, k]] * si)
                            elif op == 4:
                                nq[k] = q[k] * ci + q[perm[a, k]] * si
                            else:
                                nq[k] = q[k] * ci - q[perm[a, k]] * si
                        for k in range(4):
                            q[k] = nq[k]
                    for k in range(4):
                        rot[t, j, k] = q[k]
            for t in range(t0, t1):
                for j in range(J):
                    trans[t, j, 0] = offsets[j, 0]
                    trans[t, j, 1] = offsets[j, 1]
                    trans[t, j, 2] = offsets[j, 2]
                for p in range(pjoint.shape[0]):
                    trans[t, pjoint[p], paxis[p]] = values[t, pcol[p]]
            t0 += _BLOCK

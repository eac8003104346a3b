# cython: language_level=3, boundscheck=False, wraparound=False, initializedcheck=False, cdivision=True
"""Joint transforms taken apart and checked, a matrix at a time, compiled ahead of time.

:func:`xform_to_trs` is :func:`usdhands.model.rotations.xform_to_trs` (with its ``matrix_to_quat``) on
``(N, 4, 4)`` float64 transforms: the same translations, quaternions and scales to the bit, the
same operations in the same order (column lengths as NumPy's ``norm`` sums them, Markley's
method as ``matrix_to_quat`` builds and normalises it). Two of NumPy's steps are decisions on
numbers LAPACK and BLAS compute (the sign of a determinant, a Gram matrix against the
identity); this module decides them only where a determinant is far from zero and a Gram
matrix far from the tolerance (a mirror far from singular is its own: the reflection goes into the
x scale), and otherwise answers None: the NumPy function then does the whole call (a singular,
sheared or not finite transform: its SVD, its errors).

:func:`xforms_ok` is the USD reader's ``_xforms_ok`` (finite transforms with columns longer
than 1e-12, a normalised determinant of at least 1e-6 in magnitude, an affine last row), None
where the determinant is within a relative 1e-8 of that bound.

A read of a skeleton's 19 rest transforms spent ~45 us in NumPy's calls of ``xform_to_trs``
and ~24 in ``_xforms_ok`` (CesiumMan.usdz).
"""

from libc.math cimport sqrt, fabs, isfinite

import numpy as np

#: How far from zero a determinant must be, relative to its columns' lengths, for its sign to be
#: the one LAPACK's factorisation gives (both are within a few units of rounding of the exact one).
cdef double _SIGN_MARGIN = 1e-9
#: matrix_to_quat's bounds for r r^T against the identity: off the diagonal, on it
cdef double _OFF_TOL = 1e-12
cdef double _ON_TOL = 1e-12 + 1e-5


cdef inline double _det3(double a00, double a01, double a02, double a10, double a11, double a12,
                         double a20, double a21, double a22) noexcept nogil:
    return a00 * (a11 * a22 - a12 * a21) - a01 * (a10 * a22 - a12 * a20) + a02 * (a10 * a21 - a11 * a20)


cdef inline bint _clearly_within(double value, double tol) noexcept nogil:
    """|value| <= tol for sure (False: beyond it, or too near it to say)."""
    return fabs(value) <= 0.5 * tol


def xform_to_trs(const double[:, :, ::1] m):
    """``(t (N, 3), q (N, 4) xyzw, s (N, 3))`` float64 of ``(N, 4, 4)`` column-vector transforms, or
    None where a decision is too close to call (NumPy's function decides those)."""
    cdef Py_ssize_t n = m.shape[0], k, i, c, choice
    t_out = np.empty((n, 3))
    q_out = np.empty((n, 4))
    s_out = np.empty((n, 3))
    cdef double[:, ::1] t = t_out, q = q_out, s = s_out
    cdef double b[9]
    cdef double r[9]
    cdef double col[3]
    cdef double safe[3]
    cdef double cand[4]
    cdef double diag[4]
    cdef double det, det_r, trace, s01, s02, s12, x, y, z, rest, norm, best, g
    for k in range(n):
        for i in range(3):
            for c in range(3):
                b[3 * i + c] = m[k, i, c]
            t[k, i] = m[k, i, 3]
        for c in range(3):  # np.linalg.norm(basis, axis=-2): the rows' squares summed in order
            col[c] = sqrt((b[c] * b[c] + b[3 + c] * b[3 + c]) + b[6 + c] * b[6 + c])
        det = _det3(b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7], b[8])
        if not (isfinite(det) and fabs(det) > _SIGN_MARGIN * col[0] * col[1] * col[2]):
            return None
        if det < 0:
            col[0] = -col[0]
        for c in range(3):
            s[k, c] = col[c]
            safe[c] = 1.0 if fabs(col[c]) < 1e-12 else col[c]
        for i in range(3):
            for c in range(3):
                r[3 * i + c] = b[3 * i + c] / safe[c]
        # matrix_to_quat(r): a positive determinant, r r^T the identity within its bounds
        det_r = _det3(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8])
        if not (isfinite(det_r) and det_r > _SIGN_MARGIN):
            return None
        for i in range(3):
            for c in range(3):
                g = r[3 * i] * r[3 * c] + r[3 * i + 1] * r[3 * c + 1] + r[3 * i + 2] * r[3 * c + 2]
                if not _clearly_within(g - (1.0 if i == c else 0.0), _ON_TOL if i == c else _OFF_TOL):
                    return None  # not orthogonal (its SVD), or too near the bound to say
        # Markley's method as matrix_to_quat computes it
        trace = r[0] + r[4] + r[8]
        diag[0], diag[1], diag[2], diag[3] = r[0], r[4], r[8], trace
        choice = 0
        best = diag[0]
        for c in range(1, 4):
            if diag[c] > best:  # np.argmax: the first of equal ones
                best, choice = diag[c], c
        s01, s02, s12 = r[3] + r[1], r[6] + r[2], r[7] + r[5]
        x, y, z = r[7] - r[5], r[2] - r[6], r[3] - r[1]
        rest = 1 - trace
        if choice == 0:
            cand[0], cand[1], cand[2], cand[3] = rest + 2 * r[0], s01, s02, x
        elif choice == 1:
            cand[0], cand[1], cand[2], cand[3] = s01, rest + 2 * r[4], s12, y
        elif choice == 2:
            cand[0], cand[1], cand[2], cand[3] = s02, s12, rest + 2 * r[8], z
        else:
            cand[0], cand[1], cand[2], cand[3] = x, y, z, 1 + trace
        norm = sqrt(((cand[0] * cand[0] + cand[1] * cand[1]) + cand[2] * cand[2]) + cand[3] * cand[3])
        for c in range(4):
            q[k, c] = cand[c] / norm
    return t_out, q_out, s_out


def xforms_ok(const double[:, :, ::1] m):
    """The USD reader's ``_xforms_ok`` of ``(N, 4, 4)`` float64 transforms: True or False, or None where
    a determinant is too near the bound of 1e-6 to say (and no test failed: NumPy's answer is then
    the AND of them all, as here)."""
    cdef Py_ssize_t n = m.shape[0], k, i, c
    cdef double b[9]
    cdef double col[3]
    cdef double det
    cdef bint undecided = False
    for k in range(n):
        for i in range(4):
            for c in range(4):
                if not isfinite(m[k, i, c]):
                    return False
        for c in range(3):
            if not (fabs(m[k, 3, c]) <= 1e-6):
                return False
        if not (fabs(m[k, 3, 3] - 1.0) <= 1e-6):
            return False
        for i in range(3):
            for c in range(3):
                b[3 * i + c] = m[k, i, c]
        for c in range(3):  # np.linalg.norm(m[:, :3, :3], axis=1): the rows' squares summed in order
            col[c] = sqrt((b[c] * b[c] + b[3 + c] * b[3 + c]) + b[6 + c] * b[6 + c])
            if not (isfinite(col[c]) and col[c] > 1e-12):
                return False
        for i in range(3):
            for c in range(3):
                b[3 * i + c] = b[3 * i + c] / col[c]
        det = fabs(_det3(b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7], b[8]))
        if not isfinite(det) or fabs(det - 1e-6) <= 1e-8 * 1e-6 + 1e-15:
            undecided = True
        elif det < 1e-6:
            return False
    return None if undecided else True

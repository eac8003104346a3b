# cython: language_level=3, boundscheck=False, wraparound=False, initializedcheck=False, cdivision=True
"""The play, step-limit and stitch kernels of :mod:`usdhands.algorithms.synthesis._play_kernel`, compiled ahead of time.

The same functions with the same arguments and the same results to the bit (see
:mod:`._search_compiled`), serial where numba's :func:`play` is parallel over input
segments. ``max``/``min`` keep Python's choice between equals (the first argument).
Tests hold each to its numba twin.
"""

from libc.math cimport fabs, floor, INFINITY
from libc.stdint cimport int64_t

import numpy as np

from usdhands.algorithms.synthesis._search_compiled cimport _align_path


cdef inline double _max(double a, double b) noexcept nogil:
    return b if b > a else a


cdef inline double _min(double a, double b) noexcept nogil:
    return b if b < a else a


cdef void _smooth_path(int64_t[::1] path, int64_t m, int64_t w, double linear_share, double[::1] out) noexcept nogil:
    cdef Py_ssize_t n = path.shape[0], i
    cdef int64_t size, half, t
    cdef double top = m - 1.0, run, v, total, y0, y1, step, lin, lo, hi, a, b
    if n < 3 or w < 2:
        run = -INFINITY
        for i in range(n):
            v = _min(_max(<double>path[i], 0.0), top)
            run = _max(run, v)
            out[i] = run
        return
    size = min(w, <int64_t>n)
    half = size // 2
    total = 0.0
    for t in range(-half, size - half):
        total += <double>path[min(max(t, <int64_t>0), <int64_t>n - 1)]
    out[0] = total / size
    for i in range(1, n):
        total += <double>path[min(i - half + size - 1, <int64_t>n - 1)] - <double>path[max(i - 1 - half, <int64_t>0)]
        out[i] = total / size
    y0 = out[0]
    y1 = out[n - 1]
    step = (y1 - y0) / (n - 1)
    for i in range(n):
        lin = y1 if i == n - 1 else y0 + i * step
        out[i] = (1.0 - linear_share) * out[i] + linear_share * lin
    lo = <double>path[0]
    hi = <double>path[n - 1]
    a = out[0]
    b = out[n - 1]
    if b > a:
        for i in range(n):
            out[i] = lo + (out[i] - a) * (hi - lo) / (b - a)
    else:
        step = (hi - lo) / (n - 1)
        for i in range(n):
            out[i] = hi if i == n - 1 else lo + i * step
    run = -INFINITY
    for i in range(n):
        v = _min(_max(out[i], 0.0), top)
        run = _max(run, v)
        out[i] = run


def smooth_path(int64_t[::1] path, int64_t m, int64_t w, double linear_share, double[::1] out):
    """:func:`usdhands.algorithms.synthesis._play_kernel.smooth_path`."""
    _smooth_path(path, m, w, linear_share, out)


ctypedef fused finger_t:
    float
    double


cdef void _add_sampled(const finger_t[:, :] fingers, int64_t r0, int64_t m, double[::1] at, double weight,
                       double[:, ::1] out, int64_t o0) noexcept nogil:
    """``out[o0 + i] += weight * fingers[r0:r0 + m]`` interpolated at ``at[i]`` (sample_rows); float32
    fingers are taken as float64 in each product (C's promotion, numba's)."""
    cdef Py_ssize_t i, c
    cdef int64_t i0, i1
    cdef double x, f
    for i in range(at.shape[0]):
        x = _min(_max(at[i], 0.0), m - 1.0)
        i0 = <int64_t>floor(x)
        i1 = min(i0 + 1, m - 1)
        f = x - i0
        for c in range(fingers.shape[1]):
            out[o0 + i, c] += weight * (fingers[r0 + i0, c] * (1.0 - f) + fingers[r0 + i1, c] * f)


def play(const double[:, ::1] qf, const double[:, ::1] df, const finger_t[:, :] fingers,
         const int64_t[:, ::1] seg_ranges, const int64_t[:, ::1] qb, const int64_t[:, ::1] cand,
         const double[:, ::1] weights, const double[:, ::1] bands, int64_t w, double linear_share,
         double[:, ::1] out):
    """:func:`usdhands.algorithms.synthesis._play_kernel.play`, one input segment after the other
    (``fingers`` float32 or float64: each value taken as float64, as numba's does)."""
    cdef Py_ssize_t i, j
    cdef int64_t q0, q1, n, a, b, m, t
    cdef double total, step
    cdef int64_t[::1] path
    cdef double[::1] at
    for i in range(qb.shape[0]):
        q0 = qb[i, 0]
        q1 = qb[i, 1]
        n = q1 - q0
        path = np.zeros(n, dtype=np.int64)
        at = np.empty(n)
        for j in range(cand.shape[1]):
            if weights[i, j] <= 0.0 or cand[i, j] < 0:
                continue
            a = seg_ranges[cand[i, j], 0]
            b = seg_ranges[cand[i, j], 1]
            m = b - a
            total = _align_path(qf[q0:q1], df[a:b], bands[i, j], path)
            if total == INFINITY:
                step = (m - 1.0) / (n - 1) if n > 1 else 0.0
                for t in range(n):
                    at[t] = t * step
                if n > 1:
                    at[n - 1] = m - 1.0
            else:
                _smooth_path(path, m, w, linear_share, at)
            _add_sampled(fingers, a, m, at, weights[i, j], out, q0)


def limit(const double[:, ::1] x, const double[::1] lim, double[:, ::1] out):
    """:func:`usdhands.algorithms.synthesis._play_kernel.limit`: every frame step clamped to ``lim``."""
    cdef Py_ssize_t T = x.shape[0], C = x.shape[1], t, c
    cdef Py_ssize_t first = T
    cdef double d
    with nogil:
        for t in range(T - 1):
            for c in range(C):
                if fabs(x[t + 1, c] - x[t, c]) > lim[c]:
                    first = t
                    break
            if first < T:
                break
        for t in range(min(first + 1, T)):
            for c in range(C):
                out[t, c] = x[t, c]
        for t in range(first + 1, T):
            for c in range(C):
                d = x[t, c] - out[t - 1, c]
                if d > lim[c]:
                    d = lim[c]
                elif d < -lim[c]:
                    d = -lim[c]
                out[t, c] = out[t - 1, c] + d


def stitch(x, bounds, mask, double blend_mean, double blend_max, int64_t blend_n, out, means, maxes, blended):
    """:func:`usdhands.algorithms.synthesis._play_kernel.stitch` (``mask`` and ``blended`` bool arrays)."""
    _stitch(x, bounds, np.asarray(mask).view(np.uint8), blend_mean, blend_max, blend_n, out, means, maxes,
            np.asarray(blended).view(np.uint8))


cdef void _stitch(const double[:, ::1] x, const int64_t[::1] bounds, const unsigned char[::1] mask, double blend_mean,
                  double blend_max, int64_t blend_n, double[:, ::1] out, double[::1] means, double[::1] maxes,
                  unsigned char[::1] blended) noexcept:
    cdef Py_ssize_t C = x.shape[1], c, i
    cdef int64_t nm = 0, t, a, b, pa, n, L
    cdef double s, mx, step_prev, step_new, target, d, mean, ramp
    cdef bint blend
    cdef double[::1] delta = np.empty(C)
    for c in range(C):
        if mask[c]:
            nm += 1
    for t in range(bounds[0], bounds[1]):
        for c in range(C):
            out[t, c] = x[t, c]
    for i in range(1, bounds.shape[0] - 1):
        a = bounds[i]
        b = bounds[i + 1]
        pa = bounds[i - 1]
        n = b - a
        s = 0.0
        mx = 0.0
        for c in range(C):
            step_prev = out[a - 1, c] - out[a - 2, c] if a - pa >= 2 else 0.0
            step_new = x[a + 1, c] - x[a, c] if n >= 2 else 0.0
            target = out[a - 1, c] + 0.5 * (step_prev + step_new)
            delta[c] = target - x[a, c]
            if mask[c]:
                d = fabs(delta[c])
                s += d
                mx = _max(mx, d)
        mean = s / nm if nm else 0.0
        blend = mean > blend_mean or mx > blend_max
        means[i - 1] = mean
        maxes[i - 1] = mx
        blended[i - 1] = blend
        L = min(blend_n, n)
        for t in range(n):
            if blend:
                ramp = 1.0 - <double>t / <double>L if t < L else 0.0
                for c in range(C):
                    out[a + t, c] = x[a + t, c] + ramp * delta[c]
            else:
                for c in range(C):
                    out[a + t, c] = x[a + t, c] + delta[c]

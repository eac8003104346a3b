"""numba kernels behind playing the chosen fragments and limiting the frame steps.

:func:`play` is the compiled twin of, for every input segment and every candidate
of weight above zero, :func:`~usdhands.algorithms.synthesis.segment_cost.dtw_align`
(the warp), :func:`~usdhands.algorithms.synthesis.output_warp.smooth_warp` and
:func:`~usdhands.algorithms.synthesis.output_warp.sample_rows`, summed with the
weights; :func:`limit` is the twin of
:func:`~usdhands.algorithms.synthesis.output_warp.limit_steps`. Tests hold each to its
NumPy twin. Kept apart so importing the algorithms compiles nothing.
"""

from __future__ import annotations

import math

import numpy as np

from usdhands.algorithms.synthesis._dtw_kernel import align_path
from usdhands.jit import njit, prange


@njit(cache=True)
def smooth_path(path, m, w, linear_share, out):
    """:func:`~usdhands.algorithms.synthesis.output_warp.smooth_warp` of ``path (n,)`` into ``out (n,)``.

    ``w`` is the moving-average width in frames (already rounded).
    """
    n = path.shape[0]
    top = m - 1.0
    if n < 3 or w < 2:
        run = -math.inf
        for i in range(n):
            v = min(max(float(path[i]), 0.0), top)
            run = max(run, v)
            out[i] = run
        return
    size = min(w, n)
    half = size // 2  # scipy's uniform_filter1d: window i - size // 2 .. i - size // 2 + size - 1,
    # as scipy computes it (a running sum: equal to the bit)
    total = 0.0
    for t in range(-half, size - half):
        total += float(path[min(max(t, 0), n - 1)])
    out[0] = total / size
    for i in range(1, n):
        total += float(path[min(i - half + size - 1, n - 1)]) - float(path[max(i - 1 - half, 0)])
        out[i] = total / size
    y0 = out[0]
    y1 = out[n - 1]
    step = (y1 - y0) / (n - 1)
    for i in range(n):
        lin = y1 if i == n - 1 else y0 + i * step
        out[i] = (1.0 - linear_share) * out[i] + linear_share * lin
    lo = float(path[0])
    hi = float(path[n - 1])
    a = out[0]
    b = out[n - 1]
    if b > a:
        for i in range(n):
            out[i] = lo + (out[i] - a) * (hi - lo) / (b - a)
    else:
        step = (hi - lo) / (n - 1)
        for i in range(n):
            out[i] = hi if i == n - 1 else lo + i * step
    run = -math.inf
    for i in range(n):
        v = min(max(out[i], 0.0), top)
        run = max(run, v)
        out[i] = run


@njit(cache=True)
def _add_sampled(rows, at, weight, out, o0):
    """``out[o0 + i] += weight * rows`` interpolated at ``at[i]`` (sample_rows)."""
    m = rows.shape[0]
    for i in range(at.shape[0]):
        x = min(max(at[i], 0.0), m - 1.0)
        i0 = int(math.floor(x))
        i1 = min(i0 + 1, m - 1)
        f = x - i0
        for c in range(rows.shape[1]):
            out[o0 + i, c] += weight * (rows[i0, c] * (1.0 - f) + rows[i1, c] * f)


@njit(parallel=True, cache=True)
def play(qf, df, fingers, seg_ranges, qb, cand, weights, bands, w, linear_share, out):
    """Sum over candidates of ``weights[i, j]`` times candidate ``cand[i, j]``'s fingers played on input segment ``i``.

    ``qf (T, D)`` and ``df (F, D)`` weighted features, ``fingers (F, M)``,
    ``seg_ranges (S, 2)`` database segment frames, ``qb (N, 2)`` input segments,
    ``cand (N, k)`` indices into ``seg_ranges``, ``weights (N, k)`` (0: skipped),
    ``bands (N, k)`` DTW band per pair; ``out (T, M)`` zeros on entry. A pair no warp
    fits is stretched linearly.
    """
    for i in prange(qb.shape[0]):
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
            total = align_path(qf[q0:q1], df[a:b], bands[i, j], path)
            if total == np.inf:
                step = (m - 1.0) / (n - 1) if n > 1 else 0.0
                for t in range(n):
                    at[t] = t * step
                if n > 1:
                    at[n - 1] = m - 1.0
            else:
                smooth_path(path, m, w, linear_share, at)
            _add_sampled(fingers[a:b], at, weights[i, j], out, q0)


@njit(cache=True)
def limit(x, lim, out):
    """``out`` = ``x (T, C)`` with every frame step clamped to ``lim (C,)`` (limit_steps).

    Frames before the first step over its limit are copied as they are, as the twin does.
    """
    T, C = x.shape
    first = T
    for t in range(T - 1):
        for c in range(C):
            if abs(x[t + 1, c] - x[t, c]) > lim[c]:
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


@njit(cache=True)
def stitch(x, bounds, mask, blend_mean, blend_max, blend_n, out, means, maxes, blended):
    """:func:`~usdhands.algorithms.synthesis.stitching.stitch_fragments` of the fragments
    ``x[bounds[i]:bounds[i + 1]]`` into ``out``; per seam the mean and largest difference
    over the ``mask`` DOFs and whether it was blended out."""
    C = x.shape[1]
    nm = 0
    for c in range(C):
        if mask[c]:
            nm += 1
    for t in range(bounds[0], bounds[1]):
        for c in range(C):
            out[t, c] = x[t, c]
    delta = np.empty(C)
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
                d = abs(delta[c])
                s += d
                mx = max(mx, d)
        mean = s / nm if nm else 0.0
        blend = mean > blend_mean or mx > blend_max
        means[i - 1] = mean
        maxes[i - 1] = mx
        blended[i - 1] = blend
        L = min(blend_n, n)
        for t in range(n):
            if blend:
                ramp = 1.0 - t / L if t < L else 0.0
                for c in range(C):
                    out[a + t, c] = x[a + t, c] + ramp * delta[c]
            else:
                for c in range(C):
                    out[a + t, c] = x[a + t, c] + delta[c]

"""Carrying a chosen database segment's fingers onto the input's timing, and the step limit.

The paper uses dynamic time warping to compare a database segment with the input
segment (eq. 1) and plays the chosen segment "adapted to the input's length"; it
does not say the output must copy database frames along the DTW path. Copying does
harm: the asymmetric path moves by 0, 1 or 2 database frames per output frame, so a
played segment holds a frame (judder) and skips one (a skip over a fast closing
fist merges two real steps into one: a pop of twice the real speed). Here instead:

- :func:`smooth_warp`: the DTW path ``j(i)`` is smoothed by a moving average of
  ``smoothing_s`` seconds (a monotone path stays monotone under it), mixed with a
  quarter of the straight warp (:data:`LINEAR_SHARE`: the speed never drops to zero,
  so a long wait of the path on one frame does not hold the fingers still) and
  rescaled to run exactly from the first to the last database frame, so the timing
  follows the alignment but its speed changes gradually;
- :func:`sample_rows`: the fingers are sampled at these fractional frames by linear
  interpolation between the two neighbouring database frames (adjacent frames of
  captured fingers differ by a few degrees, where interpolating Euler curves and
  slerp agree closely);
- :func:`play_segments`: every input segment gets the weighted sum of some database
  segments' fingers, each played along its own smoothed warp (synthesis plays the
  path's candidate mixed with the ``k`` candidates of the row but those of its own
  take, see :func:`~usdhands.algorithms.synthesis.synthesize.played_weights`);
- :func:`step_limits` / :func:`limit_steps`: after stitching, no DOF may move by more
  per frame than the database's own high-percentile step (99.5th by default), so
  what remains of a pop (a seam blend, a fast warp) is spread over a few frames,
  never larger than what the captured motion does.

:func:`play_segments_fast` and :func:`limit_steps_fast` are the compiled twins that
synthesis runs (:func:`play_kernels`): numba's (:mod:`~usdhands.algorithms.synthesis._play_kernel`,
parallel over input segments) once the search has loaded numba, else the ones compiled
ahead of time (:mod:`usdhands.compiled`); without either (no C compiler at install, numba
not loaded), the NumPy functions, which the tests hold the twins to.
"""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["smooth_warp", "moving_average_nearest", "sample_rows", "step_limits", "limit_steps", "limit_steps_fast",
           "play_segments", "play_segments_fast", "play_kernels"]

#: Share of the straight warp (constant speed) mixed into the smoothed DTW warp, so the
#: warp's slope never falls to zero: a DTW path that waits on one database frame for
#: longer than the smoothing width would otherwise still hold the fingers still.
LINEAR_SHARE = 0.25


def smooth_warp(path: np.ndarray, m: int, fps: float, smoothing_s: float) -> np.ndarray:
    """A smoothed, monotone version of a warp path, in fractional database frames.

    Parameters
    ----------
    path : (n,) int or float
        Database frame aligned to each input frame, non-decreasing, in ``0..m-1``.
    m : int
        Database segment length, frames.
    fps : float
        Frames per second (for the smoothing width).
    smoothing_s : float
        Width of the moving average, seconds (0: the path as it is).

    Returns
    -------
    (n,) float
        Increasing (with smoothing) or non-decreasing, from ``0`` to ``m - 1`` (``path[0]`` and ``path[-1]`` when the
        path does not span the segment).
    """
    x = np.asarray(path, dtype=np.float64)
    n = len(x)
    w = int(round(smoothing_s * fps))
    if n < 3 or w < 2:
        return np.maximum.accumulate(np.clip(x, 0, m - 1))
    y = moving_average_nearest(x, min(w, n))
    y = (1 - LINEAR_SHARE) * y + LINEAR_SHARE * np.linspace(y[0], y[-1], n)
    lo, hi = x[0], x[-1]
    if y[-1] > y[0]:
        y = lo + (y - y[0]) * (hi - lo) / (y[-1] - y[0])
    else:
        y = np.linspace(lo, hi, n)
    return np.maximum.accumulate(np.clip(y, 0, m - 1))


def moving_average_nearest(x: np.ndarray, size: int) -> np.ndarray:
    """``scipy.ndimage.uniform_filter1d(x, size, mode="nearest")`` to the bit, without importing scipy.

    Parameters
    ----------
    x : (n,) float
    size : int
        Window length, ``1 <= size``; the window of output ``i`` is
        ``x[i - size // 2 : i - size // 2 + size]``, the ends repeated beyond the array.

    Returns
    -------
    (n,) float64
        scipy's running sum: the first window summed from 0.0, then each step adds the
        entering value minus the leaving one, each output the sum divided by ``size``.
    """
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    if n == 0:
        return x.copy()
    left = size // 2
    padded = np.concatenate([np.full(left, x[0]), x, np.full(size - left - 1, x[-1])])
    total = 0.0
    for v in padded[:size].tolist():
        total += v
    steps = (padded[size:size + n - 1] - padded[:n - 1]).tolist()
    return np.fromiter(itertools.accumulate(steps, initial=total), dtype=np.float64, count=n) / size


def sample_rows(rows: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Rows ``(m, C)`` sampled at fractional indices ``at (n,)`` by linear interpolation."""
    rows = np.asarray(rows, dtype=np.float64)
    at = np.clip(np.asarray(at, dtype=np.float64), 0, len(rows) - 1)
    i0 = np.floor(at).astype(np.int64)
    i1 = np.minimum(i0 + 1, len(rows) - 1)
    f = (at - i0)[:, None]
    return rows[i0] * (1.0 - f) + rows[i1] * f


def step_limits(fingers: np.ndarray, tracks: np.ndarray, percentile: float,
                frames: np.ndarray | None = None) -> np.ndarray:
    """Per DOF, the ``percentile`` of the absolute frame-to-frame steps inside tracks.

    Parameters
    ----------
    fingers : (F, C) float
        Finger DOF curves, degrees, tracks concatenated.
    tracks : (R, >=2) int
        ``[start, stop)`` of each track (steps across tracks do not count).
    percentile : float
        In ``(0, 100]``.
    frames : (F,) bool, optional
        Frames that may be looked at (k-fold: those outside the held-out windows); a
        step counts only when both its frames are among them.

    Returns
    -------
    (C,) float
        Degrees per frame (0 for a DOF that never moves; the largest step for one that
        moves in fewer frames than the percentile leaves out).
    """
    f = np.asarray(fingers)
    if f.ndim != 2:
        raise ValueError(f"Expected fingers (F, C), got {f.shape}")
    inside = np.ones(max(len(f) - 1, 0), dtype=bool)
    ends = np.asarray(tracks)[:, 1] - 1  # step from a track's last frame to the next track's first
    inside[ends[(ends >= 0) & (ends < len(inside))]] = False
    if frames is not None:
        frames = np.asarray(frames, dtype=bool)
        if frames.shape != (len(f),):
            raise ValueError(f"Expected frames ({len(f)},) bool, got {frames.shape}")
        inside &= frames[:-1] & frames[1:]
    if not inside.any():
        return np.zeros(f.shape[1])
    # a column at a time, the same percentiles as along axis 0 of the whole: on a database (10,560 x 45) the
    # temporaries of one column stay in the allocator's reuse; those of the whole (five arrays of 3.8 MB)
    # were ~4,600 fresh pages, the larger part of the first clip's extra cost in every process
    limits = np.empty(f.shape[1])
    for c in range(f.shape[1]):
        steps = np.abs(np.diff(np.asarray(f[:, c], dtype=np.float64)))[inside]
        lim = np.percentile(steps, percentile)
        limits[c] = lim if lim > 0 else steps.max()
    return limits


def limit_steps(curves: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """Curves ``(T, C)`` whose per-frame steps are at most ``limits (C,)``.

    Each frame moves towards the input's frame by at most the limit, so a jump
    becomes a ramp that catches up with the input; where the input never exceeds
    the limit the result equals it.
    """
    x = np.asarray(curves, dtype=np.float64)
    lim = np.asarray(limits, dtype=np.float64)
    if len(x) < 2:
        return x.copy()
    step = np.diff(x, axis=0)
    if (np.abs(step) <= lim).all():
        return x.copy()
    out = x.copy()
    first = int(np.argmax((np.abs(step) > lim).any(axis=1)))
    for t in range(first + 1, len(x)):
        out[t] = out[t - 1] + np.clip(x[t] - out[t - 1], -lim, lim)
    return out


def limit_steps_fast(curves: np.ndarray, limits: np.ndarray, kernels=None) -> np.ndarray:
    """:func:`limit_steps` compiled: same arguments, same result. ``kernels``: the module of
    :func:`play_kernels` (numba's :mod:`~usdhands.algorithms.synthesis._play_kernel` when None)."""
    kern = _numba_kernels() if kernels is None else kernels
    x = np.ascontiguousarray(curves, dtype=np.float64)
    lim = np.ascontiguousarray(limits, dtype=np.float64)
    if x.ndim != 2 or lim.shape != (x.shape[1],):
        raise ValueError(f"Expected curves (T, C) and limits (C,), got {x.shape} and {lim.shape}")
    out = np.empty_like(x)
    if len(x):
        kern.limit(x, lim, out)
    return out


def _play_arrays(query_weighted, db_weighted, fingers, seg_ranges, query_bounds, cand, weights, bands):
    qf = np.ascontiguousarray(query_weighted, dtype=np.float64)
    df = np.ascontiguousarray(db_weighted, dtype=np.float64)
    rows = np.asarray(fingers)
    sr = np.ascontiguousarray(seg_ranges, dtype=np.int64).reshape(-1, 2)
    qb = np.ascontiguousarray(query_bounds, dtype=np.int64).reshape(-1, 2)
    c = np.ascontiguousarray(cand, dtype=np.int64)
    w = np.ascontiguousarray(weights, dtype=np.float64)
    bd = np.ascontiguousarray(bands, dtype=np.float64)
    if c.shape != w.shape or c.shape != bd.shape or c.ndim != 2 or len(c) != len(qb):
        raise ValueError(f"Expected cand, weights and bands ({len(qb)}, k), got {c.shape}, {w.shape} and {bd.shape}")
    if qf.ndim != 2 or df.ndim != 2 or qf.shape[1] != df.shape[1] or rows.ndim != 2 or len(rows) != len(df):
        raise ValueError(f"Expected features (T, D), (F, D) and fingers (F, M), got {qf.shape}, {df.shape} and "
                         f"{rows.shape}")
    if len(qb) and ((qb[:, 0] < 0).any() or (qb[:, 1] > len(qf)).any() or (qb[:, 1] <= qb[:, 0]).any()):
        raise ValueError(f"query_bounds must hold non-empty ranges inside 0..{len(qf)}")
    used = c[(w > 0) & (c >= 0)]
    if ((used >= len(sr)).any() or (sr[used, 0] < 0).any() or (sr[used, 1] > len(df)).any()
            or (sr[used, 1] <= sr[used, 0]).any()):
        raise ValueError("cand must name non-empty database segments inside the features")
    return qf, df, rows, sr, qb, c, w, bd


def play_segments(query_weighted: np.ndarray, db_weighted: np.ndarray, fingers: np.ndarray,
                  seg_ranges: np.ndarray, query_bounds: np.ndarray, cand: np.ndarray, weights: np.ndarray,
                  bands: np.ndarray, fps: float, smoothing_s: float) -> np.ndarray:
    """The fingers played on the input segments: per segment a weighted sum of database segments.

    Parameters
    ----------
    query_weighted : (T, D) float
        Weighted input features (the warp aligns these).
    db_weighted : (F, D) float
        Weighted database features.
    fingers : (F, M) float
        Database finger curves, degrees.
    seg_ranges : (S, 2) int
        ``[start, stop)`` frames of the database segments ``cand`` refers to.
    query_bounds : (N, 2) int
        ``[start, stop)`` of the input segments.
    cand : (N, k) int
        Database segments (rows of ``seg_ranges``) per input segment; -1: none.
    weights : (N, k) float
        Weight of each; 0 skips it (the weights of a row normally sum to 1).
    bands : (N, k) float
        DTW band of each pair (:func:`~usdhands.algorithms.synthesis.segment_cost.dtw_align`).
    fps, smoothing_s : float
        As in :func:`smooth_warp`.

    Returns
    -------
    (T, M) float
        Rows outside every input segment are 0. Each candidate is aligned to its input
        segment by DTW, its warp smoothed (:func:`smooth_warp`) and its fingers sampled
        along it (:func:`sample_rows`); a pair no warp fits is stretched linearly.
    """
    from usdhands.algorithms.synthesis.segment_cost import dtw_align_many

    qf, df, rows, sr, qb, c, w, bd = _play_arrays(query_weighted, db_weighted, fingers, seg_ranges, query_bounds,
                                                  cand, weights, bands)
    out = np.zeros((len(qf), rows.shape[1]))
    used = [(i, j) for i in range(len(qb)) for j in range(c.shape[1]) if w[i, j] > 0 and c[i, j] >= 0]
    # every pair aligned in one batch (the compiled alignment's paths, in NumPy)
    pairs = np.array([(qb[i, 0], qb[i, 1], *sr[c[i, j]]) for i, j in used], dtype=np.int64).reshape(-1, 4)
    warps = dtw_align_many(qf, df, pairs, np.array([bd[i, j] for i, j in used]))
    for (i, j), (q0, q1, a, b), (_, warp) in zip(used, pairs, warps):
        at = np.linspace(0, b - a - 1, q1 - q0) if len(warp) == 0 else smooth_warp(warp, b - a, fps, smoothing_s)
        out[q0:q1] += w[i, j] * sample_rows(rows[a:b], at)
    return out


def play_segments_fast(query_weighted: np.ndarray, db_weighted: np.ndarray, fingers: np.ndarray,
                       seg_ranges: np.ndarray, query_bounds: np.ndarray, cand: np.ndarray, weights: np.ndarray,
                       bands: np.ndarray, fps: float, smoothing_s: float, kernels=None) -> np.ndarray:
    """:func:`play_segments` compiled: same arguments, same result. ``kernels``: the module of
    :func:`play_kernels` (numba's, parallel over input segments, when None)."""
    kern = _numba_kernels() if kernels is None else kernels
    qf, df, rows, sr, qb, c, w, bd = _play_arrays(query_weighted, db_weighted, fingers, seg_ranges, query_bounds,
                                                  cand, weights, bands)
    out = np.zeros((len(qf), rows.shape[1]))
    if len(qb):
        kern.play(qf, df, rows, sr, qb, c, w, bd, int(round(smoothing_s * fps)), LINEAR_SHARE, out)
    return out


def play_kernels():
    """The compiled play, stitch and step-limit kernels this process runs, or None for the NumPy functions.

    numba's (:mod:`~usdhands.algorithms.synthesis._play_kernel`, parallel) where the search has
    loaded numba (then they cost nothing to start and are the fastest); else the ones compiled
    ahead of time (:mod:`usdhands.compiled`: nothing to start) where they were built; else None.
    All give the same numbers.
    """
    import sys

    kernel = sys.modules.get("usdhands.algorithms.synthesis._dtw_kernel")
    if kernel is not None and kernel.search.signatures:
        return _numba_kernels()
    from usdhands.compiled import kernel_module

    return kernel_module("algorithms.synthesis._play_compiled")


def _numba_kernels():
    from usdhands.algorithms.synthesis import _play_kernel

    return _play_kernel

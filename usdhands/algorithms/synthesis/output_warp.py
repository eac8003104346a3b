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
- :func:`step_limits` / :func:`limit_steps`: after stitching, no DOF may move by more
  per frame than the database's own high-percentile step (99.5th by default), so
  what remains of a pop (a seam blend, a fast warp) is spread over a few frames,
  never larger than what the captured motion does.
"""

from __future__ import annotations

import numpy as np

__all__ = ["smooth_warp", "sample_rows", "step_limits", "limit_steps"]

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
    from scipy.ndimage import uniform_filter1d

    y = uniform_filter1d(x, size=min(w, n), mode="nearest")
    y = (1 - LINEAR_SHARE) * y + LINEAR_SHARE * np.linspace(y[0], y[-1], n)
    lo, hi = x[0], x[-1]
    if y[-1] > y[0]:
        y = lo + (y - y[0]) * (hi - lo) / (y[-1] - y[0])
    else:
        y = np.linspace(lo, hi, n)
    return np.maximum.accumulate(np.clip(y, 0, m - 1))


def sample_rows(rows: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Rows ``(m, C)`` sampled at fractional indices ``at (n,)`` by linear interpolation."""
    rows = np.asarray(rows, dtype=np.float64)
    at = np.clip(np.asarray(at, dtype=np.float64), 0, len(rows) - 1)
    i0 = np.floor(at).astype(np.int64)
    i1 = np.minimum(i0 + 1, len(rows) - 1)
    f = (at - i0)[:, None]
    return rows[i0] * (1.0 - f) + rows[i1] * f


def step_limits(fingers: np.ndarray, tracks: np.ndarray, percentile: float) -> np.ndarray:
    """Per DOF, the ``percentile`` of the absolute frame-to-frame steps inside tracks.

    Parameters
    ----------
    fingers : (F, C) float
        Finger DOF curves, degrees, tracks concatenated.
    tracks : (R, >=2) int
        ``[start, stop)`` of each track (steps across tracks do not count).
    percentile : float
        In ``(0, 100]``.

    Returns
    -------
    (C,) float
        Degrees per frame (0 for a DOF that never moves; the largest step for one that
        moves in fewer frames than the percentile leaves out).
    """
    f = np.asarray(fingers, dtype=np.float64)
    steps = np.abs(np.diff(f, axis=0))
    inside = np.ones(len(steps), dtype=bool)
    ends = np.asarray(tracks)[:, 1] - 1  # step from a track's last frame to the next track's first
    inside[ends[(ends >= 0) & (ends < len(steps))]] = False
    if not inside.any():
        return np.zeros(f.shape[1])
    steps = steps[inside]
    lim = np.percentile(steps, percentile, axis=0)
    return np.where(lim > 0, lim, steps.max(axis=0))


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

"""Segmentation of a motion by wrist speed (seed 000, §3.1).

The motion is cut where the wrist speed crosses a threshold close to zero, which
separates motion phases (fast) from holds (slow). Segments shorter than the minimum
(0.33 s) are merged into a neighbour; segments longer than the maximum (2 s) are cut
again at the lowest speed that leaves both parts at least the minimum long (a local
minimum of the speed inside the allowed range), repeatedly. Frames within
``SPLIT_TOLERANCE`` × threshold of the lowest speed count as equally low and the one
nearest the middle wins: inside a hold the speed is noise near zero, and the cut must not
depend on it (the same motion read from a glTF and from a BVH with 6 decimals would
otherwise be cut at different frames).

Segments are given as **boundaries** ``b`` (int array, ``b[0] = 0``, ``b[-1] = T``):
segment ``i`` covers frames ``b[i]`` to ``b[i+1]`` (exclusive).
"""

from __future__ import annotations

import numpy as np

__all__ = ["wrist_speed", "segment_by_speed", "segment_lengths", "SPLIT_TOLERANCE"]

#: Frames whose speed is within this fraction of the threshold of the lowest are equally good cuts.
SPLIT_TOLERANCE = 0.05


def wrist_speed(positions: np.ndarray, fps: float, smoothing_s: float = 0.0) -> np.ndarray:
    """Speed of a point, ``(T,)`` in units per second.

    Parameters
    ----------
    positions : (T, 3) float
        Positions per frame (centimetres for the wrist features).
    fps : float
        Frames per second.
    smoothing_s : float
        Width in seconds of a centred moving average applied to the speed (0: none).
    """
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"Expected positions to have shape (T, 3), got {p.shape}")
    if len(p) < 2:
        return np.zeros(len(p))
    v = np.linalg.norm(np.gradient(p, axis=0), axis=1) * float(fps)
    w = int(round(smoothing_s * fps))
    if w >= 2:
        w = min(w, len(v))
        kernel = np.ones(w) / w
        padded = np.pad(v, (w // 2, w - 1 - w // 2), mode="edge")
        v = np.convolve(padded, kernel, mode="valid")
    return v


def segment_by_speed(speed: np.ndarray, fps: float, threshold: float,
                     min_s: float = 0.33, max_s: float = 2.0) -> np.ndarray:
    """Cut a motion into segments by speed.

    Parameters
    ----------
    speed : (T,) float
        Wrist speed per frame (cm/s).
    fps : float
        Frames per second.
    threshold : float
        Speed (cm/s) below which the wrist holds.
    min_s, max_s : float
        Shortest and longest segment, seconds.

    Returns
    -------
    (N+1,) int
        Segment boundaries, ``0`` first and ``T`` last. A motion shorter than the
        minimum is one segment.
    """
    speed = np.asarray(speed, dtype=np.float64)
    if speed.ndim != 1:
        raise ValueError(f"Expected speed to have shape (T,), got {speed.shape}")
    if max_s < 2 * min_s:
        raise ValueError(f"Expected max_s >= 2 * min_s, got {max_s} and {min_s}")
    T = len(speed)
    min_f = max(1, int(round(min_s * fps)))
    max_f = max(2 * min_f, int(round(max_s * fps)))
    if T == 0:
        return np.array([0, 0])
    moving = speed > threshold
    cuts = np.nonzero(moving[1:] != moving[:-1])[0] + 1
    bounds = [0, *cuts.tolist(), T]
    bounds = _merge_short(bounds, min_f, speed)
    out = [0]
    tol = SPLIT_TOLERANCE * float(threshold)
    for a, b in zip(bounds[:-1], bounds[1:]):
        out.extend(_split_long(a, b, speed, min_f, max_f, tol))
        out.append(b)
    return np.array(out, dtype=np.int64)


def _merge_short(bounds: list[int], min_f: int, speed: np.ndarray) -> list[int]:
    """Remove boundaries until every segment is at least ``min_f`` frames (or one is left).

    The shortest segment goes first; it joins the neighbour whose merged length is
    smaller (ties: the neighbour with the more similar mean speed, then the earlier).
    """
    bounds = list(bounds)
    while len(bounds) > 2:
        lengths = np.diff(bounds)
        i = int(np.argmin(lengths))
        if lengths[i] >= min_f:
            break
        n = len(lengths)
        if i == 0:
            del bounds[1]
        elif i == n - 1:
            del bounds[-2]
        else:
            left = lengths[i - 1] + lengths[i]
            right = lengths[i + 1] + lengths[i]
            if left == right:
                m = speed[bounds[i]:bounds[i + 1]].mean()
                dl = abs(speed[bounds[i - 1]:bounds[i]].mean() - m)
                dr = abs(speed[bounds[i + 1]:bounds[i + 2]].mean() - m)
                left, right = dl, dr
            if left <= right:
                del bounds[i]
            else:
                del bounds[i + 1]
    return bounds


def _split_long(a: int, b: int, speed: np.ndarray, min_f: int, max_f: int, tol: float = 0.0) -> list[int]:
    """Inner cut points of segment ``[a, b)`` so every part is at most ``max_f`` frames.

    The cut leaves both parts at least ``min_f`` frames and is at the lowest speed
    there (a local minimum); of the frames within ``tol`` of that speed, the one
    nearest the middle (the earlier on a tie), so a flat hold is cut in its middle
    whatever its noise.
    """
    if b - a <= max_f:
        return []
    lo, hi = a + min_f, b - min_f  # a cut c must leave [a, c) and [c, b) >= min_f
    inner = np.arange(lo, hi + 1)
    window = speed[lo:hi + 1]
    near = inner[window <= window.min() + tol]
    c = int(near[int(np.argmin(np.abs(2 * near - (a + b))))])
    return (_split_long(a, c, speed, min_f, max_f, tol) + [c]
            + _split_long(c, b, speed, min_f, max_f, tol))


def segment_lengths(bounds: np.ndarray) -> np.ndarray:
    """Frames per segment, ``(N,)`` int."""
    return np.diff(np.asarray(bounds))

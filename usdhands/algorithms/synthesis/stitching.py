"""Joining the chosen fragments into one finger motion (seed 000, §3.5).

At every seam the difference between where the previous fragment ends and where the
new one starts is added to the new fragment as an offset, so the motion does not
jump; offsets carry on from seam to seam ("over time this offset can increase").
Only when the difference is large (mean over DOFs above 5° or maximum above 20°) is
it blended out linearly instead, over ``blend_duration_s`` (at most the fragment), so
the fragment returns to its own values and offsets do not pile up.

The seam target continues the motion: the new first frame is placed one average
step (of the previous fragment's last step and the new fragment's first step) after
the previous last frame, so velocity, not only position, stays continuous.

:func:`stitch_fragments_fast` is the compiled twin (numba) that synthesis runs once
numba is loaded; :func:`stitch_fragments` is the reference the tests hold it to.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SeamReport", "stitch_fragments", "stitch_fragments_fast"]


@dataclass(frozen=True)
class SeamReport:
    """What happened at each seam: ``frame`` (first frame of the new fragment),
    ``mean_deg`` and ``max_deg`` of the difference, ``blended``."""

    frame: np.ndarray
    mean_deg: np.ndarray
    max_deg: np.ndarray
    blended: np.ndarray


def stitch_fragments(fragments: list[np.ndarray], fps: float, blend_mean_deg: float = 5.0,
                     blend_max_deg: float = 20.0, blend_duration_s: float = 0.5,
                     mask: np.ndarray | None = None) -> tuple[np.ndarray, SeamReport]:
    """Concatenate finger-curve fragments with offsets and blends at the seams.

    Parameters
    ----------
    fragments : list of (n_i, C) float
        Finger DOF curves in degrees, one per segment, in order.
    fps : float
        Frames per second.
    blend_mean_deg, blend_max_deg : float
        Thresholds on the mean and maximum absolute seam difference (degrees) above
        which the difference is blended out instead of kept as an offset.
    blend_duration_s : float
        Length of the linear blend.
    mask : (C,) bool, optional
        DOFs that count for the thresholds (all by default); others are still offset.

    Returns
    -------
    curves : (sum n_i, C) float
    seams : SeamReport
    """
    if not fragments:
        raise ValueError("Expected at least one fragment")
    frags = [np.asarray(f, dtype=np.float64) for f in fragments]
    C = frags[0].shape[1]
    if any(f.ndim != 2 or f.shape[1] != C or len(f) == 0 for f in frags):
        raise ValueError(f"Expected non-empty (n, {C}) fragments, got {[f.shape for f in frags]}")
    mask = np.ones(C, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    out = [frags[0].copy()]
    frames, means, maxes, blended = [], [], [], []
    start = len(frags[0])
    blend_n = max(1, int(round(blend_duration_s * fps)))
    for f in frags[1:]:
        prev = out[-1]
        step_prev = prev[-1] - prev[-2] if len(prev) >= 2 else np.zeros(C)
        step_new = f[1] - f[0] if len(f) >= 2 else np.zeros(C)
        target = prev[-1] + 0.5 * (step_prev + step_new)
        delta = target - f[0]
        d = np.abs(delta[mask]) if mask.any() else np.zeros(1)
        mean, mx = float(d.mean()), float(d.max())
        blend = mean > blend_mean_deg or mx > blend_max_deg
        if blend:
            L = min(blend_n, len(f))
            ramp = np.zeros(len(f))
            ramp[:L] = 1.0 - np.arange(L) / L
            new = f + ramp[:, None] * delta[None, :]
        else:
            new = f + delta[None, :]
        out.append(new)
        frames.append(start)
        means.append(mean)
        maxes.append(mx)
        blended.append(blend)
        start += len(f)
    report = SeamReport(np.array(frames, dtype=np.int64), np.array(means), np.array(maxes),
                        np.array(blended, dtype=bool))
    return np.concatenate(out, axis=0), report


def stitch_fragments_fast(curves: np.ndarray, bounds: np.ndarray, fps: float, blend_mean_deg: float = 5.0,
                          blend_max_deg: float = 20.0, blend_duration_s: float = 0.5,
                          mask: np.ndarray | None = None, kernels=None) -> tuple[np.ndarray, SeamReport]:
    """:func:`stitch_fragments` of the fragments ``curves[bounds[i]:bounds[i + 1]]`` ``(T, C)``, compiled.

    Same result (the seam means are summed in another order: equal to rounding). ``kernels``:
    the module of :func:`~usdhands.algorithms.synthesis.output_warp.play_kernels` (numba's
    :mod:`~usdhands.algorithms.synthesis._play_kernel` when None).
    """
    if kernels is None:
        from usdhands.algorithms.synthesis import _play_kernel as kernels
    kern = kernels

    x = np.ascontiguousarray(curves, dtype=np.float64)
    b = np.ascontiguousarray(bounds, dtype=np.int64)
    if x.ndim != 2 or b.ndim != 1 or len(b) < 2 or b[0] != 0 or b[-1] != len(x) or (np.diff(b) <= 0).any():
        raise ValueError(f"Expected curves (T, C) and increasing bounds from 0 to T, got {x.shape} and {b.tolist()}")
    C = x.shape[1]
    m = np.ones(C, dtype=bool) if mask is None else np.ascontiguousarray(mask, dtype=bool)
    out = np.empty_like(x)
    S = len(b) - 2
    means, maxes, blended = np.zeros(S), np.zeros(S), np.zeros(S, dtype=bool)
    kern.stitch(x, b, m, float(blend_mean_deg), float(blend_max_deg), max(1, int(round(blend_duration_s * fps))),
                out, means, maxes, blended)
    return out, SeamReport(b[1:-1].copy(), means, maxes, blended)

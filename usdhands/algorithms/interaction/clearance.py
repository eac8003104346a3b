"""How close a capsule's axis comes to the colliders, by a search that cannot miss a contact.

Signed distance is 1-Lipschitz: between two axis samples ``h`` apart with distances
``d0`` and ``d1``, no point of the axis is nearer than ``(d0 + d1 - h) / 2``. Starting
from the axis end points, intervals whose bound is below what is asked are halved and
their midpoints measured, all capsules together (one collider query per level), until
every interval is cleared, a sample is found too close, or the intervals are shorter
than ``resolution``, where the bound is within ``resolution / 2`` of the samples.
A capsule of radius ``r`` is clear of the colliders by ``margin`` where every point of
its axis is at least ``r + margin`` away.
"""

from __future__ import annotations

import numpy as np

__all__ = ["axis_clearance"]


def axis_clearance(colliders, frames: np.ndarray, a: np.ndarray, b: np.ndarray, need: np.ndarray,
                   resolution: float, *, find_depth: bool = False, max_levels: int = 24,
                   end_distances: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Bounds on the smallest signed distance along each capsule axis.

    Parameters
    ----------
    colliders : Colliders
        Anything with ``signed_distance(frames, points, cutoff)`` (lower bounds beyond cutoff).
    frames : (K,) int
        Clip frame of each capsule.
    a, b : (K, 3) float
        Axis end points, clip units.
    need : (K,) float
        The distance each axis must keep (radius + margin), clip units.
    resolution : float
        Shortest interval searched, clip units; the answer is within half of it.
    find_depth : bool
        False: stop a capsule as soon as it is known to pass or fail ``need`` (a
        clearance test). True: keep refining below ``need`` until ``upper - lower <=
        resolution`` (a penetration depth).
    end_distances : ((K,), (K,)) float, optional
        The signed distances at ``a`` and ``b`` when the caller has measured them (a chain's
        segments share their joints), exact wherever below ``need`` plus the axis length
        (lower bounds beyond, as ``colliders`` gives them).

    Returns
    -------
    lower, upper : (K,) float
        The axis's smallest signed distance lies in ``[lower, upper]`` wherever
        ``lower < need``; where ``lower >= need`` the axis is clear (``upper`` is then a
        sampled distance). Clear by the test: ``lower >= need - resolution / 2``.
    """
    frames = np.asarray(frames, dtype=np.int64)
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    need = np.asarray(need, dtype=np.float64)
    K = len(frames)
    length = np.linalg.norm(b - a, axis=1)
    if end_distances is None:
        ends = np.concatenate([a, b])
        f2 = np.concatenate([frames, frames])
        cut = np.concatenate([need, need]) + np.concatenate([length, length])
        d = colliders.signed_distance(f2, ends, cut)
        d0, d1 = d[:K], d[K:]
    else:
        d0, d1 = (np.asarray(d, dtype=np.float64) for d in end_distances)
    upper = np.minimum(d0, d1)
    # open intervals: capsule index, parameters t0 < t1 and distances at both ends
    cap = np.arange(K)
    t0 = np.zeros(K)
    t1 = np.ones(K)
    lower = np.full(K, np.inf)
    for _ in range(max_levels):
        h = (t1 - t0) * length[cap]
        lb = np.minimum(0.5 * (d0 + d1 - h), np.minimum(d0, d1))
        if find_depth:
            open_ = (lb < need[cap]) & (lb < upper[cap] - resolution)
        else:
            open_ = (lb < need[cap]) & (upper[cap] >= need[cap])
        open_ &= h > resolution
        np.minimum.at(lower, cap[~open_], lb[~open_])
        if not open_.any():
            cap = cap[:0]
            break
        cap, t0, t1, d0, d1 = cap[open_], t0[open_], t1[open_], d0[open_], d1[open_]
        tm = 0.5 * (t0 + t1)
        pm = a[cap] + tm[:, None] * (b[cap] - a[cap])
        dm = colliders.signed_distance(frames[cap], pm, need[cap] + 0.5 * (t1 - t0) * length[cap])
        np.minimum.at(upper, cap, dm)
        cap = np.concatenate([cap, cap])
        t0, t1 = np.concatenate([t0, tm]), np.concatenate([tm, t1])
        d0, d1 = np.concatenate([d0, dm]), np.concatenate([dm, d1])
    if len(cap):
        h = (t1 - t0) * length[cap]
        np.minimum.at(lower, cap, np.minimum(0.5 * (d0 + d1 - h), np.minimum(d0, d1)))
    return np.minimum(lower, upper), upper

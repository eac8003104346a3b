"""Distances already measured along a finger chain, kept so that testing it again costs fewer queries.

The correction and the collision term test the same chain at the same frame many times
(the input pose, its smoothed version, every bisection step of the opening, the report's
depth). Signed distance is 1-Lipschitz and a collider is where it was at the same frame,
so a distance ``d`` measured at ``p`` bounds the distance at any ``q`` of that frame from
below by ``d - |q - p|``. :class:`ChainDistances` keeps, per row (a frame, or a candidate
at a frame) and joint, the last distance measured there, and per capsule the last search:

- a joint met again at the very same position takes the value measured there;
- a capsule whose two end bounds ``L0, L1`` already give ``min((L0 + L1 - h) / 2, L0, L1) >= need``
  (``h`` its axis length) is clear without a query: the search on the exact end values, at
  least these bounds, closes it at its first level with the same answer;
- a capsule met again with the same ends, need and end distances takes the result of its
  last search (the search is a function of them);
- everything else is measured as without this memo, with the same cutoffs.

A value beyond its cutoff is a lower bound (:meth:`usdhands.algorithms.interaction.colliders.Colliders.signed_distance`);
it only ever closes the capsules it ends at their first level, whichever bound it is, so
the answers (clear or not, the depth) are those of the exact search, bit for bit.
"""

from __future__ import annotations

import numpy as np

from usdhands.algorithms.interaction.clearance import axis_clearance

__all__ = ["ChainDistances", "joint_cutoffs"]


def joint_cutoffs(need: np.ndarray, length: np.ndarray) -> np.ndarray:
    """Distance below which each joint is measured exactly, ``(K, m + 1)``: the largest ``need + length``
    of the (one or two) capsules ``(K, m)`` it ends; beyond it a lower bound does."""
    K, m = need.shape
    cut = np.full((K, m + 1), -np.inf)
    cut[:, :-1] = need + length
    cut[:, 1:] = np.maximum(cut[:, 1:], need + length)
    return cut


class ChainDistances:
    """What was measured on one chain of ``joints`` joints (its tip counted), for ``rows`` rows.

    A row is whatever the caller tests repeatedly: a clip frame in the correction, one
    candidate at one frame in the collision term. Every row must always be at the same
    clip frame (its colliders' placement), and the chain's capsules keep their radii.
    """

    def __init__(self, rows: int, joints: int):
        self.position = np.full((rows, joints, 3), np.nan)
        self.value = np.zeros((rows, joints))
        self.cutoff = np.full((rows, joints), -np.inf)  # -inf: nothing measured; exact below it
        self.search_key = np.full((rows, joints - 1, 9), np.nan)  # a, b, need, d(a), d(b) of the last search
        self.search = np.zeros((rows, joints - 1, 2))  # its lower and upper
        self.search_resolution = np.full((rows, joints - 1), np.nan)

    def view(self, start: int, stop: int) -> "ChainDistances":
        """Rows ``start`` to ``stop`` as a memo of their own (sharing this one's arrays: what either
        measures, both know)."""
        out = ChainDistances.__new__(ChainDistances)
        for name in ("position", "value", "cutoff", "search_key", "search", "search_resolution"):
            setattr(out, name, getattr(self, name)[start:stop])
        return out

    def axis_bounds(self, colliders, rows: np.ndarray, frames: np.ndarray, a: np.ndarray, b: np.ndarray,
                    need: np.ndarray, resolution: float, first: int = 0,
                    find_depth: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """:func:`~usdhands.algorithms.interaction.clearance.axis_clearance` on a chain's capsules from
        segment ``first`` on, reusing what was measured.

        Parameters
        ----------
        rows, frames : (K,) int
            Memo row and clip frame of each chain pose.
        a, b : (K, m, 3) float
            The capsules' axis end points (segment ``first + i`` is ``a[:, i]``-``b[:, i]``), clip units;
            ``b[:, i] == a[:, i + 1]``.
        need : (K, m) float
            Radius plus margin of each capsule, clip units.
        resolution : float
        find_depth : bool

        Returns
        -------
        lower, upper : (K, m) float
            As ``axis_clearance`` gives them (``lower`` already the least of both); for a capsule
            proved clear without a search, both at least ``need``.
        """
        rows = np.asarray(rows, dtype=np.int64)
        frames = np.asarray(frames, dtype=np.int64)
        K, m = need.shape
        joints = np.concatenate([a, b[:, -1:]], axis=1)  # (K, m + 1, 3)
        length = np.linalg.norm(b - a, axis=2)
        cut = joint_cutoffs(need, length)
        slots = slice(first, first + m + 1)
        old_p = self.position[rows, slots]
        old_v = self.value[rows, slots]
        old_c = self.cutoff[rows, slots]
        measured = old_c > -np.inf
        # the same point: its value is what a query would give (exact below its old cutoff), or a bound
        # beyond the new one
        same = measured & np.all(old_p == joints, axis=2) & ((old_v < old_c) | (old_v >= cut))
        with np.errstate(invalid="ignore"):
            bound = np.where(same, old_v,
                             np.where(measured, old_v - np.linalg.norm(joints - np.nan_to_num(old_p), axis=2), -np.inf))
        lb = np.minimum(0.5 * (bound[:, :-1] + bound[:, 1:] - length), np.minimum(bound[:, :-1], bound[:, 1:]))
        proved = lb >= need
        ends_of_open = np.zeros((K, m + 1), dtype=bool)
        ends_of_open[:, :-1] |= ~proved
        ends_of_open[:, 1:] |= ~proved
        ask = ends_of_open & ~same
        d = bound
        if ask.any():
            kk, jj = np.nonzero(ask)
            d = bound.copy()
            d[kk, jj] = colliders.signed_distance(frames[kk], joints[kk, jj], cut[kk, jj])
            self.position[rows[kk], first + jj] = joints[kk, jj]
            self.value[rows[kk], first + jj] = d[kk, jj]
            self.cutoff[rows[kk], first + jj] = cut[kk, jj]
        lower = np.where(proved, lb, 0.0)
        upper = np.where(proved, np.minimum(bound[:, :-1], bound[:, 1:]), 0.0)
        todo = ~proved
        key = np.concatenate([a, b, need[..., None], d[:, :-1, None], d[:, 1:, None]], axis=2)  # (K, m, 9)
        caps = slice(first, first + m)
        hit = np.zeros((K, m), dtype=bool)
        if not find_depth:
            hit = todo & np.all(self.search_key[rows, caps] == key, axis=2) & \
                (self.search_resolution[rows, caps] == resolution)
            if hit.any():
                kk, ii = np.nonzero(hit)
                lower[kk, ii], upper[kk, ii] = self.search[rows[kk], first + ii].T
        search = todo & ~hit
        if search.any():
            kk, ii = np.nonzero(search)
            lo, up = axis_clearance(colliders, frames[kk], a[kk, ii], b[kk, ii], need[kk, ii], resolution,
                                    find_depth=find_depth, end_distances=(d[kk, ii], d[kk, ii + 1]))
            lower[kk, ii], upper[kk, ii] = lo, up
            if not find_depth:
                self.search_key[rows[kk], first + ii] = key[kk, ii]
                self.search[rows[kk], first + ii] = np.stack([lo, up], axis=1)
                self.search_resolution[rows[kk], first + ii] = resolution
        return lower, upper

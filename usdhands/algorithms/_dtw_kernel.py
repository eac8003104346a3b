"""numba kernels behind :func:`usdhands.algorithms.segment_cost.knn_segments`.

Kept apart so importing the algorithms does not compile anything; the first call
compiles (and caches on disk). See :mod:`usdhands.algorithms.segment_cost` for the
method; :func:`usdhands.algorithms.segment_cost.dtw_align` is the NumPy twin.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

INF = np.inf


@njit(cache=True)
def window(n, m, band, lo, hi):
    """Fill ``lo (n,)`` and ``hi (n,)`` with the band of the asymmetric warp (see band_window)."""
    if n == 1:
        lo[0] = 0
        hi[0] = 0 if m == 1 else -1
        return
    r = max(band * m, 1.0)
    for i in range(n):
        c = i * (m - 1) / (n - 1)
        a = max(0, (m - 1) - 2 * (n - 1 - i))
        a = max(a, int(math.ceil(c - r - 1e-9)))
        b = min(m - 1, 2 * i)
        b = min(b, int(math.floor(c + r + 1e-9)))
        lo[i] = a
        hi[i] = b


@njit(cache=True)
def _envelope_lb(q, qs, n, d, ds, m, lo, hi, rows, upq, dnq):
    """LB_Keogh rows: ``rows[i]`` = squared distance of q[i] to the envelope of d[lo_i..hi_i].

    Windows are monotone in i, so a deque per dimension gives the running max/min in
    O(n + m). Returns the total (not divided by n).
    """
    D = q.shape[1]
    for i in range(n):
        rows[i] = 0.0
    for k in range(D):
        # running max
        head = 0
        tail = 0
        nxt = 0
        for i in range(n):
            while nxt <= hi[i]:
                v = d[ds + nxt, k]
                while tail > head and d[ds + upq[tail - 1], k] <= v:
                    tail -= 1
                upq[tail] = nxt
                tail += 1
                nxt += 1
            while upq[head] < lo[i]:
                head += 1
            u = d[ds + upq[head], k]
            x = q[qs + i, k]
            if x > u:
                rows[i] += (x - u) * (x - u)
        # running min
        head = 0
        tail = 0
        nxt = 0
        for i in range(n):
            while nxt <= hi[i]:
                v = d[ds + nxt, k]
                while tail > head and d[ds + dnq[tail - 1], k] >= v:
                    tail -= 1
                dnq[tail] = nxt
                tail += 1
                nxt += 1
            while dnq[head] < lo[i]:
                head += 1
            low = d[ds + dnq[head], k]
            x = q[qs + i, k]
            if x < low:
                rows[i] += (low - x) * (low - x)
    total = 0.0
    for i in range(n):
        total += rows[i]
    return total


@njit(cache=True)
def _dtw(q, qs, n, d, ds, m, lo, hi, tail_lb, limit, prev, cur):
    """Asymmetric DTW total cost (not divided by n); INF when abandoned (partial > limit)."""
    D = q.shape[1]
    for j in range(m):
        prev[j] = INF
        cur[j] = INF
    s = 0.0
    for k in range(D):
        t = q[qs, k] - d[ds, k]
        s += t * t
    prev[0] = s
    if s + tail_lb[0] > limit:
        return INF
    for i in range(1, n):
        a, b = lo[i], hi[i]
        row_min = INF
        for j in range(a, b + 1):
            best = prev[j]
            if j >= 1 and prev[j - 1] < best:
                best = prev[j - 1]
            if j >= 2 and prev[j - 2] < best:
                best = prev[j - 2]
            if best == INF:
                cur[j] = INF
                continue
            s = 0.0
            for k in range(D):
                t = q[qs + i, k] - d[ds + j, k]
                s += t * t
            v = best + s
            cur[j] = v
            if v < row_min:
                row_min = v
        # clear what the previous row held outside this row's window
        pa, pb = lo[i - 1], hi[i - 1]
        for j in range(pa, pb + 1):
            if j < a or j > b:
                prev[j] = INF
        if row_min + tail_lb[i] > limit:
            return INF
        for j in range(a, b + 1):
            prev[j] = cur[j]
            cur[j] = INF
    return prev[m - 1]


@njit(cache=True)
def _insert(idx_row, cost_row, c, v):
    """Insert candidate c of cost v into the sorted top-k row (ties: lower index first)."""
    k = idx_row.shape[0]
    pos = k
    while pos > 0 and (cost_row[pos - 1] > v or (cost_row[pos - 1] == v and (idx_row[pos - 1] > c or idx_row[pos - 1] < 0))):
        pos -= 1
    if pos >= k:
        return
    for p in range(k - 1, pos, -1):
        idx_row[p] = idx_row[p - 1]
        cost_row[p] = cost_row[p - 1]
    idx_row[pos] = c
    cost_row[pos] = v


@njit(parallel=True, cache=True)
def search(qf, qb, qg, df, ds, dg, k, length_factor, band, prune, out_idx, out_cost, stats):
    """Top-k eq. 1 costs per query segment; see knn_segments."""
    Q = qb.shape[0]
    N = ds.shape[0]
    max_m = 0
    for c in range(N):
        if ds[c, 1] - ds[c, 0] > max_m:
            max_m = ds[c, 1] - ds[c, 0]
    for qi in prange(Q):
        qs = qb[qi, 0]
        n = qb[qi, 1] - qb[qi, 0]
        lo = np.empty(n, dtype=np.int64)
        hi = np.empty(n, dtype=np.int64)
        rows = np.empty(n)
        tail = np.empty(n)
        upq = np.empty(max_m + 1, dtype=np.int64)
        dnq = np.empty(max_m + 1, dtype=np.int64)
        prev = np.empty(max_m + 1)
        cur = np.empty(max_m + 1)
        cand = np.empty(N, dtype=np.int64)
        lbs = np.empty(N)
        nc = 0
        for c in range(N):
            m = ds[c, 1] - ds[c, 0]
            if dg[c] == qg[qi]:
                continue
            if m * length_factor < n - 1e-9 or m > n * length_factor + 1e-9:
                continue
            if m > 2 * n - 1 and not (n == 1 and m == 1):
                continue
            window(n, m, band, lo, hi)
            feasible = True
            for i in range(n):
                if lo[i] > hi[i]:
                    feasible = False
            if not feasible:
                continue
            cand[nc] = c
            if prune:
                lbs[nc] = _envelope_lb(qf, qs, n, df, ds[c, 0], m, lo, hi, rows, upq, dnq)
            else:
                lbs[nc] = 0.0
            nc += 1
        order = np.argsort(lbs[:nc], kind="mergesort")
        idx_row = out_idx[qi]
        cost_row = out_cost[qi]
        aligned = 0
        abandoned = 0
        for oi in range(nc):
            c = cand[order[oi]]
            limit = cost_row[k - 1] * n  # INF until k found
            if prune and lbs[order[oi]] > limit:
                break
            m = ds[c, 1] - ds[c, 0]
            window(n, m, band, lo, hi)
            if prune:
                _envelope_lb(qf, qs, n, df, ds[c, 0], m, lo, hi, rows, upq, dnq)
                acc = 0.0
                for i in range(n - 1, -1, -1):
                    tail[i] = acc
                    acc += rows[i]
            else:
                for i in range(n):
                    tail[i] = 0.0
            aligned += 1
            v = _dtw(qf, qs, n, df, ds[c, 0], m, lo, hi, tail, limit, prev, cur)
            if v == INF:
                abandoned += 1
                continue
            _insert(idx_row, cost_row, c, v / n)
        stats[qi, 0] = nc
        stats[qi, 1] = aligned
        stats[qi, 2] = abandoned

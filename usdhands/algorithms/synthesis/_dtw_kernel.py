"""numba kernels behind :func:`usdhands.algorithms.synthesis.segment_cost.knn_segments`.

Kept apart so importing the algorithms does not compile anything; the first call
compiles (and caches on disk). See :mod:`usdhands.algorithms.synthesis.segment_cost` for the
method; :func:`usdhands.algorithms.synthesis.segment_cost.dtw_align` is the NumPy twin.
"""

from __future__ import annotations

import math

import numpy as np
from usdhands.jit import njit, prange

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
def _dtw12(q, qs, n, d, ds, m, lo, hi, tail_lb, limit, prev, cur):
    """:func:`_dtw` for D = 12 (the paper's wrist features), to the bit.

    The query row is held in twelve locals and the local cost unrolled (the same sum,
    dimension by dimension from the first), which the compiler cannot do for a D known
    only at run time: about a fifth less time for the whole search.
    """
    for j in range(m):
        prev[j] = INF
        cur[j] = INF
    s = 0.0
    for k in range(12):
        t = q[qs, k] - d[ds, k]
        s += t * t
    prev[0] = s
    if s + tail_lb[0] > limit:
        return INF
    for i in range(1, n):
        a, b = lo[i], hi[i]
        x0 = q[qs + i, 0]
        x1 = q[qs + i, 1]
        x2 = q[qs + i, 2]
        x3 = q[qs + i, 3]
        x4 = q[qs + i, 4]
        x5 = q[qs + i, 5]
        x6 = q[qs + i, 6]
        x7 = q[qs + i, 7]
        x8 = q[qs + i, 8]
        x9 = q[qs + i, 9]
        x10 = q[qs + i, 10]
        x11 = q[qs + i, 11]
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
            t = x0 - d[ds + j, 0]
            s = t * t
            t = x1 - d[ds + j, 1]
            s += t * t
            t = x2 - d[ds + j, 2]
            s += t * t
            t = x3 - d[ds + j, 3]
            s += t * t
            t = x4 - d[ds + j, 4]
            s += t * t
            t = x5 - d[ds + j, 5]
            s += t * t
            t = x6 - d[ds + j, 6]
            s += t * t
            t = x7 - d[ds + j, 7]
            s += t * t
            t = x8 - d[ds + j, 8]
            s += t * t
            t = x9 - d[ds + j, 9]
            s += t * t
            t = x10 - d[ds + j, 10]
            s += t * t
            t = x11 - d[ds + j, 11]
            s += t * t
            v = best + s
            cur[j] = v
            if v < row_min:
                row_min = v
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


@njit(cache=True)
def _sqdist(q, qi, d, di):
    s = 0.0
    for k in range(q.shape[1]):
        t = q[qi, k] - d[di, k]
        s += t * t
    return s


@njit(parallel=True, cache=True)
def search(qf, qb, qg, df, ds, dg, k, length_factor, band, bound, out_idx, out_cost, stats):
    """Top-k eq. 1 costs per query segment; see knn_segments.

    Candidates are visited in order of the distance between segment means (a cheap
    guess that finds good neighbours first, so the k-th best cost drops fast); each is
    then checked against lower bounds before it is aligned (``bound``: 0 none, 1 the
    fixed end points j(0) = 0, j(n-1) = m-1 in O(D), 2 those and LB_Keogh in
    O((n + m) D), whose rows also tighten early abandoning).
    """
    Q = qb.shape[0]
    N = ds.shape[0]
    D = qf.shape[1]
    max_m = 0
    for c in range(N):
        if ds[c, 1] - ds[c, 0] > max_m:
            max_m = ds[c, 1] - ds[c, 0]
    dmean = np.zeros((N, D))
    for c in range(N):
        m = ds[c, 1] - ds[c, 0]
        for j in range(ds[c, 0], ds[c, 1]):
            for kk in range(D):
                dmean[c, kk] += df[j, kk]
        for kk in range(D):
            dmean[c, kk] /= m
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
        guess = np.empty(N)
        qmean = np.zeros(D)
        for i in range(n):
            for kk in range(D):
                qmean[kk] += qf[qs + i, kk]
        for kk in range(D):
            qmean[kk] /= n
        nc = 0
        for c in range(N):
            m = ds[c, 1] - ds[c, 0]
            if dg[c] == qg[qi]:
                continue
            if m * length_factor < n - 1e-9 or m > n * length_factor + 1e-9:
                continue
            if m > 2 * n - 1 and not (n == 1 and m == 1):
                continue
            if n == 1 and m != 1:
                continue
            cand[nc] = c
            g = 0.0
            for kk in range(D):
                t = qmean[kk] - dmean[c, kk]
                g += t * t
            guess[nc] = g
            nc += 1
        order = np.argsort(guess[:nc], kind="mergesort")
        idx_row = out_idx[qi]
        cost_row = out_cost[qi]
        aligned = 0
        abandoned = 0
        pruned = 0
        for oi in range(nc):
            c = cand[order[oi]]
            m = ds[c, 1] - ds[c, 0]
            # totals are compared, not costs / n, so ties stay exact; the slack keeps
            # rounding in the bounds from dropping a candidate that ties the k-th
            limit = cost_row[k - 1] * (1.0 + 1e-12) + 1e-12  # INF until k found
            if bound >= 1:
                kim = _sqdist(qf, qs, df, ds[c, 0])
                if n > 1:
                    kim += _sqdist(qf, qs + n - 1, df, ds[c, 0] + m - 1)
                if kim > limit:
                    pruned += 1
                    continue
            window(n, m, band, lo, hi)
            if bound >= 2:
                lb = _envelope_lb(qf, qs, n, df, ds[c, 0], m, lo, hi, rows, upq, dnq)
                if lb > limit:
                    pruned += 1
                    continue
                acc = 0.0
                for i in range(n - 1, -1, -1):
                    tail[i] = acc
                    acc += rows[i]
            else:
                for i in range(n):
                    tail[i] = 0.0
            aligned += 1
            if D == 12:
                v = _dtw12(qf, qs, n, df, ds[c, 0], m, lo, hi, tail, limit, prev, cur)
            else:
                v = _dtw(qf, qs, n, df, ds[c, 0], m, lo, hi, tail, limit, prev, cur)
            if v == INF:
                abandoned += 1
                continue
            _insert(idx_row, cost_row, c, v)
        for p in range(k):
            if idx_row[p] >= 0:
                cost_row[p] = cost_row[p] / n
        stats[qi, 0] = nc
        stats[qi, 1] = aligned
        stats[qi, 2] = abandoned
        stats[qi, 3] = pruned


@njit(cache=True)
def align_path(q, d, band, path):
    """Asymmetric DTW of one pair with its warp path (the numba twin of dtw_align).

    Fills ``path (n,)`` and returns the total cost (not divided by n), INF if no warp fits.
    Ties prefer the smaller step, as ``dtw_align`` does.
    """
    n = q.shape[0]
    m = d.shape[0]
    lo = np.empty(n, dtype=np.int64)
    hi = np.empty(n, dtype=np.int64)
    window(n, m, band, lo, hi)
    for i in range(n):
        if lo[i] > hi[i]:
            return INF
    acc = np.full((n, m), INF)
    step = np.zeros((n, m), dtype=np.int8)
    acc[0, 0] = _sqdist(q, 0, d, 0)
    for i in range(1, n):
        for j in range(lo[i], hi[i] + 1):
            best = acc[i - 1, j]
            st = 0
            if j >= 1 and acc[i - 1, j - 1] < best:
                best = acc[i - 1, j - 1]
                st = 1
            if j >= 2 and acc[i - 1, j - 2] < best:
                best = acc[i - 1, j - 2]
                st = 2
            if best == INF:
                continue
            acc[i, j] = best + _sqdist(q, i, d, j)
            step[i, j] = st
    if acc[n - 1, m - 1] == INF:
        return INF
    j = m - 1
    for i in range(n - 1, -1, -1):
        path[i] = j
        if i > 0:
            j -= step[i, j]
    return acc[n - 1, m - 1]

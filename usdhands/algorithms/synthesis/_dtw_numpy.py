"""NumPy twins of the search and alignment kernels, for searches too small to pay for numba.

Importing numba and loading the first cached kernel takes about half a second (numba's
own start-up, which also imports ``scipy.linalg``), more than the whole search of a
short clip against the bundled database (about 6,000 candidate pairs, a million band
cells). :func:`search` and :func:`align_paths` do the same work as
``_dtw_kernel.search`` and ``_dtw_kernel.align_path`` with NumPy, vectorised over all
candidate pairs one DTW row at a time (the cells of a row of every pair still running
in one flat array), and give **the same numbers to the bit**: every local cost is
summed dimension by dimension from 0.0 as in the kernel, the recurrence takes the same
minimum, means are summed frame by frame, ties go the same way. The search also
reports the kernel's statistics exactly (candidates, aligned, abandoned, pruned): the
alignments are computed in rounds against an upper bound of the kernel's running limit
(the ``k``-th best cost so far), then the kernel's visit is replayed in order.

:func:`usdhands.algorithms.synthesis.segment_cost.knn_segments` chooses between the two
(:func:`estimated_cells`); the tests hold this module to the kernels.
"""

from __future__ import annotations

import numpy as np

__all__ = ["search", "align_paths", "estimated_cells"]

INF = np.inf
#: Visit ranks (in multiples of ``k``) that end a round of alignments in :func:`search`:
#: the first ``k`` candidates of every query, then the next ``2k``, then the rest, each
#: round abandoning against the limit the previous one reached (measured on the
#: sample conversation: 1.39 M cells in two rounds, 1.06 M in three, no gain from four).
_ROUND_ENDS = (1, 3)


def estimated_cells(query_lengths: np.ndarray, db_lengths: np.ndarray, length_factor: float, band: float) -> float:
    """DTW band cells of every candidate pair, without pruning: the work of a search.

    Parameters
    ----------
    query_lengths : (Q,) int
        Input segment lengths ``n``.
    db_lengths : (N,) int
        Database segment lengths ``m``.

    Returns
    -------
    float
        ``Σ n · min(m, 2 · max(band · m, 1) + 1)`` over the pairs whose lengths are
        within ``length_factor`` of each other.
    """
    n = np.asarray(query_lengths, dtype=np.float64)
    m = np.sort(np.asarray(db_lengths, dtype=np.float64))
    width = np.minimum(m, 2 * np.maximum(band * m, 1.0) + 1)
    prefix = np.concatenate([[0.0], np.cumsum(width)])
    lo = np.searchsorted(m, n / length_factor - 1e-9, side="left")
    hi = np.searchsorted(m, np.minimum(n * length_factor, 2 * n - 1) + 1e-9, side="right")
    return float((n * (prefix[np.maximum(hi, lo)] - prefix[lo])).sum())


def _sequential_means(f: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """Means ``(B, D)`` of ``f[start:stop]``, summed frame by frame from 0.0 as the kernel does."""
    starts = bounds[:, 0]
    lengths = bounds[:, 1] - starts
    acc = np.zeros((len(bounds), f.shape[1]))
    for t in range(int(lengths.max()) if len(lengths) else 0):
        live = np.nonzero(t < lengths)[0]
        acc[live] += f[starts[live] + t]
    return acc / lengths[:, None]


def _row_windows(i: int, n: np.ndarray, m: np.ndarray, band) -> tuple[np.ndarray, np.ndarray]:
    """``lo``, ``hi`` of row ``i`` for pairs of lengths ``n``, ``m``: the kernel's ``window``."""
    c = (i * (m - 1)) / np.maximum(n - 1, 1)
    r = np.maximum(band * m, 1.0)
    lo = np.maximum(np.maximum(0, (m - 1) - 2 * (n - 1 - i)), np.ceil(c - r - 1e-9).astype(np.int64))
    hi = np.minimum(np.minimum(m - 1, 2 * i), np.floor(c + r + 1e-9).astype(np.int64))
    one = n == 1
    if one.any():
        lo = np.where(one, 0, lo)
        hi = np.where(one, np.where(m == 1, 0, -1), hi)
    return lo, hi


def _local_costs(qT: np.ndarray, dT: np.ndarray, qrows: np.ndarray, drows: np.ndarray) -> np.ndarray:
    """``Σ_k (q[qrow, k] − d[drow, k])²`` per cell, summed over k in order from 0.0 (the kernel's sum)."""
    s = np.zeros(len(qrows))
    for k in range(qT.shape[0]):
        t = qT[k].take(qrows)
        t -= dT[k].take(drows)
        t *= t
        s += t
    return s


def _banded_dtw(qT, dT, qs, n, d0, m, band, limit, keep_steps=False):
    """The asymmetric DTW of many pairs, row by row over the band cells of the pairs still running.

    Parameters
    ----------
    qT, dT : (D, T) and (D, F) float
        Weighted features, dimension-major.
    qs, n, d0, m : (P,) int
        First frame and length of each pair's input and database segment.
    band : float or (P,) float
        Band half-width as a fraction of ``m``.
    limit : (P,) float
        A pair is abandoned at the first row whose cheapest cell exceeds its limit
        (the kernel's early abandoning with no tail bound).
    keep_steps : bool
        Keep each cell's step (0, 1, 2) for :func:`align_paths`.

    Returns
    -------
    total : (P,) float
        ``acc[n-1, m-1]``; inf when abandoned or unreachable.
    worst_row : (P,) float
        The largest row minimum over the rows computed.
    abandoned : (P,) bool
    rows : list or None
        Per row ``i``: the running pairs, their ``lo``, the start of each pair's cells
        and the cells' steps (with ``keep_steps``).
    """
    P = len(qs)
    total = np.full(P, INF)
    band = np.broadcast_to(np.asarray(band, dtype=np.float64), (P,))
    # row 0: the single cell (0, 0) (its window is [0, 0] whenever the pair can be aligned)
    cur = _local_costs(qT, dT, qs, d0)
    worst = cur.copy()
    abandoned = cur > limit
    lo0, hi0 = _row_windows(0, n, m, band)
    empty = lo0 > hi0
    cur[empty] = INF
    finished = (n == 1) & ~abandoned
    total[finished] = np.where(hi0[finished] == m[finished] - 1, cur[finished], INF)
    rows = [(np.arange(P), lo0, np.arange(P), np.zeros(P, np.int8))] if keep_steps else None
    keep = ~abandoned & ~finished
    live = np.nonzero(keep)[0]
    prev, prev_start, prev_lo, prev_hi = cur, np.nonzero(keep)[0], lo0[keep], hi0[keep]
    i = 1
    while len(live):
        nl, ml = n[live], m[live]
        lo, hi = _row_windows(i, nl, ml, band[live])
        width = np.maximum(hi - lo + 1, 0)
        start = np.zeros(len(live), np.int64)
        np.cumsum(width[:-1], out=start[1:])
        cells = int(width.sum())
        owner = np.repeat(np.arange(len(live)), width)
        j = np.arange(cells) - start[owner] + lo[owner]
        # predecessors (i-1, j), (i-1, j-1), (i-1, j-2): the first of the least (the kernel's strict <)
        base = prev_start[owner] - prev_lo[owner]
        plo, phi = prev_lo[owner], prev_hi[owner]
        best = np.full(cells, INF)
        step = np.zeros(cells, np.int8) if keep_steps else None
        for delta in range(3):
            jj = j - delta
            ok = (jj >= plo) & (jj <= phi)
            cand = np.where(ok, prev[np.where(ok, base + jj, 0)], INF)
            if keep_steps:
                step[cand < best] = delta
            np.minimum(best, cand, out=best)
        cur = best + _local_costs(qT, dT, qs[live][owner] + i, d0[live][owner] + j)
        has = width > 0
        row_min = np.full(len(live), INF)
        if cells:
            row_min[has] = np.minimum.reduceat(cur, start[has])
        worst[live] = np.maximum(worst[live], row_min)
        stop = row_min > limit[live]
        abandoned[live[stop]] = True
        last = (nl - 1 == i) & ~stop
        if last.any():
            at_end = last & has & (hi == ml - 1)
            total[live[at_end]] = cur[(start + width - 1)[at_end]]
        if keep_steps:
            rows.append((live, lo, start, step))
        keep = ~stop & ~last
        prev, prev_start, prev_lo, prev_hi = cur, start[keep], lo[keep], hi[keep]
        live = live[keep]
        i += 1
    return total, worst, abandoned, rows


def search(qf, qb, qg, df, ds, dg, k, length_factor, band, bound, out_idx, out_cost, stats) -> None:
    """``_dtw_kernel.search`` in NumPy for ``bound`` 0 (none) or 1 (end points): same outputs, same statistics.

    Fills ``out_idx (Q, k)``, ``out_cost (Q, k)`` and ``stats (Q, 4)`` (candidates,
    aligned, abandoned, pruned) as the kernel does; see
    :func:`usdhands.algorithms.synthesis.segment_cost.knn_segments`.
    """
    if bound not in (0, 1):
        raise ValueError(f"the NumPy search has the bounds 0 and 1, not {bound}")
    Q, N, D = len(qb), len(ds), qf.shape[1]
    qT, dT = np.ascontiguousarray(qf.T), np.ascontiguousarray(df.T)
    n, m = qb[:, 1] - qb[:, 0], ds[:, 1] - ds[:, 0]
    # candidates of each query, visited in the order of the distance between segment means
    qmean, dmean = _sequential_means(qf, qb), _sequential_means(df, ds)
    nq, md = n[:, None], m[None, :]
    ok = dg[None, :] != qg[:, None]
    ok &= ~((md * length_factor < nq - 1e-9) | (md > nq * length_factor + 1e-9))
    ok &= ~((md > 2 * nq - 1) & ~((nq == 1) & (md == 1)))
    ok &= ~((nq == 1) & (md != 1))
    guess = np.zeros((Q, N))
    for kk in range(D):
        t = qmean[:, kk][:, None] - dmean[:, kk][None, :]
        guess += t * t
    pq, pc = np.nonzero(ok)
    order = np.lexsort((pc, guess[pq, pc], pq))  # per query, stable in the guess (the kernel's mergesort)
    pq, pc = pq[order], pc[order]
    P = len(pq)
    pn, pm, pqs, pds = n[pq], m[pc], qb[pq, 0], ds[pc, 0]
    kim = np.full(P, -INF)
    if bound == 1:
        kim = _local_costs(qT, dT, pqs, pds)
        two = pn > 1
        kim[two] += _local_costs(qT, dT, (pqs + pn - 1)[two], (pds + pm - 1)[two])
    count = np.bincount(pq, minlength=Q)
    first = np.zeros(Q, np.int64)
    np.cumsum(count[:-1], out=first[1:])
    rank = np.arange(P) - first[pq]
    total = np.full(P, INF)
    worst = np.full(P, INF)
    abandoned = np.zeros(P, bool)
    limit = np.full(Q, INF)  # an upper bound of the kernel's limit for every later visit
    ends = [e * k for e in _ROUND_ENDS] + [P + 1]
    for r0, r1 in zip([0] + ends[:-1], ends):
        sel = np.nonzero((rank >= r0) & (rank < r1) & (kim <= limit[pq]))[0]
        if len(sel):
            total[sel], worst[sel], abandoned[sel], _ = _banded_dtw(
                qT, dT, pqs[sel], pn[sel], pds[sel], pm[sel], band, limit[pq[sel]])
        # the k-th least total among the candidates visited so far (abandoned ones are above it)
        seen = np.where(rank < r1, total, INF)
        kth = np.full(Q, INF)
        full = count >= k
        kth[full] = seen[np.lexsort((seen, pq))][(first + k - 1)[full]]
        limit = np.where(np.isfinite(kth), kth * (1.0 + 1e-12) + 1e-12, INF)
    # the kernel's visit, replayed: the same limit before each candidate, the same counts
    tl, wl, al, kl, cl = total.tolist(), worst.tolist(), abandoned.tolist(), kim.tolist(), pc.tolist()
    for q in range(Q):
        top: list[tuple[float, int]] = []
        aligned = dropped = pruned = 0
        for p in range(first[q], first[q] + count[q]):
            lim = (top[k - 1][0] if len(top) >= k else INF) * (1.0 + 1e-12) + 1e-12
            if kl[p] > lim:
                pruned += 1
                continue
            aligned += 1
            if al[p] or wl[p] > lim or tl[p] == INF:
                dropped += 1
                continue
            top.append((tl[p], cl[p]))
            top.sort()
            del top[k:]
        for r, (v, c) in enumerate(top):
            out_idx[q, r] = c
            out_cost[q, r] = v / n[q]
        stats[q] = (count[q], aligned, dropped, pruned)


def align_paths(qf: np.ndarray, df: np.ndarray, pairs: np.ndarray, bands: np.ndarray) -> tuple[np.ndarray, list]:
    """``_dtw_kernel.align_path`` for many pairs at once: totals and warp paths, to the bit.

    Parameters
    ----------
    qf, df : (T, D), (F, D) float
        Weighted features.
    pairs : (P, 4) int
        ``[q0, q1, d0, d1)``: the input and database frame ranges of each pair.
    bands : (P,) float
        Band half-width of each pair as a fraction of its database length.

    Returns
    -------
    total : (P,) float
        ``Σ_i |q[i] − d[j(i)]|²`` (not divided by ``n``); inf when no warp fits.
    paths : list of (n,) int
        ``j(i)`` per pair; empty where ``total`` is inf.
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 4)
    qs, n, d0, m = pairs[:, 0], pairs[:, 1] - pairs[:, 0], pairs[:, 2], pairs[:, 3] - pairs[:, 2]
    bands = np.asarray(bands, dtype=np.float64)
    P = len(pairs)
    if not P:
        return np.zeros(0), []
    qT, dT = np.ascontiguousarray(np.asarray(qf, np.float64).T), np.ascontiguousarray(np.asarray(df, np.float64).T)
    total, _, _, rows = _banded_dtw(qT, dT, qs, n, d0, m, bands, np.full(P, INF), keep_steps=True)
    fits = np.isfinite(total)
    path = np.zeros((P, int(n.max())), np.int64)
    j = m - 1
    where = np.full(P, -1, np.int64)  # each pair's place among a row's running pairs
    for i in range(path.shape[1] - 1, -1, -1):
        live, lo, start, step = rows[i]
        where[live] = np.arange(len(live))
        on = np.nonzero(fits & (n > i))[0]
        path[on, i] = j[on]
        if i:
            at = where[on]
            j[on] -= step[start[at] + j[on] - lo[at]]
    return total, [path[p, :n[p]] if fits[p] else np.zeros(0, np.int64) for p in range(P)]

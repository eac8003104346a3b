# cython: language_level=3, boundscheck=False, wraparound=False, initializedcheck=False, cdivision=True
"""The search kernels of :mod:`usdhands.algorithms.synthesis._dtw_kernel`, compiled ahead of time.

The same functions with the same arguments and the same results to the bit (the same
operations in the same order; built without contracting multiplies and adds into fused
ones), compiled when the package is installed (Cython) instead of by numba when a
process first calls them. A process that uses these never imports numba: no start-up
(numba's import and CPU target, about 0.35 s a process), one thread (:func:`search`
runs its query segments one after the other where numba's runs them in parallel).

Used by :func:`usdhands.algorithms.synthesis.segment_cost.knn_segments` and the play
kernels (:mod:`._play_compiled`) through :mod:`usdhands.compiled`. Tests hold each
function to its numba twin and to the NumPy one.
"""

from libc.math cimport ceil, floor, INFINITY
from libc.stdint cimport int64_t
from libc.stdlib cimport malloc, free

import numpy as np

ctypedef const double[:, ::1] cmat
ctypedef const int64_t[:, ::1] cimat


cdef inline void _window(int64_t n, int64_t m, double band, int64_t* lo, int64_t* hi) noexcept nogil:
    cdef int64_t i, a, b
    cdef double r, c
    if n == 1:
        lo[0] = 0
        hi[0] = 0 if m == 1 else -1
        return
    r = band * m
    if r < 1.0:
        r = 1.0
    for i in range(n):
        c = <double>(i * (m - 1)) / <double>(n - 1)
        a = (m - 1) - 2 * (n - 1 - i)
        if a < 0:
            a = 0
        a = max(a, <int64_t>ceil(c - r - 1e-9))
        b = min(m - 1, 2 * i)
        b = min(b, <int64_t>floor(c + r + 1e-9))
        lo[i] = a
        hi[i] = b


def window(int64_t n, int64_t m, double band, int64_t[::1] lo, int64_t[::1] hi):
    """Fill ``lo (n,)`` and ``hi (n,)`` with the band of the asymmetric warp (see band_window)."""
    _window(n, m, band, &lo[0], &hi[0])


cdef double _envelope_lb(cmat q, int64_t qs, int64_t n, cmat d, int64_t ds, int64_t m,
                         int64_t* lo, int64_t* hi, double* rows, int64_t* upq, int64_t* dnq) noexcept nogil:
    cdef Py_ssize_t D = q.shape[1]
    cdef int64_t i, head, tail, nxt
    cdef Py_ssize_t k
    cdef double v, u, x, low, total
    for i in range(n):
        rows[i] = 0.0
    for k in range(D):
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


cdef inline double _sqdist(cmat q, int64_t qi, cmat d, int64_t di) noexcept nogil:
    cdef double s = 0.0, t
    cdef Py_ssize_t k
    for k in range(q.shape[1]):
        t = q[qi, k] - d[di, k]
        s += t * t
    return s


cdef double _dtw(cmat q, int64_t qs, int64_t n, cmat d, int64_t ds, int64_t m, int64_t* lo, int64_t* hi,
                 double* tail_lb, double limit, double* prev, double* cur) noexcept nogil:
    cdef Py_ssize_t D = q.shape[1]
    cdef Py_ssize_t k
    cdef int64_t i, j, a, b, pa, pb
    cdef double s, t, best, v, row_min
    for j in range(m):
        prev[j] = INFINITY
        cur[j] = INFINITY
    s = _sqdist(q, qs, d, ds)
    prev[0] = s
    if s + tail_lb[0] > limit:
        return INFINITY
    for i in range(1, n):
        a = lo[i]
        b = hi[i]
        row_min = INFINITY
        for j in range(a, b + 1):
            best = prev[j]
            if j >= 1 and prev[j - 1] < best:
                best = prev[j - 1]
            if j >= 2 and prev[j - 2] < best:
                best = prev[j - 2]
            if best == INFINITY:
                cur[j] = INFINITY
                continue
            s = 0.0
            for k in range(D):
                t = q[qs + i, k] - d[ds + j, k]
                s += t * t
            v = best + s
            cur[j] = v
            if v < row_min:
                row_min = v
        pa = lo[i - 1]
        pb = hi[i - 1]
        for j in range(pa, pb + 1):
            if j < a or j > b:
                prev[j] = INFINITY
        if row_min + tail_lb[i] > limit:
            return INFINITY
        for j in range(a, b + 1):
            prev[j] = cur[j]
            cur[j] = INFINITY
    return prev[m - 1]


cdef inline void _insert(int64_t[:, ::1] out_idx, double[:, ::1] out_cost, Py_ssize_t row, int64_t c,
                         double v) noexcept nogil:
    cdef Py_ssize_t k = out_idx.shape[1]
    cdef Py_ssize_t pos = k, p
    while pos > 0 and (out_cost[row, pos - 1] > v or (out_cost[row, pos - 1] == v
                       and (out_idx[row, pos - 1] > c or out_idx[row, pos - 1] < 0))):
        pos -= 1
    if pos >= k:
        return
    p = k - 1
    while p > pos:
        out_idx[row, p] = out_idx[row, p - 1]
        out_cost[row, p] = out_cost[row, p - 1]
        p -= 1
    out_idx[row, pos] = c
    out_cost[row, pos] = v


cdef inline bint _less(double a, double b) noexcept nogil:
    """NumPy's sort order of float64: NaN after every number."""
    return a < b or (b != b and a == a)


cdef void _stable_argsort(double* key, int64_t* idx, int64_t* tmp, int64_t count) noexcept nogil:
    """``idx[:count]`` = the stable ascending order of ``key[:count]`` (``np.argsort(kind="mergesort")``)."""
    cdef int64_t i, width, lo, mid, hi, a, b, o
    cdef int64_t* src = idx
    cdef int64_t* dst = tmp
    cdef int64_t* swap
    for i in range(count):
        idx[i] = i
    width = 1
    while width < count:
        lo = 0
        while lo < count:
            mid = min(lo + width, count)
            hi = min(lo + 2 * width, count)
            a = lo
            b = mid
            o = lo
            while a < mid and b < hi:
                if _less(key[src[b]], key[src[a]]):  # the left run wins ties: stable
                    dst[o] = src[b]
                    b += 1
                else:
                    dst[o] = src[a]
                    a += 1
                o += 1
            while a < mid:
                dst[o] = src[a]
                a += 1
                o += 1
            while b < hi:
                dst[o] = src[b]
                b += 1
                o += 1
            lo += 2 * width
        swap = src
        src = dst
        dst = swap
        width *= 2
    if src != idx:
        for i in range(count):
            idx[i] = src[i]


def search(cmat qf, cimat qb, const int64_t[::1] qg, cmat df, cimat ds, const int64_t[::1] dg, int64_t k,
           double length_factor, double band, int64_t bound, int64_t[:, ::1] out_idx, double[:, ::1] out_cost,
           int64_t[:, ::1] stats):
    """Top-k eq. 1 costs per query segment: :func:`usdhands.algorithms.synthesis._dtw_kernel.search`, serial."""
    cdef Py_ssize_t Q = qb.shape[0], N = ds.shape[0], D = qf.shape[1]
    cdef Py_ssize_t qi, c, kk, oi, p
    cdef int64_t max_m = 0, m, n, qs, nc, aligned, abandoned, pruned, i, j, longest = 1
    cdef double g, t, lim, kim, lb, acc, v
    cdef double[:, ::1] dmean = np.zeros((N, D))
    cdef double[::1] qmean = np.zeros(D)
    cdef int64_t* lo
    cdef int64_t* hi
    cdef int64_t* upq
    cdef int64_t* dnq
    cdef int64_t* cand
    cdef int64_t* order
    cdef int64_t* tmp
    cdef double* rows
    cdef double* tail
    cdef double* prev
    cdef double* cur
    cdef double* guess
    for c in range(N):
        if ds[c, 1] - ds[c, 0] > max_m:
            max_m = ds[c, 1] - ds[c, 0]
    for qi in range(Q):
        if qb[qi, 1] - qb[qi, 0] > longest:
            longest = qb[qi, 1] - qb[qi, 0]
    for c in range(N):
        m = ds[c, 1] - ds[c, 0]
        for j in range(ds[c, 0], ds[c, 1]):
            for kk in range(D):
                dmean[c, kk] += df[j, kk]
        for kk in range(D):
            dmean[c, kk] /= m
    lo = <int64_t*>malloc(longest * sizeof(int64_t))
    hi = <int64_t*>malloc(longest * sizeof(int64_t))
    rows = <double*>malloc(longest * sizeof(double))
    tail = <double*>malloc(longest * sizeof(double))
    upq = <int64_t*>malloc((max_m + 1) * sizeof(int64_t))
    dnq = <int64_t*>malloc((max_m + 1) * sizeof(int64_t))
    prev = <double*>malloc((max_m + 1) * sizeof(double))
    cur = <double*>malloc((max_m + 1) * sizeof(double))
    cand = <int64_t*>malloc((N + 1) * sizeof(int64_t))
    order = <int64_t*>malloc((N + 1) * sizeof(int64_t))
    tmp = <int64_t*>malloc((N + 1) * sizeof(int64_t))
    guess = <double*>malloc((N + 1) * sizeof(double))
    try:
        if (lo == NULL or hi == NULL or rows == NULL or tail == NULL or upq == NULL or dnq == NULL or prev == NULL
                or cur == NULL or cand == NULL or order == NULL or tmp == NULL or guess == NULL):
            raise MemoryError()
        with nogil:
            for qi in range(Q):
                qs = qb[qi, 0]
                n = qb[qi, 1] - qb[qi, 0]
                for kk in range(D):
                    qmean[kk] = 0.0
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
                _stable_argsort(guess, order, tmp, nc)
                aligned = 0
                abandoned = 0
                pruned = 0
                for oi in range(nc):
                    c = cand[order[oi]]
                    m = ds[c, 1] - ds[c, 0]
                    lim = out_cost[qi, k - 1] * (1.0 + 1e-12) + 1e-12
                    if bound >= 1:
                        kim = _sqdist(qf, qs, df, ds[c, 0])
                        if n > 1:
                            kim += _sqdist(qf, qs + n - 1, df, ds[c, 0] + m - 1)
                        if kim > lim:
                            pruned += 1
                            continue
                    _window(n, m, band, lo, hi)
                    if bound >= 2:
                        lb = _envelope_lb(qf, qs, n, df, ds[c, 0], m, lo, hi, rows, upq, dnq)
                        if lb > lim:
                            pruned += 1
                            continue
                        acc = 0.0
                        i = n - 1
                        while i >= 0:
                            tail[i] = acc
                            acc += rows[i]
                            i -= 1
                    else:
                        for i in range(n):
                            tail[i] = 0.0
                    aligned += 1
                    v = _dtw(qf, qs, n, df, ds[c, 0], m, lo, hi, tail, lim, prev, cur)
                    if v == INFINITY:
                        abandoned += 1
                        continue
                    _insert(out_idx, out_cost, qi, c, v)
                for p in range(k):
                    if out_idx[qi, p] >= 0:
                        out_cost[qi, p] = out_cost[qi, p] / n
                stats[qi, 0] = nc
                stats[qi, 1] = aligned
                stats[qi, 2] = abandoned
                stats[qi, 3] = pruned
    finally:
        free(lo)
        free(hi)
        free(rows)
        free(tail)
        free(upq)
        free(dnq)
        free(prev)
        free(cur)
        free(cand)
        free(order)
        free(tmp)
        free(guess)


cdef double _align_path(cmat q, cmat d, double band, int64_t[::1] path) except? -1.0:
    cdef Py_ssize_t n = q.shape[0], m = d.shape[0]
    cdef Py_ssize_t i, j
    cdef double best
    cdef signed char st
    cdef int64_t[::1] lo = np.empty(n, dtype=np.int64)
    cdef int64_t[::1] hi = np.empty(n, dtype=np.int64)
    _window(n, m, band, &lo[0], &hi[0])
    for i in range(n):
        if lo[i] > hi[i]:
            return INFINITY
    cdef double[:, ::1] acc = np.full((n, m), np.inf)
    cdef signed char[:, ::1] step = np.zeros((n, m), dtype=np.int8)
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
            if best == INFINITY:
                continue
            acc[i, j] = best + _sqdist(q, i, d, j)
            step[i, j] = st
    if acc[n - 1, m - 1] == INFINITY:
        return INFINITY
    j = m - 1
    i = n - 1
    while i >= 0:
        path[i] = j
        if i > 0:
            j -= step[i, j]
        i -= 1
    return acc[n - 1, m - 1]


def align_path(cmat q, cmat d, double band, int64_t[::1] path):
    """Asymmetric DTW of one pair with its warp path: :func:`usdhands.algorithms.synthesis._dtw_kernel.align_path`."""
    return _align_path(q, d, band, path)

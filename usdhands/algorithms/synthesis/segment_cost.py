"""The DTW-aligned segment cost of seed 000 (eq. 1) and the k-nearest search over a database.

Eq. 1 adapts the database segment ``S_D`` to the input segment ``S_I``'s length with
dynamic time warping and then averages the weighted squared differences of the wrist
features over the ``n`` input frames::

    cS = (wP · Σ_t |P_I(t) − P_D(t)|² + wR · Σ_t |R_I(t) − R_D(t)|²) / n

"Same length as the input" is taken literally: the warp maps every input frame ``i``
to exactly one database frame ``j(i)``, with ``j(0) = 0``, ``j(n−1) = m−1`` and steps
``j(i) − j(i−1) ∈ {0, 1, 2}`` (the asymmetric step pattern), so the sum has ``n``
terms. A band of half-width ``band · m`` frames around the diagonal bounds the warp.
The weights are folded into the features beforehand (:func:`weight_features`), so
the local cost is a plain squared Euclidean distance.

Search. :func:`knn_segments` compares every input segment with every database
segment whose length is within ``length_factor`` of it and keeps the ``k`` cheapest.
It runs in one kernel compiled ahead of time (:mod:`usdhands.compiled`: serial, nothing
to start) up to :data:`COMPILED_SEARCH_MAX_CELLS`, beyond it in its numba twin, parallel
over input segments; where the package was installed without a C compiler, a search too
small to pay for loading numba (about 0.5 s) runs in the NumPy twin
(:mod:`~usdhands.algorithms.synthesis._dtw_numpy`). All three give the same result and
statistics to the bit. For each input
segment it visits the candidates in order of the distance between segment means (a
cheap guess that finds good neighbours early, so the ``k``-th best cost drops fast).
Each candidate is first checked against a lower bound of its cost and **pruned**
(never aligned) when the bound exceeds the ``k``-th best cost so far; an alignment
that is started is **abandoned** as soon as its cheapest partial path (plus, with
LB_Keogh, the bound of the remaining rows) exceeds that cost. Bounds (``bound``):

- ``"kim"`` (default): the end points, ``|q₀ − d₀|² + |q_{n−1} − d_{m−1}|²``, which
  every warp contains (``j(0) = 0``, ``j(n−1) = m−1``); O(D) per candidate;
- ``"keogh"``: the end points, then **LB_Keogh**, the squared distance of each input
  frame to the min/max envelope of the database frames its band allows (built with a
  monotone deque, O(n + m) per dimension); tighter, but on wrist motion it costs
  more than the alignments it saves (see benchmarks/bench_synthesis.py);
- ``"none"``: early abandoning only.

The result is the same for every bound (ties in cost go to the lower index).

:func:`dtw_align` is the plain NumPy twin for one pair (cost and warp path); tests
check the kernel and :func:`dtw_align_fast` (its compiled twin) against it and the
benchmark measures the kernel's speed-up over it. :func:`dtw_align_many` aligns many
pairs at once in NumPy with the compiled twin's numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usdhands.compiled import kernel_module

__all__ = [
    "weight_features", "band_window", "dtw_align", "dtw_align_fast", "dtw_align_many", "lb_keogh", "knn_segments",
    "SearchResult", "load_search_kernel",
]


def weight_features(features: np.ndarray, weights) -> np.ndarray:
    """Multiply columns by ``sqrt(weight)`` so squared distances carry the weights.

    Parameters
    ----------
    features : (T, D) float
        Feature columns (for eq. 1: 3 positions in cm, then 3 rotations in degrees).
    weights : (D,) float
        Non-negative weight of each column's squared difference.

    Returns
    -------
    (T, D) float64, C-contiguous
    """
    f = np.asarray(features, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    if f.ndim != 2 or w.shape != (f.shape[1],):
        raise ValueError(f"Expected features (T, D) and weights (D,), got {f.shape} and {w.shape}")
    if (w < 0).any():
        raise ValueError(f"Expected non-negative weights, got {w.tolist()}")
    return np.ascontiguousarray(f * np.sqrt(w))


def band_window(n: int, m: int, band: float) -> tuple[np.ndarray, np.ndarray]:
    """Database frames each input frame may align to: ``lo (n,)``, ``hi (n,)`` inclusive.

    Empty windows (``lo > hi``) mean the pair cannot be aligned (``m > 2n − 1``).
    """
    n, m = int(n), int(m)
    if n < 1 or m < 1:
        raise ValueError(f"Expected n, m >= 1, got {n} and {m}")
    i = np.arange(n)
    if n == 1:
        ok = m == 1
        return np.zeros(1, dtype=np.int64), np.full(1, 0 if ok else -1, dtype=np.int64)
    c = i * (m - 1) / (n - 1)
    r = max(band * m, 1.0)
    lo = np.maximum.reduce([np.zeros(n), (m - 1) - 2 * (n - 1 - i), np.ceil(c - r - 1e-9)]).astype(np.int64)
    hi = np.minimum.reduce([np.full(n, m - 1), 2 * i, np.floor(c + r + 1e-9)]).astype(np.int64)
    return lo, hi


def dtw_align(query: np.ndarray, cand: np.ndarray, band: float = 1.0) -> tuple[float, np.ndarray]:
    """Eq. 1 for one pair with the asymmetric DTW, in plain NumPy.

    Parameters
    ----------
    query : (n, D) float
        Input segment features, already weighted (:func:`weight_features`).
    cand : (m, D) float
        Database segment features, weighted alike.
    band : float
        Half-width of the band as a fraction of ``m`` (1: unconstrained).

    Returns
    -------
    cost : float
        ``Σ_i |query[i] − cand[j(i)]|² / n``; ``inf`` when no warp fits.
    path : (n,) int
        ``j(i)``, the database frame aligned to each input frame (empty when no warp fits).
    """
    q = np.asarray(query, dtype=np.float64)
    c = np.asarray(cand, dtype=np.float64)
    n, m = len(q), len(c)
    if n == 0 or m == 0:
        raise ValueError(f"Expected non-empty segments, got lengths {n} and {m}")
    lo, hi = band_window(n, m, band)
    if (lo > hi).any():
        return float("inf"), np.zeros(0, dtype=np.int64)
    local = ((q[:, None, :] - c[None, :, :]) ** 2).sum(axis=2)  # (n, m)
    acc = np.full((n, m), np.inf)
    step = np.zeros((n, m), dtype=np.int8)
    acc[0, 0] = local[0, 0]
    for i in range(1, n):
        prev = acc[i - 1]
        opts = np.full((3, m), np.inf)  # predecessors at j, j-1, j-2
        opts[0] = prev
        opts[1, 1:] = prev[:-1]
        opts[2, 2:] = prev[:-2]
        best = np.argmin(opts, axis=0)
        row = opts[best, np.arange(m)] + local[i]
        inside = np.zeros(m, dtype=bool)
        inside[lo[i]:hi[i] + 1] = True
        acc[i] = np.where(inside, row, np.inf)
        step[i] = best
    if not np.isfinite(acc[n - 1, m - 1]):
        return float("inf"), np.zeros(0, dtype=np.int64)
    path = np.empty(n, dtype=np.int64)
    j = m - 1
    for i in range(n - 1, -1, -1):
        path[i] = j
        if i:
            j -= int(step[i, j])
    return float(acc[n - 1, m - 1] / n), path


def dtw_align_fast(query: np.ndarray, cand: np.ndarray, band: float = 1.0) -> tuple[float, np.ndarray]:
    """:func:`dtw_align` compiled with numba: same arguments, same result."""
    from usdhands.algorithms.synthesis import _dtw_kernel as kern

    q = np.ascontiguousarray(query, dtype=np.float64)
    c = np.ascontiguousarray(cand, dtype=np.float64)
    n, m = len(q), len(c)
    if n == 0 or m == 0 or q.ndim != 2 or c.ndim != 2 or q.shape[1] != c.shape[1]:
        raise ValueError(f"Expected non-empty (n, D) and (m, D) segments, got {q.shape} and {c.shape}")
    path = np.zeros(n, dtype=np.int64)
    total = kern.align_path(q, c, float(band), path)
    if not np.isfinite(total):
        return float("inf"), np.zeros(0, dtype=np.int64)
    return float(total / n), path


def dtw_align_many(query: np.ndarray, db: np.ndarray, pairs: np.ndarray, bands) -> list[tuple[float, np.ndarray]]:
    """:func:`dtw_align_fast` of many pairs at once, in NumPy (no numba): the same costs and paths.

    Parameters
    ----------
    query : (T, D) float
        Weighted input features.
    db : (F, D) float
        Weighted database features.
    pairs : (P, 4) int
        ``[q0, q1, d0, d1)``: the input and database frame ranges of each pair.
    bands : (P,) float
        Band half-width of each pair, a fraction of its database length.

    Returns
    -------
    list of (cost, path)
        As :func:`dtw_align_fast` per pair.
    """
    from usdhands.algorithms.synthesis import _dtw_numpy

    q = np.ascontiguousarray(query, dtype=np.float64)
    d = np.ascontiguousarray(db, dtype=np.float64)
    pr = np.asarray(pairs, dtype=np.int64).reshape(-1, 4)
    if q.ndim != 2 or d.ndim != 2 or q.shape[1] != d.shape[1]:
        raise ValueError(f"Expected (T, D) and (F, D) features, got {q.shape} and {d.shape}")
    if len(pr) and ((pr[:, 1] <= pr[:, 0]).any() or (pr[:, 3] <= pr[:, 2]).any() or (pr[:, [0, 2]] < 0).any()
                    or (pr[:, 1] > len(q)).any() or (pr[:, 3] > len(d)).any()):
        raise ValueError("pairs must hold non-empty frame ranges inside the features")
    totals, paths = _dtw_numpy.align_paths(q, d, pr, np.broadcast_to(np.asarray(bands, np.float64), (len(pr),)))
    return [(float(t / (p[1] - p[0])) if np.isfinite(t) else float("inf"), path)
            for t, p, path in zip(totals, pr, paths)]


def lb_keogh(query: np.ndarray, cand: np.ndarray, band: float = 1.0) -> float:
    """The LB_Keogh lower bound of :func:`dtw_align`'s cost, plain NumPy (for tests)."""
    q = np.asarray(query, dtype=np.float64)
    c = np.asarray(cand, dtype=np.float64)
    n, m = len(q), len(c)
    lo, hi = band_window(n, m, band)
    if (lo > hi).any():
        return float("inf")
    total = 0.0
    for i in range(n):
        w = c[lo[i]:hi[i] + 1]
        up, dn = w.max(axis=0), w.min(axis=0)
        total += float((np.maximum(q[i] - up, 0) ** 2 + np.maximum(dn - q[i], 0) ** 2).sum())
    return total / n


#: Lower bounds of :func:`knn_segments` and their kernel codes.
BOUNDS = {"none": 0, "kim": 1, "keogh": 2}


@dataclass(frozen=True)
class SearchResult:
    """The k cheapest database segments of every input segment.

    Attributes
    ----------
    index : (Q, k) int
        Database segment indices, cheapest first; -1 where fewer than k qualified.
    cost : (Q, k) float
        Their segment costs (eq. 1); inf where index is -1.
    candidates : (Q,) int
        Database segments within the length factor (and not excluded) per input segment.
    pruned : (Q,) int
        Candidates the lower bound ruled out without aligning them.
    aligned : (Q,) int
        Candidates whose alignment was started.
    abandoned : (Q,) int
        Alignments stopped early by the bound on the remaining rows.
    """

    index: np.ndarray
    cost: np.ndarray
    candidates: np.ndarray
    pruned: np.ndarray
    aligned: np.ndarray
    abandoned: np.ndarray

    @property
    def pruned_share(self) -> float:
        """Share of candidate pairs the lower bound skipped (never aligned)."""
        total = int(self.candidates.sum())
        return float(self.pruned.sum()) / total if total else 0.0

    @property
    def skipped_share(self) -> float:
        """Share of candidate pairs never aligned in full (pruned or abandoned early)."""
        total = int(self.candidates.sum())
        return 1.0 - float((self.aligned - self.abandoned).sum()) / total if total else 0.0


def knn_segments(query_features: np.ndarray, query_bounds: np.ndarray,
                 db_features: np.ndarray, db_segments: np.ndarray, k: int = 5,
                 length_factor: float = 1.5, band: float = 1.0,
                 query_groups: np.ndarray | None = None, db_groups: np.ndarray | None = None,
                 bound: str = "kim") -> SearchResult:
    """The ``k`` database segments of least eq. 1 cost for every input segment.

    Parameters
    ----------
    query_features : (T, D) float
        Weighted input features (:func:`weight_features`).
    query_bounds : (Q, 2) int
        ``[start, stop)`` frame ranges of the input segments in ``query_features``.
    db_features : (F, D) float
        Weighted database features, all tracks concatenated.
    db_segments : (N, 2) int
        ``[start, stop)`` frame ranges of the database segments in ``db_features``.
    k : int
        Segments kept per input segment.
    length_factor : float
        A candidate's length ``m`` must satisfy ``n / f <= m <= n * f``.
    band : float
        DTW band half-width as a fraction of the candidate's length.
    query_groups : (Q,) int, optional
    db_groups : (N,) int, optional
        A database segment whose group equals the input segment's is skipped
        (leave-one-out); -1 matches nothing.
    bound : {"kim", "keogh", "none"}
        Lower bound used to prune candidates (see the module notes).

    Returns
    -------
    SearchResult
        Ties in cost go to the lower database index; the result does not depend on
        ``bound`` or on the number of threads.
    """
    qf = np.ascontiguousarray(query_features, dtype=np.float64)
    df = np.ascontiguousarray(db_features, dtype=np.float64)
    qb = np.ascontiguousarray(query_bounds, dtype=np.int64).reshape(-1, 2)
    ds = np.ascontiguousarray(db_segments, dtype=np.int64).reshape(-1, 2)
    if qf.ndim != 2 or df.ndim != 2 or qf.shape[1] != df.shape[1]:
        raise ValueError(f"Expected query and database features (T, D) with equal D, got {qf.shape} and {df.shape}")
    if int(k) < 1:
        raise ValueError(f"Expected k >= 1, got {k}")
    if not length_factor >= 1:
        raise ValueError(f"Expected length_factor >= 1, got {length_factor}")
    if not 0 < band <= 1:
        raise ValueError(f"Expected 0 < band <= 1, got {band}")
    if bound not in BOUNDS:
        raise ValueError(f"Expected bound in {tuple(BOUNDS)}, got {bound!r}")
    for name, b, total in (("query_bounds", qb, len(qf)), ("db_segments", ds, len(df))):
        if len(b) and ((b[:, 0] < 0).any() or (b[:, 1] > total).any() or (b[:, 1] <= b[:, 0]).any()):
            raise ValueError(f"{name} must hold non-empty ranges inside 0..{total}")
    Q, N = len(qb), len(ds)
    qg = np.full(Q, -1, dtype=np.int64) if query_groups is None else np.ascontiguousarray(query_groups, dtype=np.int64)
    dg = np.full(N, -2, dtype=np.int64) if db_groups is None else np.ascontiguousarray(db_groups, dtype=np.int64)
    if qg.shape != (Q,) or dg.shape != (N,):
        raise ValueError(f"Expected query_groups ({Q},) and db_groups ({N},), got {qg.shape} and {dg.shape}")
    out_idx = np.full((Q, int(k)), -1, dtype=np.int64)
    out_cost = np.full((Q, int(k)), np.inf)
    stats = np.zeros((Q, 4), dtype=np.int64)
    if Q and N:
        search = _search_kernel(qb, ds, float(length_factor), float(band), bound)
        search(qf, qb, qg, df, ds, dg, int(k), float(length_factor), float(band), BOUNDS[bound],
               out_idx, out_cost, stats)
    return SearchResult(out_idx, out_cost, stats[:, 0], stats[:, 3], stats[:, 1], stats[:, 2])


#: Largest search (band cells of all candidate pairs, :func:`_dtw_numpy.estimated_cells`) done in
#: the kernel compiled ahead of time when numba's is not loaded yet. It runs about 0.7 ns an
#: estimated cell on one thread (the estimate ignores pruning; measured on 12-D wrist-like
#: features, a 40 M-cell search in 27 ms, numba's twin on one thread 33 ms); numba's start
#: (about 0.35-0.5 s) pays for itself on any machine of 2 cores or more beyond about 0.35 s
#: of serial search. A batch clip is about 0.3 M cells a hand, the sample conversation 1.9 M.
COMPILED_SEARCH_MAX_CELLS = 5e8
#: Largest search done in NumPy when neither the compiled kernel (not built: no C compiler at
#: install) nor numba's is loaded: importing numba and loading the kernel takes about 0.5 s,
#: the NumPy search about 25 ns per cell (the sample conversation against the bundled
#: database: 1.9 M cells a hand, 50 ms).
NUMPY_SEARCH_MAX_CELLS = 8e6
#: Cells a process searches in NumPy in all before it loads numba's kernel instead (about the
#: kernel's loading time), without the compiled kernel: a command on one short clip never loads
#: numba, a process that synthesizes many loads it after the first few clips (a batch worker
#: loads it at its start, :func:`load_search_kernel`). Either way the results are the same to the bit.
NUMPY_SEARCH_PROCESS_CELLS = 20e6
_numpy_cells_searched = [0.0]


def load_search_kernel() -> None:
    """Load the numba search kernel into this process now (from the kernel cache; compiled there
    on the first run), so that every later search runs in it, and synthesis's numba twins
    with it (:func:`~usdhands.algorithms.synthesis.output_warp.play_kernels`).

    For a process that will synthesize many clips (a batch worker, at its start) where the
    kernels compiled ahead of time were not built (:mod:`usdhands.compiled`): otherwise
    its first :data:`NUMPY_SEARCH_PROCESS_CELLS` cells are searched in NumPy (about 45 of the
    batch benchmark's clips at 2.5 times the kernel's CPU, paid again by every worker). The
    results are the same either way. Costs about 0.3 s (importing numba, loading the kernel).
    """
    one = np.zeros((2, 1))
    # the signature of every search: the bound is an int argument, the arrays float64 and int64 as
    # knn_segments makes them
    from usdhands.algorithms.synthesis import _dtw_kernel

    qb = np.array([[0, 2]], dtype=np.int64)
    _dtw_kernel.search(one, qb, np.array([-1], dtype=np.int64), one, qb, np.array([-2], dtype=np.int64), 1, 1.5, 1.0, BOUNDS["keogh"],
                       np.full((1, 1), -1, dtype=np.int64), np.full((1, 1), np.inf), np.zeros((1, 4), dtype=np.int64))


def _search_kernel(query_bounds: np.ndarray, db_segments: np.ndarray, length_factor: float, band: float,
                   bound: str):
    """The search function for this work: the kernel compiled ahead of time up to
    :data:`COMPILED_SEARCH_MAX_CELLS` (else the NumPy twin for small searches), numba's beyond,
    or wherever numba's is loaded already.

    All give the same result and statistics to the bit (``tests/test_dtw_numpy_twin.py``,
    ``tests/test_compiled_kernels.py``).
    """
    from usdhands.algorithms.synthesis import _dtw_numpy

    if not _kernel_loaded():
        cells = _dtw_numpy.estimated_cells(query_bounds[:, 1] - query_bounds[:, 0],
                                           db_segments[:, 1] - db_segments[:, 0], length_factor, band)
        compiled = kernel_module("algorithms.synthesis._search_compiled")
        if compiled is not None:
            if cells <= COMPILED_SEARCH_MAX_CELLS:
                return compiled.search
        elif (bound != "keogh" and cells <= NUMPY_SEARCH_MAX_CELLS
              and _numpy_cells_searched[0] + cells <= NUMPY_SEARCH_PROCESS_CELLS):
            _numpy_cells_searched[0] += cells
            return _dtw_numpy.search
    from usdhands.algorithms.synthesis import _dtw_kernel

    return _dtw_kernel.search


def _kernel_loaded() -> bool:
    """Whether this process has the search kernel loaded already (then it is the faster choice)."""
    import sys

    kernel = sys.modules.get("usdhands.algorithms.synthesis._dtw_kernel")
    return kernel is not None and bool(kernel.search.signatures)

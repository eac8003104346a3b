"""Dynamic time warping inside a band, with user constraints.

Implements the time warping of Majkowska, Zordan and Faloutsos 2006 (*Automatic
splicing for hand and body animations*, section 3):

- eq. 1–2: the cumulative distance ``γ(i, j) = D(i, j) + min(γ(i-1, j-1), γ(i-1, j),
  γ(i, j-1))``, path from ``(0, 0)`` to ``(n-1, m-1)``;
- eq. 3: a band of half-width ``W`` frames (perpendicular distance) around the line
  from ``(0, 0)`` to ``(n-1, m-1)``; in columns that is ``Δ = W·sqrt(n² + m²)/n``;
- eq. 4–5 and Algorithm 1: user constraints ``(x_k, y_k, T_k)``; the band is bent
  through the constraint points (one straight band per segment between consecutive
  points) and, in row ``x_k``, limited to columns ``y_k ± T_k``, so the optimal path
  matches body frame ``x_k`` to hand frames within ``T_k`` of ``y_k`` (exactly ``y_k``
  when ``T_k = 0``).

A band is stored row by row: row ``i`` holds the columns ``lo[i] .. hi[i]`` (inclusive).
Cells outside the band are never evaluated, so cost functions are only called on the
band. The kernels are compiled with numba (cached on disk); :func:`dtw_naive` is the
plain full-matrix twin used by the tests and the benchmark baseline.

Frame indices are 0-based throughout.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from usdhands.jit import njit

__all__ = [
    "Constraint", "Band", "WarpResult", "dtw", "dtw_naive", "check_constraints",
]


@dataclass(frozen=True)
class Constraint:
    """A user constraint: body frame ``body`` matches hand frame ``hand`` within ``tolerance`` frames.

    Parameters
    ----------
    body : int
        Row (frame of the first sequence), 0-based.
    hand : int
        Column (frame of the second sequence), 0-based.
    tolerance : int
        ``T`` of eq. 5, in frames of the second sequence; 0 means exactly.
    """

    body: int
    hand: int
    tolerance: int = 0

    def __str__(self) -> str:
        return f"{self.body}:{self.hand}" + (f":{self.tolerance}" if self.tolerance else "")


def check_constraints(constraints: Sequence[Constraint], n: int, m: int) -> list[Constraint]:
    """Validate constraints for an ``n`` by ``m`` warp and return them as a list.

    Raises
    ------
    ValueError
        A frame out of range, a negative tolerance, frames that do not both increase
        from one constraint to the next, constraints on adjacent body frames that skip
        hand frames, or a constraint on the first or last body frame that contradicts
        the fixed ends of the path.
    """
    out = []
    for c in constraints:
        if not isinstance(c, Constraint):
            raise TypeError(f"Expected Constraint, got {type(c).__name__}: {c!r}")
        if not 0 <= c.body < n:
            raise ValueError(f"constraint {c}: body frame {c.body} is out of range 0..{n - 1}")
        if not 0 <= c.hand < m:
            raise ValueError(f"constraint {c}: hand frame {c.hand} is out of range 0..{m - 1}")
        if c.tolerance < 0:
            raise ValueError(f"constraint {c}: tolerance must be >= 0, got {c.tolerance}")
        if out and not (c.body > out[-1].body and c.hand > out[-1].hand):
            raise ValueError(f"constraints out of order: {c} after {out[-1]} "
                             "(body and hand frames must both increase)")
        if out and c.body == out[-1].body + 1 and c.hand - c.tolerance > out[-1].hand + out[-1].tolerance + 1:
            raise ValueError(f"constraints {out[-1]} and {c} cannot both hold: hand frames "
                             f"{out[-1].hand + out[-1].tolerance + 1}..{c.hand - c.tolerance - 1} "
                             "would match no body frame")
        if c.body == 0 and c.hand > c.tolerance:
            raise ValueError(f"constraint {c} contradicts the start of the path 0:0")
        if c.body == n - 1 and c.hand < m - 1 - c.tolerance:
            raise ValueError(f"constraint {c} contradicts the end of the path {n - 1}:{m - 1}")
        out.append(c)
    return out


@dataclass(frozen=True, eq=False)
class Band:
    """The cells of an ``n`` by ``m`` matrix that a warp may use, row by row.

    Parameters
    ----------
    lo, hi : (n,) int64
        First and last column (inclusive) allowed in each row.
    m : int
        Number of columns.
    """

    lo: np.ndarray
    hi: np.ndarray
    m: int

    def __post_init__(self) -> None:
        lo = np.ascontiguousarray(self.lo, dtype=np.int64)
        hi = np.ascontiguousarray(self.hi, dtype=np.int64)
        if lo.ndim != 1 or lo.shape != hi.shape:
            raise ValueError(f"Expected lo and hi of the same shape (n,), got {lo.shape} and {hi.shape}")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)
        object.__setattr__(self, "m", int(self.m))

    @property
    def n(self) -> int:
        """Number of rows."""
        return self.lo.shape[0]

    @property
    def offsets(self) -> np.ndarray:
        """Index of each row's first cell in the flat cell order, ``(n + 1,)`` int64."""
        return np.concatenate([[0], np.cumsum(np.maximum(self.hi - self.lo + 1, 0))]).astype(np.int64)

    @property
    def num_cells(self) -> int:
        """Number of cells in the band."""
        return int(np.maximum(self.hi - self.lo + 1, 0).sum())

    def cells(self) -> tuple[np.ndarray, np.ndarray]:
        """Row and column of every cell, in flat (row-major) order: two ``(num_cells,)`` int64."""
        return _cells(self.lo, self.hi, self.offsets)

    def mask(self) -> np.ndarray:
        """The band as an ``(n, m)`` bool matrix."""
        j = np.arange(self.m)
        return (j[None, :] >= self.lo[:, None]) & (j[None, :] <= self.hi[:, None])

    def intersect(self, other: "Band") -> "Band":
        """Cells in both bands."""
        if other.n != self.n or other.m != self.m:
            raise ValueError(f"Expected bands of the same shape, got {(self.n, self.m)} and {(other.n, other.m)}")
        return Band(np.maximum(self.lo, other.lo), np.minimum(self.hi, other.hi), self.m)

    def check_connected(self) -> None:
        """Raise ValueError when no monotone path from (0, 0) to (n-1, m-1) stays in the band."""
        lo, hi = self.lo, self.hi
        if self.n == 0 or self.m == 0:
            raise ValueError(f"Expected a non-empty matrix, got {self.n} x {self.m}")
        if lo[0] != 0 or hi[-1] != self.m - 1 or np.any(hi < lo):
            raise ValueError("the band does not contain a path from (0, 0) to "
                             f"({self.n - 1}, {self.m - 1})")
        gap = np.nonzero((lo[1:] > hi[:-1] + 1) | (hi[1:] < lo[:-1]))[0]
        if gap.size:
            raise ValueError(f"the band has a gap between rows {gap[0]} and {gap[0] + 1}")

    # -- constructors -------------------------------------------------------------
    @classmethod
    def full(cls, n: int, m: int) -> "Band":
        """Every cell."""
        return cls(np.zeros(n, np.int64), np.full(n, m - 1, np.int64), m)

    @classmethod
    def diagonal(cls, n: int, m: int, width: float,
                 constraints: Sequence[Constraint] = ()) -> "Band":
        """The band of eq. 3, bent through user constraints as in eq. 4–5.

        Parameters
        ----------
        n, m : int
            Rows (body frames) and columns (hand frames).
        width : float
            Half-width ``W`` of the band as a fraction of ``n`` (0.3 for 30 %): the
            band holds the cells within ``W·n`` frames (perpendicular distance) of the
            line through the constraint points; ``inf`` for no band.
        constraints : sequence of Constraint
            Checked with :func:`check_constraints`.
        """
        if n < 1 or m < 1:
            raise ValueError(f"Expected n, m >= 1, got {n}, {m}")
        if not width >= 0:
            raise ValueError(f"Expected width >= 0, got {width}")
        cons = check_constraints(constraints, n, m)
        pts = [(0, 0, 0)]
        for c in cons:
            if c.body == 0:
                pts[0] = (0, 0, 0)
            elif c.body != n - 1:
                pts.append((c.body, c.hand, c.tolerance))
        pts.append((n - 1, m - 1, 0))
        lo = np.zeros(n, np.int64)
        hi = np.full(n, m - 1, np.int64)
        W = float(width) * n
        for (x0, y0, t0), (x1, y1, t1) in zip(pts[:-1], pts[1:]):
            dx, dy = x1 - x0, y1 - y0
            if dx == 0:
                continue
            slope = dy / dx
            delta = W * np.hypot(dx, dy) / dx if np.isfinite(W) else np.inf
            delta = max(delta, slope + 1.0)  # consecutive rows must overlap for a path to exist
            i = np.arange(x0, x1 + 1)
            c = y0 + slope * (i - x0)
            with np.errstate(invalid="ignore"):
                seg_lo = np.maximum(y0 - t0, np.floor(c - delta)) if np.isfinite(delta) else np.full(i.shape, y0 - t0)
                seg_hi = np.minimum(y1 + t1, np.ceil(c + delta)) if np.isfinite(delta) else np.full(i.shape, y1 + t1)
            # rows shared by two segments (the constraint rows) keep both limits
            lo[i] = np.where(i == x0, np.maximum(lo[i], seg_lo), seg_lo) if x0 else seg_lo
            hi[i] = np.where(i == x0, np.minimum(hi[i], seg_hi), seg_hi) if x0 else seg_hi
        for c in cons:
            lo[c.body] = max(lo[c.body], c.hand - c.tolerance)
            hi[c.body] = min(hi[c.body], c.hand + c.tolerance)
        lo = np.clip(lo, 0, m - 1)
        hi = np.clip(hi, 0, m - 1)
        lo[0] = 0
        hi[-1] = m - 1
        band = cls(lo, hi, m)
        band.check_connected()
        return band

    @classmethod
    def around_path(cls, path: np.ndarray, n: int, m: int, width: float) -> "Band":
        """Cells within ``width·n`` frames (perpendicular distance) of a warp path.

        Parameters
        ----------
        path : (K, 2) int
            A monotone path from ``(0, 0)`` to ``(n-1, m-1)``, rows then columns.
        width : float
            Half-width as a fraction of ``n`` (0.1 for the second pass).
        """
        path = np.asarray(path, dtype=np.int64)
        if path.ndim != 2 or path.shape[1] != 2:
            raise ValueError(f"Expected path to have shape (K, 2), got {path.shape}")
        pmin = np.full(n, m, np.int64)
        pmax = np.full(n, -1, np.int64)
        np.minimum.at(pmin, path[:, 0], path[:, 1])
        np.maximum.at(pmax, path[:, 0], path[:, 1])
        if np.any(pmax < 0):
            raise ValueError(f"Expected a path that visits every row 0..{n - 1}")
        delta = int(np.ceil(float(width) * n * np.hypot(n, m) / n))
        lo = np.clip(pmin - delta, 0, m - 1)
        hi = np.clip(pmax + delta, 0, m - 1)
        band = cls(lo, hi, m)
        band.check_connected()
        return band


@dataclass(frozen=True, eq=False)
class WarpResult:
    """The optimal warp.

    Parameters
    ----------
    path : (K, 2) int64
        Matched cells ``(row, column)`` from ``(0, 0)`` to ``(n-1, m-1)``, monotone,
        each step one of (1, 1), (1, 0), (0, 1).
    cost : float
        Total cost ``γ(n-1, m-1)``: the sum of the cell costs along the path.
    band : Band
        The band searched.
    cell_costs : (num_cells,) float64, or uint8
        ``D`` on every band cell, flat order of :meth:`Band.cells` (uint8 when the cost
        function gave uint8 counts, as splicing's first pass does).
    """

    path: np.ndarray
    cost: float
    band: Band
    cell_costs: np.ndarray

    def cost_matrix(self) -> np.ndarray:
        """``D`` as an ``(n, m)`` matrix with NaN outside the band (for plots)."""
        out = np.full((self.band.n, self.band.m), np.nan)
        rows, cols = self.band.cells()
        out[rows, cols] = self.cell_costs
        return out


# -- numba kernels ------------------------------------------------------------------
@njit(cache=True)
def _cells(lo, hi, off):  # pragma: no cover - compiled
    N = off[-1]
    rows = np.empty(N, dtype=np.int64)
    cols = np.empty(N, dtype=np.int64)
    for i in range(lo.shape[0]):
        for j in range(lo[i], hi[i] + 1):
            k = off[i] + j - lo[i]
            rows[k] = i
            cols[k] = j
    return rows, cols


@njit(cache=True)
def _accumulate(vals, off, lo, hi):  # pragma: no cover - compiled
    """``γ(n-1, m-1)`` and, for every band cell, the step the optimal path takes into it.

    ``γ(i, j) = D(i, j) + min(γ(i-1, j-1), γ(i-1, j), γ(i, j-1))``, each row in two sweeps:
    the cells above (diagonal and up, independent of each other) first, then the
    left-to-right chain. Only two rows of ``γ`` are kept; the step into each cell
    (int8: 0 diagonal, 1 up, 2 left) is the first of diagonal, up, left whose ``γ`` is
    the smallest, the choice :func:`_backtrack_steps` follows (the tie-breaking of
    :func:`dtw_naive`).
    """
    n = lo.shape[0]
    width = max(hi.max() - lo.min() + 1, 1) if n else 1
    prev = np.empty(width)
    cur = np.empty(width)
    up = np.empty(width)
    steps = np.empty(vals.shape[0], dtype=np.int8)
    total = np.inf
    for i in range(n):
        base = off[i]
        l_i = lo[i]
        w = hi[i] - l_i + 1
        st = steps[base:base + max(w, 0)]
        if i == 0:
            for t in range(w):
                up[t] = np.inf
                st[t] = 0
            if l_i == 0 and w > 0:
                up[0] = 0.0
        else:
            pl = lo[i - 1]
            ph = hi[i - 1]
            for t in range(w):
                j = l_i + t
                a = prev[j - 1 - pl] if pl <= j - 1 <= ph else np.inf
                b = prev[j - pl] if pl <= j <= ph else np.inf
                up[t] = a if a < b else b
                st[t] = 0 if a <= b else 1
        left = np.inf
        for t in range(w):
            u = up[t]
            if u <= left:
                best = u
            else:
                best = left
                st[t] = 2
            v = vals[base + t] + best
            cur[t] = v
            left = v
        if w > 0:
            total = cur[w - 1]
        prev, cur = cur, prev
    return total, steps


@njit(cache=True)
def _backtrack_steps(steps, off, lo, hi):  # pragma: no cover - compiled
    """The path from ``(0, 0)`` to ``(n-1, hi[n-1])`` following :func:`_accumulate`'s steps, ``(K, 2)``."""
    n = lo.shape[0]
    i = n - 1
    j = hi[n - 1]
    out = np.empty((n + hi[n - 1] + 1, 2), dtype=np.int64)
    k = 0
    out[k, 0] = i
    out[k, 1] = j
    k += 1
    while i > 0 or j > 0:
        s = steps[off[i] + j - lo[i]]
        if s == 0:
            i -= 1
            j -= 1
        elif s == 1:
            i -= 1
        else:
            j -= 1
        out[k, 0] = i
        out[k, 1] = j
        k += 1
    return out[:k][::-1].copy()


def dtw(cost: np.ndarray | Callable, band: Band | None = None,
        *, shape: tuple[int, int] | None = None, on_band: bool = False) -> WarpResult:
    """Optimal monotone warp from ``(0, 0)`` to ``(n-1, m-1)`` inside a band.

    Parameters
    ----------
    cost : (n, m) float array, or callable
        The distance ``D(i, j)`` (any unit, >= 0 not required). A callable is called
        once as ``cost(rows, cols)`` with two ``(num_cells,)`` int64 arrays of the band
        cells and must return ``(num_cells,)`` floats, or uint8 counts (kept as they
        are: an eighth of the memory); ``shape`` is then required.
    band : Band, optional
        Cells allowed; the full matrix when omitted.
    shape : (int, int), optional
        ``(n, m)`` when ``cost`` is a callable.
    on_band : bool
        With a callable ``cost``: call it as ``cost(band)`` instead, to return the
        band cells' costs in flat row-major order (a cost that works on the band's rows
        needs no list of cells).

    Returns
    -------
    WarpResult

    Raises
    ------
    ValueError
        Shapes that do not agree, a band without a path, or a path of infinite cost.
    """
    if callable(cost):
        if shape is None:
            raise ValueError("Expected shape=(n, m) with a cost function")
        n, m = (int(s) for s in shape)
    else:
        cost = np.asarray(cost, dtype=np.float64)
        if cost.ndim != 2:
            raise ValueError(f"Expected cost to have shape (n, m), got {cost.shape}")
        n, m = cost.shape
    if band is None:
        band = Band.full(n, m)
    if (band.n, band.m) != (n, m):
        raise ValueError(f"Expected a band of shape {(n, m)}, got {(band.n, band.m)}")
    band.check_connected()
    if callable(cost):
        if on_band:
            vals = _cost_values(cost(band))
            want = (band.num_cells,)
        else:
            rows, cols = band.cells()
            vals = _cost_values(cost(rows, cols))
            want = rows.shape
        if vals.shape != want:
            raise ValueError(f"Expected the cost function to return shape {want}, got {vals.shape}")
    else:
        rows, cols = band.cells()
        vals = np.ascontiguousarray(cost[rows, cols])
    off = band.offsets
    total, steps = _accumulate(vals, off, band.lo, band.hi)
    total = float(total)
    if not np.isfinite(total):
        raise ValueError("no path of finite cost through the band")
    path = _backtrack_steps(steps, off, band.lo, band.hi)
    return WarpResult(path=path, cost=total, band=band, cell_costs=vals)


def _cost_values(values) -> np.ndarray:
    """A cost function's values as a contiguous array: uint8 counts as they are, anything else as float64."""
    values = np.asarray(values)
    return np.ascontiguousarray(values, dtype=np.uint8 if values.dtype == np.uint8 else np.float64)


def dtw_naive(cost: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Plain full-matrix DTW in Python: the reference twin of :func:`dtw`.

    Parameters
    ----------
    cost : (n, m) float
        ``D(i, j)``.
    mask : (n, m) bool, optional
        Allowed cells (``Band.mask()``); all when omitted.

    Returns
    -------
    path : (K, 2) int64
        The same tie-breaking as :func:`dtw` (diagonal, then up, then left).
    total : float
        ``γ(n-1, m-1)``.
    """
    cost = np.asarray(cost, dtype=np.float64)
    n, m = cost.shape
    if mask is None:
        mask = np.ones((n, m), bool)
    inf = float("inf")
    g = [[inf] * (m + 1) for _ in range(n + 1)]  # 1-based with a border of +inf
    g[0][0] = 0.0
    c = cost.tolist()
    mk = mask.tolist()
    for i in range(1, n + 1):
        gi, gp, ci, mi = g[i], g[i - 1], c[i - 1], mk[i - 1]
        for j in range(1, m + 1):
            if not mi[j - 1]:
                continue
            best = gp[j - 1]
            if i == 1 and j == 1:
                best = 0.0
            if gp[j] < best:
                best = gp[j]
            if gi[j - 1] < best:
                best = gi[j - 1]
            gi[j] = ci[j - 1] + best
    g[0][0] = inf
    total = g[n][m]
    if not total < inf:
        raise ValueError("no path of finite cost through the band")
    i, j = n, m
    path = [(n - 1, m - 1)]
    while (i, j) != (1, 1):
        cands = [(g[i - 1][j - 1], i - 1, j - 1), (g[i - 1][j], i - 1, j), (g[i][j - 1], i, j - 1)]
        best = min(v for v, _, _ in cands)
        _, i, j = next(t for t in cands if t[0] == best)
        path.append((i - 1, j - 1))
    return np.array(path[::-1], dtype=np.int64), float(total)

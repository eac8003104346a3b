"""The distances of splicing's two DTW passes (Majkowska et al. 2006, eq. 6-9).

First pass: how many signs of the first and second derivatives of the markers differ,
after subtracting the shoulder and turning the hand clip about the vertical axis
(eq. 6, 7). Second pass: the angle between the hand vectors once the forearms are
aligned (eq. 8, 9), in degrees. Compiled kernels with plain NumPy twins for tests.
Used by :mod:`usdhands.algorithms.splicing.splice`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from usdhands.jit import njit
from scipy.ndimage import convolve1d
from scipy.signal import savgol_coeffs

from usdhands.model.clip import Clip
from usdhands.model.handmap import HandSide
from usdhands.algorithms.splicing.markers import MarkerOffsets, _rot_only, default_marker_offsets

# -- first pass: signs of derivatives (eq. 6, 7) ----------------------------------------
def _smooth_window(T: int, window: int) -> int:
    w = min(window, T if T % 2 else T - 1)
    return w


def sign_features(markers: np.ndarray, fps: float, *, window: int = 7,
                  dead_zone: float = 0.05) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Smoothed first and second derivatives of markers and their dead zones.

    Parameters
    ----------
    markers : (T, K, 3) float
        Positions, centimetres.
    fps : float
        Frames per second.
    window : int
        Savitzky–Golay window in frames (odd; cubic fit), against noise.
    dead_zone : float
        A derivative component smaller than this fraction of the clip's RMS derivative
        counts as zero (sign 0), so holds (``v = 0``) are seen as holds.

    Returns
    -------
    vel : (T, K, 3) float
        cm/s.
    acc : (T, K, 3) float
        cm/s².
    eps_v, eps_a : float
        The dead zones in cm/s and cm/s².
    """
    x = np.asarray(markers, dtype=np.float64)
    T = x.shape[0]
    if T < 3:
        raise ValueError(f"Expected at least 3 frames, got {T}")
    w = _smooth_window(T, window)
    if w >= 5:
        vel = _savgol(x, w, 1, 1.0 / fps)
        acc = _savgol(x, w, 2, 1.0 / fps)
    else:
        vel = np.gradient(x, 1.0 / fps, axis=0)
        acc = np.gradient(vel, 1.0 / fps, axis=0)
    eps_v = dead_zone * float(np.sqrt(np.mean(vel ** 2)))
    eps_a = dead_zone * float(np.sqrt(np.mean(acc ** 2)))
    return vel, acc, eps_v, eps_a


@functools.lru_cache(maxsize=32)
def _savgol_operators(window: int, deriv: int, delta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """scipy's cubic Savitzky-Golay filter with ``mode="interp"`` as three linear maps.

    Returns the convolution coefficients ``(window,)`` for the frames a whole window
    away from the ends, and ``(window // 2, window)`` matrices giving the first and
    last ``window // 2`` frames from the first and last ``window`` frames (the
    derivative of the cubic fitted to them), computed once per window, derivative and
    frame time instead of fitted on every call.
    """
    half = window // 2
    coeffs = savgol_coeffs(window, 3, deriv=deriv, delta=delta)
    i = np.arange(window, dtype=np.float64)
    fit = np.linalg.pinv(np.vander(i, 4, increasing=True))  # (4, window): cubic coefficients c_k of x
    powers = np.arange(4)
    falling = np.array([np.prod(np.arange(k - deriv + 1, k + 1)) if k >= deriv else 0.0 for k in powers])

    def at(points):  # (len(points), 4): d^deriv/dt^deriv of t^k at the points, per second
        p = np.where(powers >= deriv, powers - deriv, 0)
        return falling[None, :] * points[:, None].astype(np.float64) ** p[None, :] / delta ** deriv

    ops = (coeffs, at(np.arange(half)) @ fit, at(np.arange(window - half, window)) @ fit)
    for a in ops:
        a.setflags(write=False)  # shared by every call (lru_cache)
    return ops


def _savgol(x: np.ndarray, window: int, deriv: int, delta: float) -> np.ndarray:
    """``savgol_filter(x, window, 3, deriv, delta, axis=0, mode="interp")`` with cached operators."""
    coeffs, first, last = _savgol_operators(window, deriv, delta)
    y = convolve1d(x, coeffs, axis=0, mode="constant")
    half = window // 2
    flat = x.reshape(x.shape[0], -1)
    y.reshape(y.shape[0], -1)[:half] = first @ flat[:window]
    y.reshape(y.shape[0], -1)[-half:] = last @ flat[-window:]
    return y


@njit(cache=True)
def _sgn(x, eps):  # pragma: no cover - compiled
    if x > eps:
        return 1.0
    if x < -eps:
        return -1.0
    return 0.0


@njit(cache=True, error_model="numpy")
def _first_pass_kernel(run_row, run_col, run_len, P, Q, vb, ab, vh, ah, eps_vb, eps_ab, eps_vh, eps_ah,
                       half, use_trunk, yaw_b, yaw_h, out):  # pragma: no cover - compiled
    """Eq. 6 (with eq. 7's angle, or the trunk angles) on runs of cells along rows.

    Run ``r`` is the cells ``(run_row[r], run_col[r] + t)`` for ``t < run_len[r]``; the
    costs go into ``out`` (``(sum(run_len),)``, float64 or uint8: they are whole numbers
    up to ``24 K``) run after run (a band's rows are its runs). The runs come row after
    row (``run_row`` non-decreasing; ValueError otherwise).

    Eq. 7's window sums run along diagonals: the cell ``(i, j)`` adds the per-frame-pair
    products ``f(i + k, j + k)`` (``|k| <= half``, both frames inside their clips), so
    each ``f(a, b)`` (a sum over the markers) is computed once, for every frame pair the
    asked cells' windows reach, and shared by the cells of its diagonal, instead of
    once per window it falls in. The window sums of the frames' own marker sums (the
    centring terms) are the same for every cell whose window is whole: they are summed
    once per frame, in the order the cells near the ends add them (the same bits).
    Each cell's value depends on that cell alone (not on which other cells are asked
    or in what order). The products are made frame after frame as the rows reach them
    and kept only for the ``2 * half + 1`` frames a row's windows span (a few rows of
    the hand's length: no band-sized buffers to fault in on every call). Eq. 6 is
    accumulated marker by marker in contiguous slices of a run, which the compiler
    vectorises (``error_model="numpy"``: no zero-division checks in the loops, none
    can divide by zero).
    """
    R = run_row.shape[0]
    n = P.shape[0]
    m = Q.shape[0]
    K = P.shape[1]
    Lmax = 1
    for r in range(R):
        Lmax = max(Lmax, run_len[r])
    X = np.ascontiguousarray(P[:, :, 0])
    Z = np.ascontiguousarray(P[:, :, 2])
    Xh = np.ascontiguousarray(Q[:, :, 0])
    Zh = np.ascontiguousarray(Q[:, :, 2])
    SX = X.sum(axis=1)
    SZ = Z.sum(axis=1)
    SXh = Xh.sum(axis=1)
    SZh = Zh.sum(axis=1)
    # hand arrays marker-major, so a run of cells along a row reads them contiguously
    XhT = np.ascontiguousarray(Xh.T)
    ZhT = np.ascontiguousarray(Zh.T)
    VX = np.empty((K, m))
    VZ = np.empty((K, m))
    AX = np.empty((K, m))
    AZ = np.empty((K, m))
    SV = np.empty((K, m))  # hand signs of the vertical components
    SA = np.empty((K, m))
    for j in range(m):
        for mk in range(K):
            VX[mk, j] = vh[j, mk, 0]
            VZ[mk, j] = vh[j, mk, 2]
            AX[mk, j] = ah[j, mk, 0]
            AZ[mk, j] = ah[j, mk, 2]
            SV[mk, j] = _sgn(vh[j, mk, 1], eps_vh)
            SA[mk, j] = _sgn(ah[j, mk, 1], eps_ah)
    SB = np.empty((n, K, 6))  # body signs: v then a, x y z
    for i in range(n):
        for mk in range(K):
            for ax in range(3):
                SB[i, mk, ax] = _sgn(vb[i, mk, ax], eps_vb)
                SB[i, mk, 3 + ax] = _sgn(ab[i, mk, ax], eps_ab)
    # the frame sums over a whole window (frames half .. n - 1 - half), k = -half .. half from 0.0
    WX = np.zeros(n)
    WZ = np.zeros(n)
    WXh = np.zeros(m)
    WZh = np.zeros(m)
    for k in range(-half, half + 1):
        for a in range(half, n - half):
            WX[a] += SX[a + k]
            WZ[a] += SZ[a + k]
        for b in range(half, m - half):
            WXh[b] += SXh[b + k]
            WZh[b] += SZh[b + k]
    # eq. 7's products of frame pairs: f(a, b) for b in need_lo[a] .. need_hi[a], the columns
    # the asked cells' windows reach in frame a
    need_lo = np.full(n, m, dtype=np.int64)
    need_hi = np.full(n, -1, dtype=np.int64)
    if not use_trunk:
        for r in range(R):
            i = run_row[r]
            if r and i < run_row[r - 1]:
                raise ValueError("runs must come row after row")
            for k in range(-half, half + 1):
                a = i + k
                if a < 0 or a >= n:
                    continue
                b0 = max(run_col[r] + k, 0)
                b1 = min(run_col[r] + run_len[r] - 1 + k, m - 1)
                if b0 > b1:
                    continue
                if b0 < need_lo[a]:
                    need_lo[a] = b0
                if b1 > need_hi[a]:
                    need_hi[a] = b1
    # ... kept for the 2 * half + 1 frames a row's windows span: frame a's products in
    # slot a % H, from column need_lo[a] on (small enough to stay in cache)
    H = 2 * half + 1
    FXZ = np.empty((H, m))
    FXX = np.empty((H, m))
    next_a = 0  # the frames before it have their products in (or already out of) the slots
    sxz = np.empty(Lmax)
    acc = np.empty(Lmax)  # a run's costs, summed in float64, then stored in out
    sxx = np.empty(Lmax)
    co = np.empty(Lmax)
    si = np.empty(Lmax)
    whole = K * (2 * half + 1)  # markers in a whole window
    c = 0
    for r in range(R):
        # a run of cells: row i, columns j0 .. j0 + L - 1
        i = run_row[r]
        j0 = run_col[r]
        L = run_len[r]
        while not use_trunk and next_a <= i + half and next_a < n:
            a = next_a
            next_a += 1
            lo_a = need_lo[a]
            w = need_hi[a] - lo_a + 1
            if w <= 0:
                continue
            fxz = FXZ[a % H, :w]
            fxx = FXX[a % H, :w]
            for u in range(w):
                fxz[u] = 0.0
                fxx[u] = 0.0
            for mk in range(K):
                xa = X[a, mk]
                za = Z[a, mk]
                xs = XhT[mk, lo_a:lo_a + w]
                zs = ZhT[mk, lo_a:lo_a + w]
                for u in range(w):
                    fxz[u] += xa * zs[u] - xs[u] * za
                    fxx[u] += xa * xs[u] + za * zs[u]
        if use_trunk:
            for t in range(L):
                th = yaw_b[i] - yaw_h[j0 + t]
                co[t] = np.cos(th)
                si[t] = np.sin(th)
        else:
            # eq. 7 over the window: the diagonal's products
            for t in range(L):
                sxz[t] = 0.0
                sxx[t] = 0.0
            for k in range(-half, half + 1):
                a = i + k
                if a < 0 or a >= n:
                    continue
                t_lo = max(0, -(j0 + k))
                t_hi = min(L, m - (j0 + k))
                if t_lo >= t_hi:
                    continue
                w = t_hi - t_lo
                base = j0 + k + t_lo - need_lo[a]
                f_xz = FXZ[a % H, base:base + w]
                f_xx = FXX[a % H, base:base + w]
                s_xz = sxz[t_lo:t_hi]
                s_xx = sxx[t_lo:t_hi]
                for u in range(w):
                    s_xz[u] += f_xz[u]
                    s_xx[u] += f_xx[u]
            # the cells whose window is whole, t0 <= t < t1: the centring sums precomputed
            t0 = 0
            t1 = 0
            if half <= i < n - half:
                t0 = min(max(half - j0, 0), L)
                t1 = max(min(m - half - j0, L), t0)
            bxi = WX[i]
            bzi = WZ[i]
            whx = WXh[j0 + t0:j0 + t1]
            whz = WZh[j0 + t0:j0 + t1]
            s_xz = sxz[t0:t1]
            s_xx = sxx[t0:t1]
            cs = co[t0:t1]
            sn = si[t0:t1]
            for t in range(t1 - t0):  # without branches, so it vectorises: r = 0 gives the identity
                num = s_xz[t] - (bxi * whz[t] - whx[t] * bzi) / whole
                den = s_xx[t] - (bxi * whx[t] + bzi * whz[t]) / whole
                rad = np.sqrt(num * num + den * den)
                r0 = (rad == 0.0) * 1.0
                rr = rad + r0
                cs[t] = den / rr + r0
                sn[t] = num / rr
            # the cells near the clips' ends: the window's frames inside both clips
            for t in range(L):
                if t0 <= t < t1:
                    continue
                j = j0 + t
                bx = 0.0
                bz = 0.0
                hx = 0.0
                hz = 0.0
                cnt = 0
                for k in range(-half, half + 1):
                    a = i + k
                    b = j + k
                    if a < 0 or a >= n or b < 0 or b >= m:
                        continue
                    bx += SX[a]
                    bz += SZ[a]
                    hx += SXh[b]
                    hz += SZh[b]
                    cnt += K
                num = sxz[t] - (bx * hz - hx * bz) / cnt
                den = sxx[t] - (bx * hx + bz * hz) / cnt
                rad = np.sqrt(num * num + den * den)
                r0 = (rad == 0.0) * 1.0
                rr = rad + r0
                co[t] = den / rr + r0
                si[t] = num / rr
        dl = acc[:L]
        for t in range(L):
            dl[t] = 0.0
        cs = co[:L]
        sn = si[:L]
        for mk in range(K):
            b0 = SB[i, mk, 0]
            b1 = SB[i, mk, 1]
            b2 = SB[i, mk, 2]
            b3 = SB[i, mk, 3]
            b4 = SB[i, mk, 4]
            b5 = SB[i, mk, 5]
            vx = VX[mk, j0:j0 + L]
            vz = VZ[mk, j0:j0 + L]
            axs = AX[mk, j0:j0 + L]
            azs = AZ[mk, j0:j0 + L]
            sv = SV[mk, j0:j0 + L]
            sa_ = SA[mk, j0:j0 + L]
            for t in range(L):
                x = vx[t]
                z = vz[t]
                u = cs[t] * x + sn[t] * z
                w = -sn[t] * x + cs[t] * z
                ev = b0 - ((u > eps_vh) * 1.0 - (u < -eps_vh) * 1.0)
                ew = b2 - ((w > eps_vh) * 1.0 - (w < -eps_vh) * 1.0)
                x = axs[t]
                z = azs[t]
                u = cs[t] * x + sn[t] * z
                w = -sn[t] * x + cs[t] * z
                ea = b3 - ((u > eps_ah) * 1.0 - (u < -eps_ah) * 1.0)
                eb = b5 - ((w > eps_ah) * 1.0 - (w < -eps_ah) * 1.0)
                e1 = b1 - sv[t]
                e4 = b4 - sa_[t]
                dd = dl[t]
                dd += ev * ev
                dd += ew * ew
                dd += ea * ea
                dd += eb * eb
                dd += e1 * e1
                dd += e4 * e4
                dl[t] = dd
        oc = out[c:c + L]
        for t in range(L):
            oc[t] = dl[t]
        c += L


@dataclass(frozen=True)
class FirstPassInput:
    """What eq. 6 and 7 need of both clips (built by :func:`align_hands`).

    Parameters
    ----------
    P, Q : (n, K, 3), (m, K, 3) float
        Body and hand markers, shoulder subtracted, cm, Y up.
    vb, ab, vh, ah : (n, K, 3), (n, K, 3), (m, K, 3), (m, K, 3) float
        Their first (cm/s) and second (cm/s²) derivatives.
    eps : (4,) float
        Dead zones of vb, ab, vh, ah.
    half : int
        Half-width of eq. 7's window in frames (2 for 5 frames).
    yaw_b, yaw_h : (n,), (m,) float or None
        Trunk headings in degrees; None to use eq. 7.
    """

    P: np.ndarray
    Q: np.ndarray
    vb: np.ndarray
    ab: np.ndarray
    vh: np.ndarray
    ah: np.ndarray
    eps: tuple
    half: int
    yaw_b: np.ndarray | None
    yaw_h: np.ndarray | None


def cell_runs(rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cells as runs along rows: first row, first column and length of each run, three ``(R,)`` int64."""
    rows = np.ascontiguousarray(rows, np.int64)
    cols = np.ascontiguousarray(cols, np.int64)
    if not len(rows):
        return rows, cols, np.zeros(0, np.int64)
    starts = np.concatenate([[0], np.nonzero((rows[1:] != rows[:-1]) | (cols[1:] != cols[:-1] + 1))[0] + 1])
    return rows[starts], cols[starts], np.diff(np.append(starts, len(rows)))


def band_runs(band) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A :class:`~usdhands.algorithms.dtw.Band`'s rows as runs (see :func:`cell_runs`), empty rows left out."""
    width = band.hi - band.lo + 1
    keep = np.nonzero(width > 0)[0]
    return keep.astype(np.int64), band.lo[keep], width[keep]


def first_pass_cost(inp: FirstPassInput, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Eq. 6 on the given cells, in any order (numba); see :func:`first_pass_cost_naive` for the definition.

    ``(N,)``, uint8 (float64 for more than 10 markers): the costs are counts, 0 to ``24 K``.
    """
    rows = np.asarray(rows, np.int64)
    cols = np.asarray(cols, np.int64)
    order = np.lexsort((cols, rows))  # the kernel takes runs row after row
    costs = _first_pass_runs(inp, *cell_runs(rows[order], cols[order]))
    out = np.empty_like(costs)
    out[order] = costs
    return out


def first_pass_band_cost(inp: FirstPassInput, band) -> np.ndarray:
    """Eq. 6 on every cell of a band, in its flat row-major order (for ``dtw(..., on_band=True)``).

    ``(num_cells,)`` uint8 (float64 for more than 10 markers), as :func:`first_pass_cost`:
    an eighth of the memory of float64 costs, which ``dtw`` keeps as they are.
    """
    return _first_pass_runs(inp, *band_runs(band))


def _first_pass_runs(inp: FirstPassInput, run_row, run_col, run_len) -> np.ndarray:
    use_trunk = inp.yaw_b is not None
    yb = np.radians(inp.yaw_b) if use_trunk else np.zeros(1)
    yh = np.radians(inp.yaw_h) if use_trunk else np.zeros(1)
    out = np.empty(int(np.sum(run_len)), dtype=np.uint8 if 24 * inp.P.shape[1] <= 255 else np.float64)
    _first_pass_kernel(run_row, run_col, run_len, inp.P, inp.Q, inp.vb, inp.ab, inp.vh, inp.ah, *inp.eps,
                       inp.half, use_trunk, yb, yh, out)
    return out


def window_yaw_naive(P: np.ndarray, Q: np.ndarray, i: int, j: int, half: int = 2) -> float:
    """Eq. 7 for one pair of frames in NumPy: the rotation about Y (radians) taking Q's window onto P's.

    Parameters
    ----------
    P : (n, K, 3) float
        Body markers, Y up.
    Q : (m, K, 3) float
        Hand markers, Y up.
    i, j : int
        Frames; the window holds frames ``i + k, j + k`` for ``|k| <= half`` inside both clips.
    """
    ks = [k for k in range(-half, half + 1) if 0 <= i + k < len(P) and 0 <= j + k < len(Q)]
    a = P[[i + k for k in ks]].reshape(-1, 3)
    b = Q[[j + k for k in ks]].reshape(-1, 3)
    n = len(a)
    x, z, xp, zp = a[:, 0], a[:, 2], b[:, 0], b[:, 2]
    num = np.sum(x * zp - xp * z) - (x.sum() * zp.sum() - xp.sum() * z.sum()) / n
    den = np.sum(x * xp + z * zp) - (x.sum() * xp.sum() + z.sum() * zp.sum()) / n
    return float(np.arctan2(num, den))


def first_pass_cost_naive(inp: FirstPassInput) -> np.ndarray:
    """Eq. 6 on every cell, ``(n, m)``, in plain NumPy (the reference twin).

    ``D(i, j) = Σ_markers |sgn(v_i) − sgn(R v'_j)|² + |sgn(a_i) − sgn(R a'_j)|²`` with
    ``R = R_y(θ(i, j))`` from eq. 7 (or the trunk angles).
    """
    n, m = inp.P.shape[0], inp.Q.shape[0]
    eps_vb, eps_ab, eps_vh, eps_ah = inp.eps
    sg = lambda x, e: np.where(x > e, 1.0, np.where(x < -e, -1.0, 0.0))
    out = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            if inp.yaw_b is not None:
                th = np.radians(inp.yaw_b[i] - inp.yaw_h[j])
            else:
                th = window_yaw_naive(inp.P, inp.Q, i, j, inp.half)
            R = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
            rv = inp.vh[j] @ R.T
            ra = inp.ah[j] @ R.T
            out[i, j] = (np.sum((sg(inp.vb[i], eps_vb) - sg(rv, eps_vh)) ** 2)
                         + np.sum((sg(inp.ab[i], eps_ab) - sg(ra, eps_ah)) ** 2))
    return out


# -- second pass: forearm-aligned hand angle (eq. 8, 9) ---------------------------------
def forearm_hand_vectors(markers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit forearm and hand vectors of eq. 8, two ``(T, 3)`` from markers ``(T, 4, 3)``."""
    mid = 0.5 * (markers[:, 0] + markers[:, 1])
    f = markers[:, 2] - mid
    h = markers[:, 3] - mid
    unit = lambda v: v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)
    return unit(f), unit(h)




def hand_directions(clip: Clip, side: HandSide, offsets: MarkerOffsets | None = None,
                    world: np.ndarray | None = None) -> np.ndarray:
    """The hand vector of eq. 8 in the forearm joint's frame, ``(T, 3)`` unit vectors.

    ``u(t) = R_f(t)ᵀ h(t)``, with ``R_f`` the forearm joint's world rotation: the forearm
    is aligned as a whole frame rather than by the minimal rotation between forearm
    vectors, so the twist about the forearm stays fixed. Two rigs' forearm frames may
    differ by a constant rotation (other joint axes); :func:`align_hands` removes it
    with a least-squares fit over the first pass's matches.
    """
    sk = clip.skeleton
    offsets = default_marker_offsets(sk, side) if offsets is None else offsets
    world = clip.world_xforms() if world is None else world
    return hand_directions_from_xforms(world[:, sk.index(side.wrist)], world[:, sk.index(side.forearm)], offsets)


def hand_directions_from_xforms(wrist: np.ndarray, forearm: np.ndarray, offsets: MarkerOffsets) -> np.ndarray:
    """:func:`hand_directions` from the wrist's and the forearm's world transforms, two ``(T, 4, 4)``.

    Compiled; the same bits as :func:`hand_directions_numpy` (a test holds them together).
    """
    o = offsets.as_array()
    hv = o[3] - 0.5 * (o[0] + o[1])  # in the wrist frame
    out = np.empty((wrist.shape[0], 3))
    _hand_directions_kernel(np.ascontiguousarray(wrist, dtype=np.float64),
                            np.ascontiguousarray(forearm, dtype=np.float64), hv, out)
    return out


def hand_directions_numpy(wrist: np.ndarray, forearm: np.ndarray, offsets: MarkerOffsets) -> np.ndarray:
    """:func:`hand_directions_from_xforms` in NumPy (the twin the tests hold it to)."""
    o = offsets.as_array()
    hv = o[3] - 0.5 * (o[0] + o[1])
    Rw = _rot_only(wrist[:, :3, :3])
    Rf = _rot_only(forearm[:, :3, :3])
    u = np.einsum("tji,tjk,k->ti", Rf, Rw, hv)
    return u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-12)


@njit(cache=True)
def _hand_directions_kernel(wrist, forearm, hv, out):  # pragma: no cover - compiled
    """``u = Rfᵀ Rw hv`` normalised, per frame, with ``Rw, Rf`` the 3x3 blocks divided by
    their column norms (``_rot_only``). NumPy's order: column norms as sums of squares left
    to right; einsum's sum over ``j`` of partial sums over ``k``, products ``(Rf Rw) hv``."""
    Rw = np.empty((3, 3))
    Rf = np.empty((3, 3))
    for t in range(wrist.shape[0]):
        for c in range(3):
            nw = np.sqrt(wrist[t, 0, c] * wrist[t, 0, c] + wrist[t, 1, c] * wrist[t, 1, c]
                         + wrist[t, 2, c] * wrist[t, 2, c])
            nf = np.sqrt(forearm[t, 0, c] * forearm[t, 0, c] + forearm[t, 1, c] * forearm[t, 1, c]
                         + forearm[t, 2, c] * forearm[t, 2, c])
            nw = max(nw, 1e-12)
            nf = max(nf, 1e-12)
            for r in range(3):
                Rw[r, c] = wrist[t, r, c] / nw
                Rf[r, c] = forearm[t, r, c] / nf
        u0 = 0.0
        u1 = 0.0
        u2 = 0.0
        for i in range(3):
            s = 0.0
            for j in range(3):
                acc = 0.0
                for k in range(3):
                    acc += Rf[j, i] * Rw[j, k] * hv[k]
                s += acc
            if i == 0:
                u0 = s
            elif i == 1:
                u1 = s
            else:
                u2 = s
        nrm = max(np.sqrt(u0 * u0 + u1 * u1 + u2 * u2), 1e-12)
        out[t, 0] = u0 / nrm
        out[t, 1] = u1 / nrm
        out[t, 2] = u2 / nrm


def forearm_rest_basis(skeleton, side: HandSide, offsets: MarkerOffsets | None = None) -> np.ndarray:
    """Rest-pose axes of the hand in the forearm joint's frame, ``(3, 3)`` (columns).

    Columns: the hand vector of eq. 8, the wrist markers' across direction (made
    perpendicular), their cross product, all at rest and in forearm-local coordinates.
    ``B_body · B_handᵀ`` maps :func:`hand_directions` of the hand rig onto the body rig's
    when both rest poses hold the hand alike.
    """
    offsets = default_marker_offsets(skeleton, side) if offsets is None else offsets
    rest = skeleton.rest_world_xforms()
    rw = _rot_only(rest[skeleton.index(side.wrist), :3, :3])
    rf = _rot_only(rest[skeleton.index(side.forearm), :3, :3])
    o = offsets.as_array()
    e1 = rf.T @ rw @ (o[3] - 0.5 * (o[0] + o[1]))
    e1 = e1 / np.linalg.norm(e1)
    e2 = rf.T @ rw @ (o[0] - o[1])
    e2 = e2 - e1 * np.dot(e1, e2)
    if np.linalg.norm(e2) < 1e-9:
        helper = np.array([0.0, 1.0, 0.0]) if abs(e1[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        e2 = np.cross(e1, helper)
    e2 = e2 / np.linalg.norm(e2)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=1)


def fit_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation ``(3, 3)`` minimising ``Σ |a_k − R b_k|²`` over rows of ``(N, 3)`` arrays (Kabsch)."""
    H = np.asarray(b, dtype=np.float64).T @ np.asarray(a, dtype=np.float64)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    return Vt.T @ np.diag([1.0, 1.0, d]) @ U.T


@njit(cache=True)
def _angle_kernel(run_row, run_col, run_len, ub, uh):  # pragma: no cover - compiled
    N = 0
    for r in range(run_row.shape[0]):
        N += run_len[r]
    out = np.empty(N)
    c = 0
    for r in range(run_row.shape[0]):
        i = run_row[r]
        for j in range(run_col[r], run_col[r] + run_len[r]):
            d = ub[i, 0] * uh[j, 0] + ub[i, 1] * uh[j, 1] + ub[i, 2] * uh[j, 2]
            if d > 1.0:
                d = 1.0
            elif d < -1.0:
                d = -1.0
            out[c] = np.degrees(np.arccos(d))
            c += 1
    return out


def direction_angle_cost(ub: np.ndarray, uh: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Angle in degrees between unit vectors ``ub[rows]`` ``(n, 3)`` and ``uh[cols]`` ``(m, 3)`` (numba)."""
    return _angle_kernel(*cell_runs(rows, cols), np.ascontiguousarray(ub, np.float64),
                         np.ascontiguousarray(uh, np.float64))


def direction_angle_band_cost(ub: np.ndarray, uh: np.ndarray, band) -> np.ndarray:
    """:func:`direction_angle_cost` on every cell of a band, flat row-major (for ``dtw(..., on_band=True)``)."""
    return _angle_kernel(*band_runs(band), np.ascontiguousarray(ub, np.float64), np.ascontiguousarray(uh, np.float64))


@njit(cache=True)
def _hand_angle_kernel(rows, cols, fb, hb, fh, hh):  # pragma: no cover - compiled
    N = rows.shape[0]
    out = np.empty(N)
    for c in range(N):
        i = rows[c]
        j = cols[c]
        a0, a1, a2 = fh[j, 0], fh[j, 1], fh[j, 2]  # f' (rotate onto f)
        b0, b1, b2 = fb[i, 0], fb[i, 1], fb[i, 2]
        v0, v1, v2 = hh[j, 0], hh[j, 1], hh[j, 2]
        cth = a0 * b0 + a1 * b1 + a2 * b2
        if cth > -1.0 + 1e-9:
            # Rodrigues with k = a x b: R v = c v + k x v + k (k.v) / (1 + c)
            k0 = a1 * b2 - a2 * b1
            k1 = a2 * b0 - a0 * b2
            k2 = a0 * b1 - a1 * b0
            kv = (k0 * v0 + k1 * v1 + k2 * v2) / (1.0 + cth)
            r0 = cth * v0 + (k1 * v2 - k2 * v1) + k0 * kv
            r1 = cth * v1 + (k2 * v0 - k0 * v2) + k1 * kv
            r2 = cth * v2 + (k0 * v1 - k1 * v0) + k2 * kv
        else:
            # opposite vectors: half turn about an axis perpendicular to a
            if abs(a0) < 0.9:
                p0, p1, p2 = 0.0, -a2, a1
            else:
                p0, p1, p2 = a2, 0.0, -a0
            nn = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
            p0 /= nn
            p1 /= nn
            p2 /= nn
            pv = p0 * v0 + p1 * v1 + p2 * v2
            r0 = 2.0 * pv * p0 - v0
            r1 = 2.0 * pv * p1 - v1
            r2 = 2.0 * pv * p2 - v2
        d = hb[i, 0] * r0 + hb[i, 1] * r1 + hb[i, 2] * r2
        nr = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        d = d / max(nr, 1e-12)
        if d > 1.0:
            d = 1.0
        elif d < -1.0:
            d = -1.0
        out[c] = np.degrees(np.arccos(d))
    return out


def hand_angle_cost(fb: np.ndarray, hb: np.ndarray, fh: np.ndarray, hh: np.ndarray,
                    rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Eq. 9 in degrees on the given cells (numba).

    Parameters
    ----------
    fb, hb : (n, 3) float
        Unit forearm and hand vectors of the body clip.
    fh, hh : (m, 3) float
        The same for the hand clip.
    rows, cols : (N,) int
        Cells.
    """
    return _hand_angle_kernel(np.ascontiguousarray(rows, np.int64), np.ascontiguousarray(cols, np.int64),
                              np.ascontiguousarray(fb), np.ascontiguousarray(hb),
                              np.ascontiguousarray(fh), np.ascontiguousarray(hh))


def hand_angle_cost_naive(fb: np.ndarray, hb: np.ndarray, fh: np.ndarray, hh: np.ndarray) -> np.ndarray:
    """Eq. 9 on every cell, ``(n, m)`` degrees, with scipy's rotation alignment (the twin)."""
    from scipy.spatial.transform import Rotation

    out = np.empty((len(fb), len(fh)))
    for i in range(len(fb)):
        for j in range(len(fh)):
            R, _ = Rotation.align_vectors(fb[i][None], fh[j][None])
            v = R.apply(hh[j])
            c = np.dot(hb[i], v) / (np.linalg.norm(hb[i]) * np.linalg.norm(v))
            out[i, j] = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
    return out

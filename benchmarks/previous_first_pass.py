"""The first-pass kernel of splicing as it was before the run-vectorised rewrite (cell by cell).

Kept for ``bench_splice.py``: the reference its figures are compared with, and a check
that the current kernel gives the same costs to the bit. Compiled on first use, not cached.
"""

import numpy as np
from usdhands.jit import njit

from usdhands.algorithms.splicing.costs import _sgn


@njit(cache=False)
def _window_cos_sin(X, Z, Xh, Zh, SX, SZ, SXh, SZh, i, j, half):  # pragma: no cover - compiled
    """cos and sin of eq. 7's angle (num and den normalised, no atan2).

    ``X, Z`` ``(n, K)`` are the body markers' horizontal coordinates, ``SX, SZ`` ``(n,)``
    their sums over the markers; ``Xh, Zh, SXh, SZh`` the same for the hand.
    """
    n = X.shape[0]
    m = Xh.shape[0]
    K = X.shape[1]
    sxz = 0.0
    sxx = 0.0
    bx = 0.0
    bz = 0.0
    hx = 0.0
    hz = 0.0
    cnt = 0
    for k in range(-half, half + 1):
        a = i + k
        b = j + k
        if a < 0 or b < 0 or a >= n or b >= m:
            continue
        for mk in range(K):
            sxz += X[a, mk] * Zh[b, mk] - Xh[b, mk] * Z[a, mk]
            sxx += X[a, mk] * Xh[b, mk] + Z[a, mk] * Zh[b, mk]
        bx += SX[a]
        bz += SZ[a]
        hx += SXh[b]
        hz += SZh[b]
        cnt += K
    num = sxz - (bx * hz - hx * bz) / cnt
    den = sxx - (bx * hx + bz * hz) / cnt
    r = np.sqrt(num * num + den * den)
    if r == 0.0:
        return 1.0, 0.0  # atan2(0, 0) = 0
    return den / r, num / r


@njit(cache=False)
def previous_first_pass_kernel(rows, cols, P, Q, vb, ab, vh, ah, eps_vb, eps_ab, eps_vh, eps_ah,
                       half, use_trunk, yaw_b, yaw_h):  # pragma: no cover - compiled
    N = rows.shape[0]
    K = P.shape[1]
    out = np.empty(N)
    X = np.ascontiguousarray(P[:, :, 0])
    Z = np.ascontiguousarray(P[:, :, 2])
    Xh = np.ascontiguousarray(Q[:, :, 0])
    Zh = np.ascontiguousarray(Q[:, :, 2])
    SX = X.sum(axis=1)
    SZ = Z.sum(axis=1)
    SXh = Xh.sum(axis=1)
    SZh = Zh.sum(axis=1)
    n = vb.shape[0]
    m = vh.shape[0]
    SB = np.empty((n, K, 6))  # body signs: v then a, x y z
    for i in range(n):
        for mk in range(K):
            for ax in range(3):
                SB[i, mk, ax] = _sgn(vb[i, mk, ax], eps_vb)
                SB[i, mk, 3 + ax] = _sgn(ab[i, mk, ax], eps_ab)
    SH = np.empty((m, K, 2))  # hand signs of the vertical components
    for j in range(m):
        for mk in range(K):
            SH[j, mk, 0] = _sgn(vh[j, mk, 1], eps_vh)
            SH[j, mk, 1] = _sgn(ah[j, mk, 1], eps_ah)
    for c in range(N):
        i = rows[c]
        j = cols[c]
        if use_trunk:
            th = yaw_b[i] - yaw_h[j]
            co = np.cos(th)
            si = np.sin(th)
        else:
            co, si = _window_cos_sin(X, Z, Xh, Zh, SX, SZ, SXh, SZh, i, j, half)
        d = 0.0
        for mk in range(K):
            # R_y(θ) applied to the hand's derivatives: x' = c x + s z, z' = -s x + c z
            x = vh[j, mk, 0]
            z = vh[j, mk, 2]
            e = SB[i, mk, 0] - _sgn(co * x + si * z, eps_vh)
            d += e * e
            e = SB[i, mk, 2] - _sgn(-si * x + co * z, eps_vh)
            d += e * e
            x = ah[j, mk, 0]
            z = ah[j, mk, 2]
            e = SB[i, mk, 3] - _sgn(co * x + si * z, eps_ah)
            d += e * e
            e = SB[i, mk, 5] - _sgn(-si * x + co * z, eps_ah)
            d += e * e
            e = SB[i, mk, 1] - SH[j, mk, 0]  # vertical components do not turn
            d += e * e
            e = SB[i, mk, 4] - SH[j, mk, 1]
            d += e * e
        out[c] = d
    return out

"""Smoothing finger curves and corrections: an RTS Kalman smoother and a bound-constrained smoother.

:func:`rts_smooth` is the Kalman filter with a Rauch-Tung-Striebel backward pass on a
constant-velocity model, vectorised over curves: with the same model and no missing
samples every curve shares the gains, so they are computed once per frame and applied
to all curves as array operations.

:func:`bounded_smooth` smooths a correction that must not go below a bound (the least
opening that clears every collider): the least-squares fit to the bound with a penalty
on second differences, subject to ``lower <= x``, a banded problem solved by an active-set method with
banded Cholesky solves (``scipy.optimize.lsq_linear`` took 11 s on 1,800 frames). The result can never dip below the bound, so smoothing
cannot put a contact back.
"""

from __future__ import annotations

import numpy as np

from usdhands.jit import kernels_running

__all__ = ["rts_smooth", "bounded_smooth", "smoothness_weight"]


def rts_smooth(values: np.ndarray, fps: float, time_scale_s: float) -> np.ndarray:
    """Kalman + RTS smoothing of curves ``(T, C)`` sampled at ``fps``.

    Parameters
    ----------
    values : (T, C) float
        Curves, any units.
    fps : float
    time_scale_s : float
        Motion faster than about this is treated as noise (process to measurement
        noise ratio ``time_scale_s ** -4``, constant-velocity model).

    Returns
    -------
    (T, C) float
    """
    z = np.asarray(values, dtype=np.float64)
    T = z.shape[0]
    if T < 3 or time_scale_s <= 0:
        return z.copy()
    dt = 1.0 / fps
    F = np.array([[1.0, dt], [0.0, 1.0]])
    q = time_scale_s ** -4
    Q = q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
    r = 1.0
    # covariances and gains: the same for every curve, 2x2 per frame
    P_pred = np.empty((T, 2, 2))
    P_filt = np.empty((T, 2, 2))
    K = np.empty((T, 2))
    P = np.array([[r, 0.0], [0.0, 1e6]])
    steady = T  # the gains are the same from this frame on
    for t in range(T):
        if t > 0:
            P = F @ P @ F.T + Q
        if t > 1 and np.allclose(P, P_pred[t - 1], rtol=1e-13, atol=0.0):  # steady state reached
            P_pred[t:], K[t:], P_filt[t:] = P_pred[t - 1], K[t - 1], P_filt[t - 1]
            steady = t - 1
            break
        P_pred[t] = P
        k = P[:, 0] / (P[0, 0] + r)
        K[t] = k
        P = P - np.outer(k, P[0])
        P_filt[t] = P
    G = P_filt[:-1] @ F.T @ np.linalg.inv(P_pred[1:])  # (T-1, 2, 2) smoother gains
    flat = z.reshape(T, -1)
    # Where the gains are steady both passes are a fixed linear recursion of the 2-vector state,
    # x_t = A x_(t-1) + u_t, so each state component follows the second-order recursion
    # x_t = tr(A) x_(t-1) - det(A) x_(t-2) + u_t + (A - tr(A) I) u_(t-1) (Cayley-Hamilton),
    # run by a compiled loop with lfilter's arithmetic; the frames before (and the two that start each recursion) are stepped.
    head = min(steady + 2, T)
    pos = np.empty_like(flat)
    vel = np.empty_like(flat)
    p, v = flat[0].copy(), np.zeros(flat.shape[1])
    for t in range(head):  # filter: predict, then correct with the shared gain
        if t > 0:
            p = p + dt * v
        innov = flat[t] - p
        p = p + K[t, 0] * innov
        v = v + K[t, 1] * innov
        pos[t] = p
        vel[t] = v
    if head < T:
        k = K[-1]
        A = (np.eye(2) - np.outer(k, [1.0, 0.0])) @ F
        u = (k[0] * flat, k[1] * flat)  # u_t = K z_t
        _recur(A, u, (pos, vel), head, T)
    sp, sv = np.empty_like(flat), np.empty_like(flat)
    sp[-1], sv[-1] = pos[-1], vel[-1]
    tail = T - 3 if steady <= T - 4 else 0  # the recursion runs backward from here to `steady`
    for t in range(T - 2, -1, -1):  # RTS backward pass
        if t == tail - 1 and tail > 0:
            break
        dp = sp[t + 1] - (pos[t] + dt * vel[t])
        dv = sv[t + 1] - vel[t]
        sp[t] = pos[t] + G[t, 0, 0] * dp + G[t, 0, 1] * dv
        sv[t] = vel[t] + G[t, 1, 0] * dp + G[t, 1, 1] * dv
    if tail > 0:
        g = G[-1]
        n = np.eye(2) - g @ F  # s_t = G s_(t+1) + (I - G F) x_t
        u = (n[0, 0] * pos + n[0, 1] * vel, n[1, 0] * pos + n[1, 1] * vel)
        rev = lambda a: a[::-1]  # noqa: E731  time reversed: the backward pass runs forward
        _recur(g, tuple(map(rev, u)), (rev(sp), rev(sv)), T - tail, T - steady)
        for t in range(steady - 1, -1, -1):
            dp = sp[t + 1] - (pos[t] + dt * vel[t])
            dv = sv[t + 1] - vel[t]
            sp[t] = pos[t] + G[t, 0, 0] * dp + G[t, 0, 1] * dv
            sv[t] = vel[t] + G[t, 1, 0] * dp + G[t, 1, 1] * dv
    return sp.reshape(z.shape)


def _recur(A: np.ndarray, u: tuple, x: tuple, start: int, stop: int) -> None:
    """Run ``x_t = A x_(t-1) + u_t`` for ``t`` in ``[start, stop)`` in place, as a second-order recursion on
    each component with the arithmetic of ``scipy.signal.lfilter``: compiled ahead of time where it was built
    (:mod:`usdhands.compiled`), else numba's where a kernel of the package already runs
    (:func:`usdhands.jit.kernels_running`, :mod:`._recursion_kernel`), else :func:`second_order_steps`
    (the same bits).

    ``A`` ``(2, 2)``; ``u`` and ``x``: the two components, ``(T, C)`` arrays (views allowed);
    ``x`` holds the states at ``start - 2`` and ``start - 1`` (``start >= 2``).
    """
    from usdhands.compiled import kernel_module

    built = kernel_module("algorithms.interaction._interaction_compiled")
    if built is not None:
        run = built.second_order
    elif kernels_running():
        from usdhands.algorithms.interaction._recursion_kernel import second_order as run
    else:
        run = second_order_steps
    tr, det = float(np.trace(A)), float(np.linalg.det(A))
    C = A - tr * np.eye(2)
    w, zi = [], []
    for i in range(2):
        w.append(u[i][start:stop] + C[i, 0] * u[0][start - 1:stop - 1] + C[i, 1] * u[1][start - 1:stop - 1])
        y1, y2 = x[i][start - 1], x[i][start - 2]
        zi.append(np.stack([tr * y1 - det * y2, -det * y1]))  # the state after y_(start-1), y_(start-2)
    # both components follow the same recursion: one pass over their columns side by side
    y = run(np.ascontiguousarray(np.concatenate(w, axis=1)), -tr, det, np.ascontiguousarray(np.concatenate(zi, axis=1)))
    n = w[0].shape[1]
    x[0][start:stop], x[1][start:stop] = y[:, :n], y[:, n:]


def second_order_steps(x: np.ndarray, a1: float, a2: float, zi: np.ndarray) -> np.ndarray:
    """``scipy.signal.lfilter([1.0], [1.0, a1, a2], x, axis=0, zi=zi)[0]`` for ``x`` ``(n, C)`` and ``zi``
    ``(2, C)``, a step at a time over all columns with lfilter's very operations (its transposed direct
    form II, the numerator padded with zeros), so the same bits: a few milliseconds for 1,800 frames,
    without importing ``scipy.signal`` or a compiler."""
    x = np.asarray(x, dtype=np.float64)
    y = np.empty_like(x)
    xz = x * 0.0  # x * b1 and x * b2, the numerator's zero coefficients
    z0 = np.array(zi[0], dtype=np.float64)
    z1 = np.array(zi[1], dtype=np.float64)
    t = np.empty_like(z0)
    for k in range(len(x)):
        yk = y[k]
        np.add(z0, x[k], out=yk)  # z0 + 1.0 * x
        np.add(z1, xz[k], out=z0)
        np.multiply(yk, a1, out=t)
        np.subtract(z0, t, out=z0)
        np.multiply(yk, a2, out=t)
        np.subtract(xz[k], t, out=z1)
    return y


def smoothness_weight(fps: float, time_scale_s: float) -> float:
    """Weight of the second-difference penalty giving a smoother of about ``time_scale_s``."""
    return float((max(time_scale_s, 0.0) * fps) ** 4)


def _second_difference_bands(T: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The diagonals of ``D.T @ D`` for the ``(T-2, T)`` second-difference operator ``D``, ``T >= 3``
    (pentadiagonal, symmetric): the main one ``(T,)`` ``1, 5, 6, ..., 6, 5, 1``, the first above it
    ``(T-1,)`` ``-2, -4, ..., -4, -2`` and the second ``(T-2,)`` of ones (integers: exact)."""
    d0 = np.zeros(T)
    d0[:T - 2] += 1.0
    d0[1:T - 1] += 4.0
    d0[2:] += 1.0
    d1 = np.zeros(T - 1)
    d1[:T - 2] -= 2.0
    d1[1:] -= 2.0
    return d0, d1, np.ones(T - 2)


def _banded_product(diagonals: tuple, y: np.ndarray) -> np.ndarray:
    """``H @ y`` ``(T,)`` for the symmetric pentadiagonal ``H`` given by its ``diagonals`` (0, 1 and 2 above
    the main one, as :func:`_second_difference_bands` gives them) and ``y`` ``(T,)``."""
    d0, d1, d2 = diagonals
    out = d0 * y
    out[:-1] += d1 * y[1:]
    out[1:] += d1 * y[:-1]
    out[:-2] += d2 * y[2:]
    out[2:] += d2 * y[:-2]
    return out


def _solve_banded(ab: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``scipy.linalg.solveh_banded(ab, rhs)`` for the upper bands ``ab`` ``(3, n)`` of a positive definite
    pentadiagonal matrix: the banded Cholesky compiled ahead of time where it was built (no SciPy to
    import: its linear algebra and sparse modules cost a fresh ``correct`` about 0.1 s), else SciPy's."""
    from usdhands.compiled import kernel_module

    built = kernel_module("algorithms.interaction._interaction_compiled")
    if built is not None:
        return built.solve_pentadiagonal_spd(np.ascontiguousarray(ab), np.ascontiguousarray(rhs))
    from scipy.linalg import solveh_banded

    return solveh_banded(ab, rhs)


def _principal_bands(diagonals: tuple, idx: np.ndarray) -> np.ndarray:
    """The upper bands ``(3, len(idx))`` (``solveh_banded``'s layout) of the principal submatrix
    ``H[idx][:, idx]`` of a symmetric pentadiagonal ``H`` (at least 3 x 3) given by its ``diagonals``
    (0, 1 and 2 above the main one), for sorted ``idx``: the very entries of ``H``, gathered without
    building the submatrix (scipy's sparse indexing cost more than the solve)."""
    d0, d1, d2 = diagonals
    n = len(idx)
    ab = np.zeros((3, n))
    ab[2] = d0[idx]
    first = idx[:-1]
    gap = idx[1:] - first  # neighbours in the submatrix: H[i, i + 1] or H[i, i + 2], else 0
    ab[1, 1:] = np.where(gap == 1, d1[np.minimum(first, len(d1) - 1)],
                         np.where(gap == 2, d2[np.minimum(first, len(d2) - 1)], 0.0))
    if n > 2:
        ab[0, 2:] = np.where(idx[2:] - idx[:-2] == 2, d2[np.minimum(idx[:-2], len(d2) - 1)], 0.0)
    return ab


def bounded_smooth(lower: np.ndarray, upper: np.ndarray, weight: float, max_iterations: int = 100,
                   fit: np.ndarray | None = None, target: np.ndarray | None = None) -> np.ndarray:
    """The smooth curve closest to ``lower`` that stays between ``lower`` and ``upper``.

    Minimises ``sum(fit * (x - target)**2) + weight * sum((x[t-1] - 2 x[t] + x[t+1])**2)``
    subject to ``lower <= x <= upper``, by block principal pivoting on the two active
    sets: each step one banded Cholesky solve on the free frames (a principal submatrix
    of a pentadiagonal matrix is pentadiagonal again), the frames held at a bound
    entering through the right-hand side.

    Parameters
    ----------
    lower, upper : (T,) float
        Bounds, ``lower <= upper``.
    weight : float
        Second-difference penalty (:func:`smoothness_weight`); 0 returns ``lower``.
    fit : (T,) float, optional
        Weight of each frame's distance to the target (default 1 everywhere).
    target : (T,) float, optional
        The curve to stay near (default ``lower``).

    Returns
    -------
    (T,) float
        Within the bounds exactly (clipped into them should the pivoting not settle).
    """
    lower = np.asarray(lower, dtype=np.float64)
    upper = np.maximum(np.asarray(upper, dtype=np.float64), lower)
    T = len(lower)
    if T < 3 or weight <= 0 or np.all(lower == lower[0]):
        return lower.copy()
    G = _second_difference_bands(T)
    a = np.ones(T) if fit is None else np.asarray(fit, dtype=np.float64)
    bands = (a + weight * G[0], weight * G[1], weight * G[2])  # H = diag(a) + weight * G
    c = weight * _banded_product(G, lower)  # x = lower + y, minimise y.H.y/2 + c.y with 0 <= y <= room
    if target is not None:
        c = c + a * (lower - np.asarray(target, dtype=np.float64))
    room = upper - lower
    at_lo = np.zeros(T, dtype=bool)
    at_hi = np.zeros(T, dtype=bool)
    y = np.zeros(T)
    for _ in range(max_iterations):
        free = ~(at_lo | at_hi)
        y = np.where(at_hi, room, 0.0)
        if free.any():
            idx = np.nonzero(free)[0]
            rhs = -c[idx] - _banded_product(bands, y)[idx]
            y[idx] = _solve_banded(_principal_bands(bands, idx), rhs)
        grad = _banded_product(bands, y) + c
        to_lo = free & (y < -1e-12)
        to_hi = free & (y > room + 1e-12)
        off_lo = at_lo & (grad < -1e-12)
        off_hi = at_hi & (grad > 1e-12)
        if not (to_lo.any() or to_hi.any() or off_lo.any() or off_hi.any()):
            break
        at_lo = (at_lo | to_lo) & ~off_lo
        at_hi = (at_hi | to_hi) & ~off_hi
    return np.clip(lower + y, lower, upper)

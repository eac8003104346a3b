"""Finger rotations for the transfer: relative to rest, in one hemisphere, sampled at
fractional frames by slerp (used by :func:`usdhands.algorithms.splicing.splice.transfer_fingers`).

The same numbers, to the bit, as the NumPy expressions they replace
(``quat_multiply(quat_conjugate(rest)[None], q)``, the hemisphere flips by ``cumprod``,
``quat_slerp(rel[i0], rel[i1], w)``; tests hold them to it), without the dozens of
``(T, k, 4)`` temporaries: the arithmetic runs in compiled loops in NumPy's order (its
sums over the four components run left to right), and the transcendental functions
stay NumPy's, called on flat arrays (``arccos``, ``sin``), so their rounding is theirs.
"""

from __future__ import annotations

import numpy as np

from usdhands.jit import njit

__all__ = ["relative_rotations", "rest_times", "sample_rotations"]


@njit(cache=True)
def _relative_kernel(q, rest, conj, out):  # pragma: no cover - compiled
    """``out[f, k] = r_k * q[f, k]`` with ``r_k = rest[k]`` (conjugated when ``conj``),
    the Hamilton product of ``quat_multiply`` term by term."""
    T = q.shape[0]
    K = q.shape[1]
    for k in range(K):
        ax = rest[k, 0]
        ay = rest[k, 1]
        az = rest[k, 2]
        aw = rest[k, 3]
        if conj:
            ax = -ax
            ay = -ay
            az = -az
        for f in range(T):
            bx = q[f, k, 0]
            by = q[f, k, 1]
            bz = q[f, k, 2]
            bw = q[f, k, 3]
            out[f, k, 0] = aw * bx + ax * bw + ay * bz - az * by
            out[f, k, 1] = aw * by - ax * bz + ay * bw + az * bx
            out[f, k, 2] = aw * bz + ax * by - ay * bx + az * bw
            out[f, k, 3] = aw * bw - ax * bx - ay * by - az * bz


@njit(cache=True)
def _hemisphere_kernel(rel):  # pragma: no cover - compiled
    """In place: each quaternion after the first times the product of the signs of the dot
    products of all consecutive pairs up to it (``rel[1:] *= cumprod(step)``)."""
    T = rel.shape[0]
    K = rel.shape[1]
    for k in range(K):
        p0 = rel[0, k, 0]
        p1 = rel[0, k, 1]
        p2 = rel[0, k, 2]
        p3 = rel[0, k, 3]
        sign = 1.0
        for f in range(1, T):
            c0 = rel[f, k, 0]
            c1 = rel[f, k, 1]
            c2 = rel[f, k, 2]
            c3 = rel[f, k, 3]
            d = c0 * p0 + c1 * p1 + c2 * p2 + c3 * p3
            if d < 0:
                sign = -sign
            rel[f, k, 0] = c0 * sign
            rel[f, k, 1] = c1 * sign
            rel[f, k, 2] = c2 * sign
            rel[f, k, 3] = c3 * sign
            p0 = c0
            p1 = c1
            p2 = c2
            p3 = c3


@njit(cache=True)
def _slerp_cos(rel, i0, i1, dot):  # pragma: no cover - compiled
    """``quat_slerp``'s first steps on ``a = rel[i0]``, ``b = rel[i1]``: ``clip(|a . b|, -1, 1)``
    into ``dot (n, k)`` (the sign of ``a . b`` says whether ``b`` is turned into ``a``'s
    hemisphere; :func:`_slerp_mix` computes it again)."""
    n = i0.shape[0]
    K = rel.shape[1]
    for f in range(n):
        for k in range(K):
            a = rel[i0[f], k]
            c = rel[i1[f], k]
            d = abs(a[0] * c[0] + a[1] * c[1] + a[2] * c[2] + a[3] * c[3])
            if d > 1.0:
                d = 1.0
            dot[f, k] = d


@njit(cache=True)
def _slerp_mix(rel, i0, i1, w, sin_theta, sin_a, sin_b, out):  # pragma: no cover - compiled
    """``quat_slerp``'s last steps: ``b`` into ``a``'s hemisphere, the weights of ``a`` and
    ``b`` (``sin_a``, ``sin_b`` the sines of ``(1 - w) θ`` and ``w θ``), their sum, normalised."""
    n = i0.shape[0]
    K = rel.shape[1]
    for f in range(n):
        for k in range(K):
            a = rel[i0[f], k]
            b = rel[i1[f], k]
            b0 = b[0]
            b1 = b[1]
            b2 = b[2]
            b3 = b[3]
            if a[0] * b0 + a[1] * b1 + a[2] * b2 + a[3] * b3 < 0:
                b0 = -b0
                b1 = -b1
                b2 = -b2
                b3 = -b3
            s = sin_theta[f, k]
            t = w[f, k]
            if s < 1e-6:
                wa = 1.0 - t
                wb = t
            else:
                wa = sin_a[f, k] / s
                wb = sin_b[f, k] / s
            o0 = wa * a[0] + wb * b0
            o1 = wa * a[1] + wb * b1
            o2 = wa * a[2] + wb * b2
            o3 = wa * a[3] + wb * b3
            nrm = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2 + o3 * o3)
            out[f, k, 0] = o0 / nrm
            out[f, k, 1] = o1 / nrm
            out[f, k, 2] = o2 / nrm
            out[f, k, 3] = o3 / nrm


def relative_rotations(q: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """``quat_multiply(quat_conjugate(rest)[None], q)``: ``q (T, k, 4)`` relative to ``rest (k, 4)``, xyzw."""
    q = np.asarray(q, dtype=np.float64)
    out = np.empty(q.shape)
    _relative_kernel(q, np.ascontiguousarray(rest, dtype=np.float64), True, out)
    return out


def rest_times(rest: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``quat_multiply(rest[None], q)``: ``rest (k, 4)`` times ``q (T, k, 4)``, xyzw."""
    q = np.asarray(q, dtype=np.float64)
    out = np.empty(q.shape)
    _relative_kernel(q, np.ascontiguousarray(rest, dtype=np.float64), False, out)
    return out


def one_hemisphere(rel: np.ndarray) -> None:
    """In place: consecutive quaternions of ``rel (T, k, 4)`` kept in one hemisphere (flips
    by the running product of the signs of their dot products), so slerp takes short arcs."""
    _hemisphere_kernel(rel)


def sample_rotations(rel: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``rel (m, k, 4)`` at fractional frames ``t (n,)`` by slerp between the frames around
    each, ``(n, k, 4)`` (frames clipped to ``0 .. m - 1``)."""
    m, k = rel.shape[0], rel.shape[1]
    t = np.clip(t, 0.0, m - 1)
    i0 = np.minimum(np.floor(t).astype(int), max(m - 2, 0))
    i1 = np.minimum(i0 + 1, m - 1)
    w = (t - i0)[:, None] * np.ones(k)
    n = len(t)
    rel = np.ascontiguousarray(rel, dtype=np.float64)
    dot = np.empty((n, k))
    _slerp_cos(rel, i0, i1, dot)
    theta = np.arccos(dot)
    out = np.empty((n, k, 4))
    _slerp_mix(rel, i0, i1, w, np.sin(theta), np.sin((1.0 - w) * theta), np.sin(w * theta), out)
    return out

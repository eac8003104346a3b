"""Rotation helpers on batched arrays.

Glossary (all arrays batch-first, any number of leading axes ``...``):

- ``quat``: unit quaternion, **xyzw** (scalar last), shape ``(..., 4)``, float.
- ``matrix``: rotation matrix, shape ``(..., 3, 3)``.
- ``xform``: homogeneous transform for column vectors, shape ``(..., 4, 4)``;
  ``p_world = xform @ [p, 1]``. Local transforms compose as ``T @ R @ S``.
- ``euler_deg``: Euler angles in degrees, shape ``(..., 3)``, intrinsic order given
  by ``order`` (scipy's upper-case convention, default ``"XYZ"``).

Conversions are named ``source_to_target``. USD's ``Gf`` (row vectors, wxyz
quaternions) is converted only in the USD format module.

Plain NumPy, with the conventions and results of ``scipy.spatial.transform.Rotation``
(the tests compare them): importing scipy.spatial costs a quarter of a second, more than
everything else a command needs before it starts work.
"""

from __future__ import annotations

import re

import numpy as np

__all__ = [
    "DEFAULT_EULER_ORDER",
    "check_quat",
    "quat_normalize",
    "quat_multiply",
    "quat_conjugate",
    "quat_identity",
    "quat_slerp",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_to_euler_deg",
    "euler_deg_to_quat",
    "quat_to_rotvec_deg",
    "quat_angle_deg",
    "quat_canonical",
    "trs_to_xform",
    "xform_to_trs",
    "transforms_kernel",
    "unwrap_deg",
]

DEFAULT_EULER_ORDER = "XYZ"
_EYE3 = np.eye(3)
#: ``np.isclose``'s bound for a Gram matrix against the identity at ``atol=1e-12`` (its default ``rtol``)
_ORTHOGONAL_TOL = 1e-12 + 1e-5 * np.abs(_EYE3)


def check_quat(q: np.ndarray, name: str = "quat") -> np.ndarray:
    """Return ``q`` as float64 and check its last axis is 4.

    Raises
    ------
    ValueError
        ``Expected quat to have shape (..., 4), got (3,)``.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.ndim == 0 or q.shape[-1] != 4:
        raise ValueError(f"Expected {name} to have shape (..., 4), got {q.shape}")
    return q


def quat_identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions, shape ``shape + (4,)``, xyzw."""
    q = np.zeros(tuple(shape) + (4,))
    q[..., 3] = 1.0
    return q


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(..., 4)``; raises ValueError on zero length or NaN."""
    q = check_quat(q)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(n)) or np.any(n < 1e-12):
        raise ValueError("Cannot normalize quaternions with zero length or NaN")
    return q / n


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate (inverse for unit quaternions), shape ``(..., 4)``."""
    q = check_quat(q)
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``), broadcast, xyzw."""
    a = check_quat(a, "a")
    b = check_quat(b, "b")
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_canonical(q: np.ndarray) -> np.ndarray:
    """Flip quaternions to a non-negative w (same rotation), shape ``(..., 4)``."""
    q = check_quat(q)
    return np.where(q[..., 3:4] < 0, -q, q)


def quat_slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical linear interpolation, shortest path.

    Parameters
    ----------
    a, b : (..., 4) float
        Unit quaternions, xyzw.
    t : float or (...,) float
        Interpolation weight, 0 gives ``a``, 1 gives ``b``.
    """
    a = check_quat(a, "a")
    b = check_quat(b, "b")
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(dot < 0, -b, b)
    dot = np.abs(dot)
    dot = np.clip(dot, -1.0, 1.0)
    theta = np.arccos(dot)
    sin_theta = np.sin(theta)
    small = sin_theta < 1e-6
    safe = np.where(small, 1.0, sin_theta)
    wa = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    wb = np.where(small, t, np.sin(t * theta) / safe)
    out = wa * a + wb * b
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def _unit_quats(q: np.ndarray) -> np.ndarray:
    """``q`` ``(..., 4)`` divided by its norm; ValueError on a zero norm (as scipy's from_quat)."""
    x, y, z, w = np.moveaxis(q, -1, 0)
    n = np.sqrt(x * x + y * y + z * z + w * w)[..., None]  # scipy's order of operations, to the bit
    if np.any(n == 0):
        raise ValueError("Found zero norm quaternions in `quat`.")
    return q / n


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from quaternions ``(..., 4)`` xyzw (normalized first)."""
    x, y, z, w = np.moveaxis(_unit_quats(check_quat(q)), -1, 0)
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    m = np.stack([
        x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw),
        2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw),
        2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2,
    ], axis=-1)
    return m.reshape(m.shape[:-1] + (3, 3))


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` xyzw from rotation matrices ``(..., 3, 3)``.

    A matrix that is not orthogonal is replaced by the nearest orthogonal one (SVD).

    Raises
    ------
    ValueError
        ``Non-positive determinant ...`` for a reflection or a singular matrix.
    """
    m = np.asarray(m, dtype=np.float64)
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"Expected matrix to have shape (..., 3, 3), got {m.shape}")
    shape = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    det = np.linalg.det(m)
    if not (det > 0).all():
        i = int(np.flatnonzero(~(det > 0))[0])
        raise ValueError(f"Non-positive determinant (left-handed or null coordinate frame) in rotation matrix {i}: "
                         f"{m[i].tolist()}.")
    gram = m @ np.swapaxes(m, -1, -2)
    # np.isclose(gram, I, atol=1e-12) is |gram - I| <= 1e-12 + 1e-5 |I| (I is finite): the same test
    # without isclose's machinery (about 20 us a call, a third of this function on a skeleton's joints)
    bent = ~(np.abs(gram - _EYE3) <= _ORTHOGONAL_TOL).all(axis=(-2, -1))
    if bent.any():
        u, _, vt = np.linalg.svd(m[bent])
        m = m.copy()
        m[bent] = u @ vt
    # Markley's method: build from the largest of the diagonal and the trace; the four candidates
    # share six sums and differences (each computed once: the same numbers as computed per candidate)
    n = len(m)
    flat = m.reshape(n, 9)
    d0, d1, d2 = flat[:, 0], flat[:, 4], flat[:, 8]
    trace = d0 + d1 + d2
    diagonal = np.empty((n, 4))
    diagonal[:, 0], diagonal[:, 1], diagonal[:, 2], diagonal[:, 3] = d0, d1, d2, trace
    choice = np.argmax(diagonal, axis=-1)
    s01, s02, s12 = flat[:, 3] + flat[:, 1], flat[:, 6] + flat[:, 2], flat[:, 7] + flat[:, 5]
    x, y, z = flat[:, 7] - flat[:, 5], flat[:, 2] - flat[:, 6], flat[:, 3] - flat[:, 1]
    rest = 1 - trace
    cand = np.empty((n, 4, 4))
    c = cand.reshape(n, 16)
    c[:, 0], c[:, 1], c[:, 2], c[:, 3] = rest + 2 * d0, s01, s02, x
    c[:, 4], c[:, 5], c[:, 6], c[:, 7] = s01, rest + 2 * d1, s12, y
    c[:, 8], c[:, 9], c[:, 10], c[:, 11] = s02, s12, rest + 2 * d2, z
    c[:, 12], c[:, 13], c[:, 14], c[:, 15] = x, y, z, 1 + trace
    q = cand[np.arange(n), choice]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q.reshape(shape + (4,))


_TRANSFORMS_KERNEL: list = []


def transforms_kernel():
    """The compiled module of joint transforms (``usdhands.model._transforms_compiled``), or None where it
    was not built or compiled kernels are off; looked up at the first call (not at import)."""
    if not _TRANSFORMS_KERNEL:
        from usdhands.compiled import kernel_module

        _TRANSFORMS_KERNEL.append(kernel_module("model._transforms_compiled"))
    return _TRANSFORMS_KERNEL[0]


_AXIS = {"x": 0, "y": 1, "z": 2}


def _check_order(order: str) -> tuple[list[int], bool]:
    """Axis indices and extrinsic flag of an Euler order: ``"XYZ"`` intrinsic, ``"xyz"`` extrinsic."""
    if not (isinstance(order, str) and len(order) == 3 and re.fullmatch(r"[XYZ]{3}|[xyz]{3}", order)):
        raise ValueError(f"Expected an Euler order of 3 axes from 'XYZ' (intrinsic) or 'xyz' (extrinsic), got {order!r}")
    if order[0] == order[1] or order[1] == order[2]:
        raise ValueError(f"Expected consecutive axes to be different, got {order!r}")
    return [_AXIS[a] for a in order.lower()], order.islower()


def quat_to_euler_deg(q: np.ndarray, order: str = DEFAULT_EULER_ORDER) -> np.ndarray:
    """Euler angles in degrees ``(..., 3)``, each in [-180, 180), from quaternions ``(..., 4)`` xyzw.

    ``order``: upper case intrinsic (``"XYZ"``: about x, then the new y, then the new z),
    lower case extrinsic. In gimbal lock (middle angle 0 or 180° for proper Euler orders,
    ±90° for Tait-Bryan ones) the third angle is 0. The method of Bernardes and Viollet
    (2022), as in scipy.
    """
    q = _unit_quats(check_quat(q))
    axes, extrinsic = _check_order(order)
    i, j, k = axes if extrinsic else axes[::-1]
    symmetric = i == k
    if symmetric:
        k = 3 - i - j
    sign = (i - j) * (j - k) * (k - i) // 2
    qw, qi, qj, qk = q[..., 3], q[..., i], q[..., j], q[..., k]
    if symmetric:
        a, b, c, d = qw, qi, qj, qk * sign
    else:
        a, b, c, d = qw - qj, qi + qk * sign, qj + qw, qk * sign - qi
    half_sum = np.arctan2(b, a)
    half_diff = np.arctan2(d, c)
    middle = 2 * np.arctan2(np.hypot(c, d), np.hypot(a, b))
    eps = 1e-7
    at_zero = np.abs(middle) <= eps
    at_pi = np.abs(middle - np.pi) <= eps
    regular = ~(at_zero | at_pi)
    first, third = (0, 2) if extrinsic else (2, 0)
    out = np.zeros(q.shape[:-1] + (3,))
    out[..., 1] = middle
    # gimbal lock: the whole turn on the first angle of the sequence, 0 on the third
    out[..., 0] = np.where(at_zero, 2 * half_sum, 2 * half_diff * (-1 if extrinsic else 1))
    out[..., first] = np.where(regular, half_sum - half_diff, out[..., first])
    last = np.where(regular, half_sum + half_diff, out[..., third])
    if not symmetric:
        last = last * sign
        out[..., 1] -= np.pi / 2
    out[..., third] = last
    out = np.where(out < -np.pi, out + 2 * np.pi, np.where(out > np.pi, out - 2 * np.pi, out))
    return np.degrees(out)


def euler_deg_to_quat(e: np.ndarray, order: str = DEFAULT_EULER_ORDER) -> np.ndarray:
    """Quaternions ``(..., 4)`` xyzw from Euler angles in degrees ``(..., 3)`` (order as in quat_to_euler_deg)."""
    e = np.asarray(e, dtype=np.float64)
    if e.ndim == 0 or e.shape[-1] != 3:
        raise ValueError(f"Expected euler_deg to have shape (..., 3), got {e.shape}")
    axes, extrinsic = _check_order(order)
    half = np.radians(e) / 2
    out = None
    for n, axis in enumerate(axes):
        elem = np.zeros(e.shape[:-1] + (4,))
        elem[..., axis] = np.sin(half[..., n])
        elem[..., 3] = np.cos(half[..., n])
        if out is None:
            out = elem
        else:  # intrinsic: each turn about the moving axes (right); extrinsic: about the fixed ones (left)
            out = quat_multiply(elem, out) if extrinsic else quat_multiply(out, elem)
    return out


def quat_to_rotvec_deg(q: np.ndarray) -> np.ndarray:
    """Rotation vectors ``(..., 3)``: the axis times the angle in degrees, angle in [0, 180]."""
    q = _unit_quats(check_quat(q))
    x, y, z, w = np.moveaxis(q, -1, 0)
    # scipy's canonical sign: w > 0, or the first non-zero of x, y, z positive when w = 0
    flip = (w < 0) | ((w == 0) & ((x < 0) | ((x == 0) & ((y < 0) | ((y == 0) & (z < 0))))))
    q = np.where(flip[..., None], -q, q)
    x, y, z, w = np.moveaxis(q, -1, 0)
    angle = 2 * np.arctan2(np.sqrt(x * x + y * y + z * z), w)
    small = angle <= 1e-3
    a2 = angle * angle
    safe = np.where(small, 1.0, angle)
    scale = np.where(small, 2 + a2 / 12 + 7 * a2 * a2 / 2880, safe / np.sin(safe / 2))
    return np.degrees(scale[..., None] * q[..., :3])


def quat_angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Geodesic angle between rotations in degrees, shape ``broadcast(...)``, in [0, 180]."""
    a = check_quat(a, "a")
    b = check_quat(b, "b")
    rel = quat_multiply(quat_conjugate(a), b)
    # atan2 keeps precision near 0 where arccos of the dot product loses it
    return np.degrees(2.0 * np.arctan2(np.linalg.norm(rel[..., :3], axis=-1), np.abs(rel[..., 3])))


def trs_to_xform(t: np.ndarray, q: np.ndarray, s: np.ndarray | None = None) -> np.ndarray:
    """Compose ``T @ R @ S`` transforms ``(..., 4, 4)`` for column vectors.

    Parameters
    ----------
    t : (..., 3) float
        Translations, asset units.
    q : (..., 4) float
        Rotations, xyzw.
    s : (..., 3) float, optional
        Scales; ones when omitted.
    """
    t = np.asarray(t, dtype=np.float64)
    r = quat_to_matrix(q)
    shape = np.broadcast_shapes(t.shape[:-1], r.shape[:-2])
    out = np.zeros(shape + (4, 4))
    if s is None:
        out[..., :3, :3] = r
    else:
        out[..., :3, :3] = r * np.asarray(s, dtype=np.float64)[..., None, :]
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def xform_to_trs(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split ``(..., 4, 4)`` transforms into translations, xyzw rotations and scales.

    Assumes no shear. A negative determinant puts the reflection into the x scale.

    Where the compiled twin is built (:mod:`usdhands.compiled`), it splits the transforms whose
    decisions it can take (rotations times scales, mirrored or not, far from singular), with the same
    numbers to the bit; this function's NumPy steps do every other call.
    """
    m = np.asarray(m, dtype=np.float64)
    if m.shape[-2:] != (4, 4):
        raise ValueError(f"Expected xform to have shape (..., 4, 4), got {m.shape}")
    kernel = transforms_kernel()
    if kernel is not None and m.size:
        split = kernel.xform_to_trs(np.ascontiguousarray(m.reshape(-1, 4, 4)))
        if split is not None:
            lead = m.shape[:-2]
            t, q, s = split
            return t.reshape(lead + (3,)), q.reshape(lead + (4,)), s.reshape(lead + (3,))
    return _xform_to_trs(m)


def _xform_to_trs(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`xform_to_trs` in NumPy (``m`` float64 ``(..., 4, 4)``): the reference of the compiled twin."""
    t = m[..., :3, 3].copy()
    basis = m[..., :3, :3]
    s = np.linalg.norm(basis, axis=-2)
    det = np.linalg.det(basis)
    s[..., 0] = np.where(det < 0, -s[..., 0], s[..., 0])
    safe = np.where(np.abs(s) < 1e-12, 1.0, s)
    r = basis / safe[..., None, :]
    q = matrix_to_quat(r)
    return t, q, s


def unwrap_deg(angles: np.ndarray, axis: int = 0) -> np.ndarray:
    """Remove 360° jumps along ``axis`` (time), degrees in, degrees out."""
    return np.degrees(np.unwrap(np.radians(np.asarray(angles, dtype=np.float64)), axis=axis))

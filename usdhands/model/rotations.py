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
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

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
    "quat_angle_deg",
    "quat_canonical",
    "trs_to_xform",
    "xform_to_trs",
    "unwrap_deg",
]

DEFAULT_EULER_ORDER = "XYZ"


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


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` from quaternions ``(..., 4)`` xyzw."""
    q = check_quat(q)
    shape = q.shape[:-1]
    m = Rotation.from_quat(q.reshape(-1, 4)).as_matrix()
    return m.reshape(shape + (3, 3))


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` xyzw from rotation matrices ``(..., 3, 3)``."""
    m = np.asarray(m, dtype=np.float64)
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"Expected matrix to have shape (..., 3, 3), got {m.shape}")
    shape = m.shape[:-2]
    q = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat()
    return q.reshape(shape + (4,))


def quat_to_euler_deg(q: np.ndarray, order: str = DEFAULT_EULER_ORDER) -> np.ndarray:
    """Euler angles in degrees ``(..., 3)`` from quaternions ``(..., 4)`` xyzw."""
    q = check_quat(q)
    shape = q.shape[:-1]
    e = Rotation.from_quat(q.reshape(-1, 4)).as_euler(order, degrees=True)
    return e.reshape(shape + (3,))


def euler_deg_to_quat(e: np.ndarray, order: str = DEFAULT_EULER_ORDER) -> np.ndarray:
    """Quaternions ``(..., 4)`` xyzw from Euler angles in degrees ``(..., 3)``."""
    e = np.asarray(e, dtype=np.float64)
    if e.ndim == 0 or e.shape[-1] != 3:
        raise ValueError(f"Expected euler_deg to have shape (..., 3), got {e.shape}")
    shape = e.shape[:-1]
    q = Rotation.from_euler(order, e.reshape(-1, 3), degrees=True).as_quat()
    return q.reshape(shape + (4,))


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
    """
    m = np.asarray(m, dtype=np.float64)
    if m.shape[-2:] != (4, 4):
        raise ValueError(f"Expected xform to have shape (..., 4, 4), got {m.shape}")
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

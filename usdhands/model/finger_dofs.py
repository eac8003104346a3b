"""Finger DOF curves: the animator's basis.

Each finger joint contributes three curves, the Euler angles in degrees (intrinsic
order :data:`~usdhands.model.rotations.DEFAULT_EULER_ORDER`) of its local rotation
relative to its rest rotation, ``q_local = q_rest * q_rel``, unwrapped over time.
A curve is named ``"<short joint name>.<axis>"`` (``"LeftHandIndex2.y"``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usdhands.model.clip import Clip
from usdhands.model.rotations import (
    DEFAULT_EULER_ORDER, euler_deg_to_quat, quat_conjugate, quat_multiply,
    quat_to_euler_deg, unwrap_deg,
)
from usdhands.model.skeleton import readonly, short_joint_name

__all__ = ["FingerCurves", "finger_curves", "apply_finger_curves"]


@dataclass(frozen=True, eq=False)
class FingerCurves:
    """Euler-angle curves of a set of joints.

    Parameters
    ----------
    joints : tuple of int, length N
        Skeleton indices of the joints, in curve order.
    joint_names : tuple of str, length N
        Their names as in the skeleton.
    values : (T, N*3) float
        Degrees; column ``3*i + a`` is axis ``a`` of joint ``i``.
    order : str
        Intrinsic Euler order, e.g. ``"XYZ"``; axis ``a`` is ``order[a]``.
    """

    joints: tuple[int, ...]
    joint_names: tuple[str, ...]
    values: np.ndarray
    order: str = DEFAULT_EULER_ORDER

    def __post_init__(self) -> None:
        v = np.asarray(self.values, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 3 * len(self.joints):
            raise ValueError(f"Expected values to have shape (T, {3 * len(self.joints)}), got {v.shape}")
        object.__setattr__(self, "values", readonly(v))
        object.__setattr__(self, "joints", tuple(int(j) for j in self.joints))
        object.__setattr__(self, "joint_names", tuple(self.joint_names))

    @property
    def names(self) -> tuple[str, ...]:
        """Curve names ``"<short joint name>.<axis>"``, length N*3."""
        return tuple(f"{short_joint_name(n)}.{a.lower()}" for n in self.joint_names for a in self.order)

    def with_values(self, values: np.ndarray) -> "FingerCurves":
        """The same curves with new values ``(T', N*3)`` degrees."""
        return FingerCurves(self.joints, self.joint_names, values, self.order)


def finger_curves(clip: Clip, joints: list[int] | tuple[int, ...], order: str = DEFAULT_EULER_ORDER) -> FingerCurves:
    """Euler curves of ``joints`` relative to their rest rotations.

    Parameters
    ----------
    clip : Clip
    joints : sequence of int
        Skeleton indices.
    order : str
        Intrinsic Euler order.

    Returns
    -------
    FingerCurves
        ``values`` shape ``(T, 3*len(joints))``, degrees, unwrapped over time.
    """
    joints = [int(j) for j in joints]
    rest = clip.skeleton.rest_rotations[joints]  # (N, 4)
    local = clip.rotations[:, joints]  # (T, N, 4)
    rel = quat_multiply(quat_conjugate(rest)[None], local)
    e = quat_to_euler_deg(rel, order)  # (T, N, 3)
    e = unwrap_deg(e, axis=0)
    T = clip.num_frames
    return FingerCurves(tuple(joints), tuple(clip.skeleton.joint_names[j] for j in joints),
                        e.reshape(T, -1), order)


def apply_finger_curves(clip: Clip, curves: FingerCurves) -> Clip:
    """A copy of ``clip`` whose curve joints take the rotations the curves describe.

    ``curves.values`` must have ``clip.num_frames`` rows.
    """
    T = clip.num_frames
    if curves.values.shape[0] != T:
        raise ValueError(f"Expected curves with {T} frames, got {curves.values.shape[0]}")
    joints = list(curves.joints)
    rest = clip.skeleton.rest_rotations[joints]
    e = curves.values.reshape(T, len(joints), 3)
    rel = euler_deg_to_quat(e, curves.order)
    local = quat_multiply(rest[None], rel)
    return clip.with_joint_rotations(joints, local)

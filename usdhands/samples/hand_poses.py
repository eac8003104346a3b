"""Finger poses of the sample humanoid: relaxed, and the characteristic pose of each gesture type.

A pose is a ``(15, 3)`` array: for each finger joint that carries DOFs (thumb to pinky,
proximal to distal: ``Thumb1, Thumb2, Thumb3, Index1, ..., Pinky3``), Euler angles in
degrees (intrinsic ``"XYZ"``) of its local rotation relative to its rest rotation,
written for the **left** hand. X is flexion (positive curls toward the palm), Z is
abduction (for the left hand's index, positive turns away from the middle finger).
:func:`mirror_pose` gives the right hand's angles: the rig is mirror-symmetric, so a
mirrored pose is ``(x, -y, -z)``.

These are exactly the values :func:`usdhands.model.finger_curves` recovers from a clip
(order ``"XYZ"``), which is why the generated clips serve as finger ground truth.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.optimize import least_squares

from usdhands.model.rotations import euler_deg_to_quat, quat_multiply, trs_to_xform
from usdhands.model.skeleton import Skeleton
from usdhands.samples.humanoid import FINGER_NAMES, humanoid_skeleton

__all__ = [
    "GESTURE_TYPES", "POSE_JOINTS", "relaxed_pose", "gesture_pose", "mirror_pose",
    "fingertip_positions", "solve_thumb", "varied_pose",
]

GESTURE_TYPES = ("attention", "big", "doubt_shrug", "ok", "palm_presentation", "small", "turn", "wipe")

POSE_JOINTS = tuple(f"{f}{k + 1}" for f in FINGER_NAMES for k in range(3))

_MIRROR = np.array([1.0, -1.0, -1.0])


def mirror_pose(pose: np.ndarray) -> np.ndarray:
    """The other hand's angles for a pose ``(..., 15, 3)`` degrees: ``(x, -y, -z)``."""
    return np.asarray(pose, dtype=np.float64) * _MIRROR


def _pose(curl: dict[str, tuple[float, float, float]], spread: dict[str, float],
          thumb: tuple[float, float, float, float, float]) -> np.ndarray:
    """Build a left-hand pose.

    curl : finger -> (proximal, middle, distal) flexion in degrees
    spread : finger -> abduction of the proximal joint away from the middle finger
    thumb : (Thumb1 x, Thumb1 y, Thumb1 z, Thumb2 x, Thumb3 x)
    """
    p = np.zeros((15, 3))
    sign = {"Index": 1.0, "Middle": 0.0, "Ring": -1.0, "Pinky": -1.0}
    for i, f in enumerate(FINGER_NAMES[1:], start=1):
        p[3 * i:3 * i + 3, 0] = curl[f]
        p[3 * i, 2] = sign[f] * spread.get(f, 0.0)
    p[0] = thumb[:3]
    p[1, 0] = thumb[3]
    p[2, 0] = thumb[4]
    return p


def relaxed_pose() -> np.ndarray:
    """The hand hanging relaxed: a light curl growing toward the pinky, ``(15, 3)`` degrees."""
    return _pose({"Index": (14, 20, 10), "Middle": (18, 25, 12), "Ring": (22, 30, 14), "Pinky": (26, 34, 15)},
                 {"Index": 3, "Ring": 3, "Pinky": 6}, (12, 0, 5, 10, 8))


# --------------------------------------------------------------------- kinematics

def fingertip_positions(pose: np.ndarray, skeleton: Skeleton | None = None) -> dict[str, np.ndarray]:
    """Positions of every finger joint of the left hand in the hand's local frame.

    Parameters
    ----------
    pose : (15, 3) float
        Left-hand pose, degrees.

    Returns
    -------
    dict
        ``"Index4"`` etc. (joints 1-4 of each finger) -> ``(3,)`` cm in the frame of
        ``LeftHand``.
    """
    sk = skeleton or humanoid_skeleton()
    pose = np.asarray(pose, dtype=np.float64)
    out = {}
    for fi, f in enumerate(FINGER_NAMES):
        m = np.eye(4)
        for k in range(4):
            j = sk.index(f"LeftHand{f}{k + 1}")
            q = sk.rest_rotations[j]
            if k < 3:
                q = quat_multiply(q, euler_deg_to_quat(pose[3 * fi + k]))
            m = m @ trs_to_xform(sk.rest_translations[j], q)
            out[f"{f}{k + 1}"] = m[:3, 3].copy()
    return out


def solve_thumb(pose: np.ndarray, target: np.ndarray, prior: tuple[float, float, float, float],
                skeleton: Skeleton | None = None) -> np.ndarray:
    """Thumb angles that bring the thumb tip to ``target``.

    Parameters
    ----------
    pose : (15, 3) float
        Left-hand pose; its thumb rows are replaced.
    target : (3,) float
        Point in the hand frame, cm.
    prior : (Thumb1 x, Thumb1 z, Thumb2 x, Thumb3 x) degrees
        Starting point and the pose the solution stays near.

    Returns
    -------
    (15, 3) float
        The pose with the solved thumb.
    """
    sk = skeleton or humanoid_skeleton()
    pose = np.array(pose, dtype=np.float64)
    prior = np.asarray(prior, dtype=np.float64)

    def with_thumb(x):
        p = pose.copy()
        p[0] = (x[0], 0.0, x[1])
        p[1] = (x[2], 0.0, 0.0)
        p[2] = (x[3], 0.0, 0.0)
        return p

    def residual(x):
        tip = fingertip_positions(with_thumb(x), sk)["Thumb4"]
        return np.concatenate([tip - target, 0.02 * (x - prior)])

    sol = least_squares(residual, prior, bounds=([-20, -40, -10, -10], [70, 60, 70, 80]),
                        xtol=1e-8, ftol=1e-8)
    return with_thumb(sol.x)


# --------------------------------------------------------------------- gesture poses

def _ok_pose(index_curl: tuple[float, float, float]) -> np.ndarray:
    p = _pose({"Index": index_curl, "Middle": (8, 10, 5), "Ring": (12, 14, 7), "Pinky": (16, 14, 8)},
              {"Index": 0, "Ring": 5, "Pinky": 10}, (20, 0, 10, 20, 20))
    tips = fingertip_positions(p)
    # thumb pad meets the index pad: aim slightly on the palm side of the index tip
    target = tips["Index4"] + np.array([0.0, 0.0, 0.4])
    return solve_thumb(p, target, (25, 15, 20, 20))


def _attention_pose() -> np.ndarray:
    p = _pose({"Index": (0, 4, 2), "Middle": (85, 95, 55), "Ring": (88, 95, 55), "Pinky": (90, 95, 55)},
              {"Index": 2, "Ring": 2, "Pinky": 4}, (30, 0, -10, 30, 25))
    tips = fingertip_positions(p)
    # thumb lies over the curled middle finger
    target = 0.5 * (tips["Middle2"] + tips["Middle3"]) + np.array([0.0, 0.0, 1.8])
    return solve_thumb(p, target, (35, -10, 30, 25))


def _small_pose() -> np.ndarray:
    p = _pose({"Index": (35, 45, 25), "Middle": (40, 50, 28), "Ring": (45, 52, 28), "Pinky": (48, 55, 30)},
              {"Index": 0, "Ring": 2, "Pinky": 4}, (20, 0, 10, 20, 15))
    tips = fingertip_positions(p)
    # thumb a little short of the index tip: "a small thing"
    target = tips["Index4"] + np.array([-1.5, -1.0, 2.5])
    return solve_thumb(p, target, (20, 15, 20, 15))


@lru_cache(maxsize=None)
def _gesture_poses() -> dict[str, np.ndarray]:
    return {
        "attention": _attention_pose(),
        "big": _pose({"Index": (4, 5, 3), "Middle": (5, 6, 3), "Ring": (7, 8, 4), "Pinky": (9, 8, 4)},
                     {"Index": 10, "Ring": 9, "Pinky": 18}, (0, 0, 25, 5, 5)),
        "doubt_shrug": _pose({"Index": (10, 12, 6), "Middle": (12, 15, 8), "Ring": (15, 18, 9), "Pinky": (18, 20, 10)},
                             {"Index": 12, "Ring": 10, "Pinky": 20}, (5, 0, 28, 8, 8)),
        "ok": _ok_pose((42, 55, 35)),
        "palm_presentation": _pose({"Index": (3, 4, 2), "Middle": (4, 5, 2), "Ring": (6, 6, 3), "Pinky": (8, 6, 3)},
                                   {"Index": 6, "Ring": 5, "Pinky": 10}, (0, 0, 20, 5, 5)),
        "small": _small_pose(),
        "turn": _pose({"Index": (28, 35, 18), "Middle": (32, 40, 20), "Ring": (36, 44, 22), "Pinky": (40, 46, 24)},
                      {"Index": 4, "Ring": 4, "Pinky": 8}, (15, 0, 15, 15, 12)),
        "wipe": _pose({"Index": (2, 2, 1), "Middle": (2, 2, 1), "Ring": (3, 3, 1), "Pinky": (4, 3, 2)},
                      {"Index": -1, "Ring": -1, "Pinky": 0}, (0, 0, -5, 5, 5)),
    }


def gesture_pose(gesture: str) -> np.ndarray:
    """The characteristic left-hand pose ``(15, 3)`` degrees of a gesture type.

    Raises
    ------
    ValueError
        For an unknown type, listing the known ones.
    """
    poses = _gesture_poses()
    if gesture not in poses:
        raise ValueError(f"Unknown gesture type {gesture!r}; expected one of {GESTURE_TYPES}")
    return poses[gesture].copy()


def varied_pose(gesture: str, rng: np.random.Generator, amount: float = 1.0) -> np.ndarray:
    """A take's version of a gesture pose: small random changes of flexion and spread.

    The ok ring stays closed (the thumb is solved again for the varied index);
    the attention index stays straight.
    """
    if gesture == "ok":
        base = np.array([42.0, 55.0, 35.0]) + rng.normal(0, 4.0 * amount, 3)
        p = _ok_pose(tuple(np.clip(base, [25, 35, 20], [60, 75, 50])))
        noise = rng.normal(0, 3.0 * amount, (15, 3)) * [1, 0, 0.5]
        noise[:6] = 0  # thumb and index carry the ring
        return p + noise
    p = gesture_pose(gesture)
    noise = rng.normal(0, 4.0 * amount, (15, 3)) * [1, 0, 0.5]
    if gesture == "attention":
        noise[3:6, 0] = np.abs(noise[3:6, 0]) * 0.5
    if gesture in ("palm_presentation", "wipe", "big", "doubt_shrug"):
        noise[:, 0] = np.abs(noise[:, 0]) * 0.7  # open hands do not hyperextend much
    return p + noise

"""Per-hand arm features: wrist (and elbow, shoulder) position and orientation relative to the root.

Seed 000 compares body motion by "the position and rotation coordinates [of the wrist]
relative to the root (hip) of the character", positions in centimetres and rotations
in degrees. Here, for joint ``j`` at frame ``t``:

- the **body frame** is the root's rotation relative to its rest rotation,
  ``B(t) = R_root(t) · R_root_rest⁻¹`` (identity in the rest pose), so a character
  turning or walking does not change its features;
- the **position** is ``B(t)⁻¹ (p_j(t) − p_root(t))`` in centimetres, expressed in
  the rest pose's axes turned Y-up (Z-up assets are rotated), times a body-size
  ``scale``;
- the **rotation** is the joint's world rotation relative to its own rest world
  rotation, seen from the body frame, ``B(t)⁻¹ R_j(t) R_j_rest⁻¹``, as a rotation
  vector in degrees (axis times angle). The paper uses Euler angles and notes any
  angle representation works; rotation vectors have no order and no gimbal lock and
  their Euclidean distance is close to the geodesic angle for the small differences
  that matter here.

Characters are assumed to face the same way in their rest poses (glTF and Mixamo:
+Z, Y up); "left/right" mirroring flips the X axis of this frame.

The **hand point** is the wrist joint's position, except on rigs without a hand
joint (the fingers hang from the forearm, as on RobotExpressive) where the wrist
joint sits at the elbow: there it is the mean rest position of the finger chains'
first joints, carried by the wrist joint.

**Body size** is the reach: the rest length of the bone chain from the root to the
hand point, in centimetres. Positions of a character are multiplied by
``reference_reach / reach`` to compare with a database recorded on another body.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from usdhands.model.clip import Clip
from usdhands.model.handmap import FINGERS, HandSide
from usdhands.model.skeleton import Skeleton

__all__ = [
    "FEATURE_JOINTS", "hand_point", "reach_cm", "arm_features", "wrist_features",
    "mirror_features", "Z_UP_TO_Y_UP", "world_rotations",
]

#: Joint roles whose features :func:`arm_features` computes.
FEATURE_JOINTS = ("shoulder", "elbow", "wrist")

#: Rotation taking a Z-up frame to Y-up: (x, y, z) → (x, z, −y).
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def _root_index(skeleton: Skeleton, hand: HandSide) -> int:
    if hand.root:
        return skeleton.index(hand.root)
    return int(np.nonzero(skeleton.parents < 0)[0][0])


def _up_matrix(skeleton: Skeleton) -> np.ndarray:
    return Z_UP_TO_Y_UP if skeleton.up_axis == "Z" else np.eye(3)


def hand_point(skeleton: Skeleton, hand: HandSide) -> tuple[int, np.ndarray]:
    """Where the hand is: a joint and an offset in its local rest frame.

    Parameters
    ----------
    skeleton : Skeleton
    hand : HandSide

    Returns
    -------
    joint : int
        The wrist joint's index.
    offset : (3,) float
        Offset of the hand point in the wrist joint's local frame, asset units
        (zero unless the wrist joint sits at the elbow, see the module notes).
    """
    w = skeleton.index(hand.wrist)
    rest = skeleton.rest_world_xforms()
    bases = [skeleton.index(hand.fingers[f][0]) for f in FINGERS[1:] if hand.fingers[f]]
    if not bases or not hand.forearm:
        return w, np.zeros(3)
    e = skeleton.index(hand.forearm)
    pw = rest[w, :3, 3]
    forearm_len = np.linalg.norm(pw - rest[e, :3, 3])
    base_mean = rest[bases, :3, 3].mean(axis=0)
    if forearm_len > 0 and np.linalg.norm(base_mean - pw) <= 0.6 * forearm_len:
        return w, np.zeros(3)
    inv = np.linalg.inv(rest[w])
    return w, (inv @ np.append(base_mean, 1.0))[:3]


def reach_cm(skeleton: Skeleton, hand: HandSide) -> float:
    """Body size: rest length of the bone chain from the root to the hand point, cm."""
    rest = skeleton.rest_world_positions() * skeleton.meters_per_unit * 100.0
    w, offset = hand_point(skeleton, hand)
    root = _root_index(skeleton, hand)
    chain = skeleton.chain_to_root(w)
    total = 0.0
    for a, b in zip(chain[:-1], chain[1:]):
        total += float(np.linalg.norm(rest[a] - rest[b]))
        if b == root:
            break
    xf = skeleton.rest_world_xforms()[w]
    p = (xf @ np.append(offset, 1.0))[:3] * skeleton.meters_per_unit * 100.0
    total += float(np.linalg.norm(p - rest[w]))
    if total <= 0:
        raise ValueError(f"Hand {hand.side!r} of skeleton {skeleton.name!r} has zero reach")
    return total


def world_rotations(xforms: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of transforms ``(..., 4, 4)`` with the scale removed."""
    m = xforms[..., :3, :3]
    return m / np.linalg.norm(m, axis=-2, keepdims=True)


def _rotvec_deg(m: np.ndarray) -> np.ndarray:
    shape = m.shape[:-2]
    r = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_rotvec(degrees=True)
    return r.reshape(shape + (3,))


def arm_features(clip: Clip, hand: HandSide, scale: float = 1.0,
                 joints: tuple[str, ...] = FEATURE_JOINTS, world: np.ndarray | None = None) -> dict:
    """Position and rotation features of the arm joints of one hand.

    Parameters
    ----------
    clip : Clip
    hand : HandSide
    scale : float
        Body-size factor applied to positions (``reference_reach / reach``).
    joints : tuple of {"shoulder", "elbow", "wrist"}
        Which features to compute; a role the hand map leaves empty is skipped.
    world : (T, J, 4, 4) float, optional
        The clip's world transforms when already computed.

    Returns
    -------
    dict of str to (T, 3) float
        ``"<role>_pos"`` in centimetres (scaled) and ``"<role>_rot"`` rotation
        vectors in degrees, for each role present.
    """
    sk = clip.skeleton
    if world is None:
        world = clip.world_xforms()
    rest = sk.rest_world_xforms()
    root = _root_index(sk, hand)
    U = _up_matrix(sk)
    cm = sk.meters_per_unit * 100.0 * float(scale)
    R_root = world_rotations(world[:, root])  # (T,3,3)
    B = R_root @ world_rotations(rest[root]).T  # (T,3,3)
    Binv = np.swapaxes(B, -1, -2)
    p_root = world[:, root, :3, 3]
    out = {}
    roles = {"wrist": hand.wrist, "elbow": hand.forearm, "shoulder": hand.shoulder}
    for role in joints:
        if role not in roles:
            raise ValueError(f"Unknown joint role {role!r}; expected one of {FEATURE_JOINTS}")
        name = roles[role]
        if not name:
            continue
        j = sk.index(name)
        if role == "wrist":
            j, offset = hand_point(sk, hand)
            p = (world[:, j] @ np.append(offset, 1.0))[:, :3]
        else:
            p = world[:, j, :3, 3]
        rel = np.einsum("tij,tj->ti", Binv, p - p_root)
        out[f"{role}_pos"] = (rel @ U.T) * cm
        q = Binv @ world_rotations(world[:, j]) @ world_rotations(rest[j]).T
        out[f"{role}_rot"] = _rotvec_deg(q) @ U.T
    return out


def wrist_features(clip: Clip, hand: HandSide, scale: float = 1.0, world: np.ndarray | None = None) -> np.ndarray:
    """The wrist features of eq. 1: ``(T, 6)`` float, position (cm, scaled) then rotation vector (deg)."""
    f = arm_features(clip, hand, scale, ("wrist",), world)
    return np.concatenate([f["wrist_pos"], f["wrist_rot"]], axis=1)


def mirror_features(features: np.ndarray) -> np.ndarray:
    """Mirror features left↔right (the body frame's X axis flips).

    Parameters
    ----------
    features : (T, 6) float
        Position (cm) then rotation vector (deg).

    Returns
    -------
    (T, 6) float
        Positions ``(−x, y, z)``; rotation vectors, being axial, ``(x, −y, −z)``.
    """
    f = np.array(features, dtype=np.float64)
    if f.ndim != 2 or f.shape[1] != 6:
        raise ValueError(f"Expected features to have shape (T, 6), got {f.shape}")
    f[:, 0] *= -1
    f[:, 4:6] *= -1
    return f

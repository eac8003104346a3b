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
- the **rotation** of the wrist is the orientation of the *hand frame* seen from the
  body frame, relative to a fixed reference orientation ``G`` (the hand hanging down,
  palm towards the body, thumb forward): ``B(t)⁻¹ R_w(t) H G⁻¹``. ``H`` is built in the
  wrist joint's local frame from the local offsets of the finger chains' first joints
  (forward: towards the fingers; side: pinky side to index side; normal: their cross
  product), so it depends on the rig's geometry only, not on its rest rotations or
  joint-axis conventions (a BVH whose zero pose is not the bind pose, a glTF with
  another bone roll still compare). For the elbow and shoulder (used by
  ``evaluate``) it is the joint's world rotation relative to its rest world rotation,
  ``B(t)⁻¹ R_j(t) R_j_rest⁻¹``. A rotation is given by the **nine entries of its
  matrix** (row-major) times ``(180/π)/√2``, "degrees": the paper uses Euler angles
  and notes any angle representation works. Matrix entries never wrap (a rotation
  vector relative to a fixed reference jumps by up to 360° where the hand turns past
  180° from it, which raised hands and guessed hand frames do), have no order and no
  gimbal lock, and the squared Euclidean distance of two of them is
  ``(180/π)² · 2(1 − cos θ)`` for a difference of angle ``θ``: ``θ²`` in degrees² for
  the small differences that matter, growing smoothly to its maximum at 180°.

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

from usdhands.model.clip import Clip
from usdhands.model.handmap import FINGERS, HandSide
from usdhands.model.skeleton import Skeleton

__all__ = [
    "FEATURE_JOINTS", "hand_point", "hand_frame", "guess_hand_frame", "REFERENCE_HAND", "reach_cm", "arm_features", "wrist_features",
    "mirror_features", "Z_UP_TO_Y_UP", "world_rotations", "world_xforms_for", "ROTATION_SCALE",
    "rotation_features", "NUM_WRIST_FEATURES", "WRIST_FEATURE_NAMES",
]

#: Factor from rotation-matrix entries to "degrees": |ΔM|² ≈ θ² (deg²) for small angles θ.
ROTATION_SCALE = float(np.degrees(1.0) / np.sqrt(2.0))

#: Columns of :func:`wrist_features`: position (cm), then the rotation matrix entries.
WRIST_FEATURE_NAMES = ("pos.x", "pos.y", "pos.z") + tuple(f"rot.{a}{b}" for a in "xyz" for b in "xyz")
NUM_WRIST_FEATURES = len(WRIST_FEATURE_NAMES)

#: Joint roles whose features :func:`arm_features` computes.
FEATURE_JOINTS = ("shoulder", "elbow", "wrist")

#: Rotation taking a Z-up frame to Y-up: (x, y, z) → (x, z, −y).
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


#: The reference hand orientation G (columns: forward, side, normal), Y up, facing +Z:
#: hanging down, thumb side forward. The same for both sides (see :func:`hand_frame`).
REFERENCE_HAND = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


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


def hand_frame(skeleton: Skeleton, hand: HandSide) -> np.ndarray:
    """The hand frame ``H`` in the wrist joint's local frame, ``(3, 3)`` rotation (columns forward, side, normal).

    Forward points from the wrist to the mean of the non-thumb fingers' first joints;
    side from the outermost to the innermost non-thumb finger (towards the thumb),
    or from that mean to the thumb where the first joints coincide (RobotExpressive's
    palms); normal = forward × side. Built from local offsets only (rest
    translations, and rest rotations of joints between the wrist and a first joint).
    A hand without fingers gets :func:`guess_hand_frame` (which needs a sensible rest pose).
    """
    w = skeleton.index(hand.wrist)
    local = skeleton.rest_local_xforms()

    def offset(j: int) -> np.ndarray:
        m = np.eye(4)
        while j != w and j >= 0:
            m = local[j] @ m
            j = int(skeleton.parents[j])
        if j != w:
            raise ValueError(f"Finger joint {skeleton.joint_names[j]!r} does not hang from the wrist {hand.wrist!r}")
        return m[:3, 3]

    firsts = {f: offset(skeleton.index(hand.fingers[f][0])) for f in FINGERS if hand.fingers[f]}
    non_thumb = [f for f in FINGERS[1:] if f in firsts]
    if not firsts:  # no fingers: guess from the rest pose, in the wrist's local frame
        rest_rot = world_rotations(skeleton.rest_world_xforms()[w])
        fa = skeleton.index(hand.forearm) if hand.forearm else None
        return rest_rot.T @ guess_hand_frame(skeleton, w, fa)
    mean = np.mean([firsts[f] for f in non_thumb], axis=0) if non_thumb else firsts["thumb"]
    fwd = mean / max(np.linalg.norm(mean), 1e-12)
    side = np.zeros(3)
    if len(non_thumb) >= 2:
        side = firsts[non_thumb[0]] - firsts[non_thumb[-1]]
    if np.linalg.norm(side - fwd * np.dot(side, fwd)) < 1e-3 * np.linalg.norm(mean) and "thumb" in firsts:
        side = firsts["thumb"] - mean
    side = side - fwd * np.dot(side, fwd)
    if np.linalg.norm(side) < 1e-12:
        side = np.cross(fwd, [0.0, 0.0, 1.0]) if abs(fwd[2]) < 0.9 else np.cross(fwd, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    return np.stack([fwd, side, np.cross(fwd, side)], axis=1)


def guess_hand_frame(skeleton: Skeleton, wrist: int, forearm: int | None) -> np.ndarray:
    """A hand frame ``(3, 3)`` in world rest coordinates for a wrist without fingers.

    Forward along the forearm (elbow to wrist), side towards the character's front
    (+Z, Y up: the thumb of a T-pose with palms down), or upwards where the forearm
    points forwards; normal = forward × side. Where the wrist sits on its forearm
    joint (a Leap Motion BVH: ``rHand`` at offset 0 from the root ``rForeArm``),
    forward comes from the next ancestor away from the wrist, else from the wrist
    towards the mean of its children, else it is +X.
    """
    rest = skeleton.rest_world_positions()
    U = Z_UP_TO_Y_UP if skeleton.up_axis == "Z" else np.eye(3)
    span = float(np.ptp(rest, axis=0).max()) if len(rest) > 1 else 0.0
    tiny = 1e-9 * max(span, 1e-300)
    fwd = np.zeros(3)
    parent = forearm if forearm is not None else int(skeleton.parents[wrist])
    while parent is not None and parent >= 0:
        fwd = rest[wrist] - rest[parent]
        if np.linalg.norm(fwd) > tiny:
            break
        parent = int(skeleton.parents[parent])
    if np.linalg.norm(fwd) <= tiny:
        kids = skeleton.children(wrist)
        fwd = rest[kids].mean(axis=0) - rest[wrist] if len(kids) else np.zeros(3)
    if np.linalg.norm(fwd) <= tiny:
        fwd = U.T @ np.array([1.0, 0.0, 0.0])
    fwd = U @ fwd
    fwd /= np.linalg.norm(fwd)
    for guess in ([0.0, 0.0, 1.0], [0.0, 1.0, 0.0]):
        side = np.asarray(guess) - fwd * np.dot(guess, fwd)
        if np.linalg.norm(side) > 0.3:
            break
    side /= np.linalg.norm(side)
    H = np.stack([fwd, side, np.cross(fwd, side)], axis=1)
    return U.T @ H


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


def world_xforms_for(clip: Clip, hands: list[HandSide]) -> np.ndarray:
    """World transforms ``(T, J, 4, 4)`` of only the joints arm features need.

    Forward kinematics runs on the chains from the root to the wrist, elbow and
    shoulder of the given hands; other joints' entries are left zero. Much cheaper
    than :meth:`Clip.world_xforms` on rigs with many finger, face or leg joints.
    The array is a joint-major block seen time-major (``world[:, j]`` is contiguous):
    only the pages of the joints computed are ever written (a 3-minute clip of 65
    joints would otherwise zero and touch 47 MB for a dozen joints).
    """
    sk = clip.skeleton
    need = set()
    for hand in hands:
        for name in (hand.wrist, hand.forearm, hand.shoulder, hand.root):
            if name:
                need.update(sk.chain_to_root(sk.index(name)))
        if not hand.root:
            need.add(_root_index(sk, hand))
    joints = sorted(need)
    T = clip.num_frames
    out = np.zeros((sk.num_joints, T, 4, 4)).transpose(1, 0, 2, 3)
    from usdhands.model.rotations import trs_to_xform

    local = trs_to_xform(clip.translations[:, joints], clip.rotations[:, joints], clip.scales[:, joints])
    for i, j in enumerate(joints):
        p = int(sk.parents[j])
        out[:, j] = local[:, i] if p < 0 else out[:, p] @ local[:, i]
    return out


def world_rotations(xforms: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of transforms ``(..., 4, 4)`` with the scale removed."""
    m = xforms[..., :3, :3]
    return m / np.linalg.norm(m, axis=-2, keepdims=True)


def rotation_features(m: np.ndarray) -> np.ndarray:
    """Wrap-free rotation features ``(..., 9)`` of rotation matrices ``(..., 3, 3)``.

    The matrix entries, row-major, times :data:`ROTATION_SCALE` (see the module notes).
    """
    m = np.asarray(m, dtype=np.float64)
    return m.reshape(m.shape[:-2] + (9,)) * ROTATION_SCALE


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
    dict of str to (T, 3) or (T, 9) float
        ``"<role>_pos"`` ``(T, 3)`` in centimetres (scaled) and ``"<role>_rot"``
        ``(T, 9)`` rotation features (:func:`rotation_features`), for each role present.
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
        if role == "wrist":
            # U turns the Z-up body frame Y-up before comparing with the Y-up reference
            q = U @ Binv @ world_rotations(world[:, j]) @ hand_frame(sk, hand) @ REFERENCE_HAND.T
            out[f"{role}_rot"] = rotation_features(q)
        else:
            q = U @ Binv @ world_rotations(world[:, j]) @ world_rotations(rest[j]).T @ U.T
            out[f"{role}_rot"] = rotation_features(q)
    return out


def wrist_features(clip: Clip, hand: HandSide, scale: float = 1.0, world: np.ndarray | None = None) -> np.ndarray:
    """The wrist features of eq. 1: ``(T, 12)`` float, position (cm, scaled) then the
    rotation features (:func:`rotation_features`, "degrees"), see :data:`WRIST_FEATURE_NAMES`."""
    f = arm_features(clip, hand, scale, ("wrist",), world)
    return np.concatenate([f["wrist_pos"], f["wrist_rot"]], axis=1)


def mirror_features(features: np.ndarray) -> np.ndarray:
    """Mirror features left↔right (the body frame's X axis flips).

    Parameters
    ----------
    features : (T, 12) float
        Position (cm) then rotation matrix entries (:func:`wrist_features`).

    Returns
    -------
    (T, 12) float
        Positions ``(−x, y, z)``; rotations ``M R M`` with ``M = diag(−1, 1, 1)``:
        the entries ``xy, xz, yx, zx`` change sign.
    """
    f = np.array(features, dtype=np.float64)
    if f.ndim != 2 or f.shape[1] != NUM_WRIST_FEATURES:
        raise ValueError(f"Expected features to have shape (T, {NUM_WRIST_FEATURES}), got {f.shape}")
    f[:, 0] *= -1
    f[:, 3 + np.array([1, 2, 3, 6])] *= -1
    return f

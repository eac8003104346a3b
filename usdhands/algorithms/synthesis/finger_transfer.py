"""Finger motion in a rig-independent form, and back onto any rig.

Finger motion is kept as **canonical finger DOF curves**: for each finger joint, its
rotation relative to its rest pose (as in :mod:`usdhands.model.finger_dofs`) but
expressed in an *anatomical frame* built from the rest geometry instead of the
joint's own local axes, which differ from rig to rig:

- x: along the bone (from the joint to the next joint of its finger; for the last
  joint, from its parent to it);
- y: the palm normal ``f × s``, where ``f`` points from the wrist joint to the
  fingers and ``s`` from the outermost to the innermost non-thumb finger (pinky side
  to index side), made orthogonal to x;
- z: ``x × y``.

With ``C = A⁻¹ · W`` (``A`` the anatomical frame, ``W`` the joint's rest world
rotation), the canonical rotation is ``C · q_rel · C⁻¹`` and the curves are its Euler
angles (intrinsic XYZ, degrees, unwrapped over time). Applying them to another rig
inverts this with that rig's ``C``. Rigs that share a rest pose receive the same
finger shapes whatever their joint axes.

**Slots.** Every finger has up to four slots counted from the distal end
(``d0`` distal phalanx, ``d1`` middle, ``d2`` proximal, ``d3`` metacarpal); a chain is
mapped onto the slots by its position from the distal end, so a two-bone finger
gets ``d0`` and ``d1``, and a rig with metacarpals fills ``d3``. Curve columns are
``3 · slot + axis`` with ``slot = 4 · finger + d``.

**Mirroring** left↔right conjugates the canonical rotation by a reflection of the
y axis, which turns Euler angles ``(a, b, c)`` into ``(−a, b, −c)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usdhands.errors import UnsupportedRigError
from usdhands.model.clip import Clip
from usdhands.model.handmap import FINGERS, HandSide
from usdhands.model.rotations import matrix_to_quat, quat_conjugate, quat_multiply, quat_to_euler_deg, unwrap_deg
from usdhands.model.skeleton import Skeleton

__all__ = [
    "SLOTS_PER_FINGER", "NUM_SLOTS", "NUM_DOFS", "slot_names", "dof_names", "HandRig",
    "hand_rig", "canonical_curves", "apply_canonical_curves", "canonical_local_rotations", "mirror_curves",
    "MIRROR_SIGNS", "canonical_to_local", "local_to_canonical",
]

SLOTS_PER_FINGER = 4
NUM_SLOTS = len(FINGERS) * SLOTS_PER_FINGER
NUM_DOFS = 3 * NUM_SLOTS
ORDER = "XYZ"

#: Multiply canonical curves column-wise by this to mirror them (see module notes).
MIRROR_SIGNS = np.tile(np.array([-1.0, 1.0, -1.0]), NUM_SLOTS)


def slot_names() -> list[str]:
    """``"thumb.d0"`` ... ``"pinky.d3"``, length :data:`NUM_SLOTS`."""
    return [f"{f}.d{d}" for f in FINGERS for d in range(SLOTS_PER_FINGER)]


def dof_names() -> list[str]:
    """``"thumb.d0.x"`` ..., length :data:`NUM_DOFS`."""
    return [f"{s}.{a}" for s in slot_names() for a in "xyz"]


@dataclass(frozen=True)
class HandRig:
    """One hand of one skeleton, mapped onto the canonical slots.

    Attributes
    ----------
    side : str
    slot_joint : (NUM_SLOTS,) int
        Skeleton index of the joint in each slot, -1 where the rig has none.
    frame : (NUM_SLOTS, 4) float
        ``C = A⁻¹ W`` per slot, xyzw (identity where empty).
    unmapped : tuple of str
        Finger joints beyond four per finger, which get no motion.
    reference : (NUM_SLOTS, 4) float or None
        Local rotations the curves are relative to (xyzw); the rest rotations when None.
    """

    side: str
    slot_joint: np.ndarray
    frame: np.ndarray
    unmapped: tuple[str, ...] = ()
    reference: np.ndarray | None = None

    def reference_rotations(self, skeleton: Skeleton, slots: np.ndarray) -> np.ndarray:
        """``(len(slots), 4)`` local rotations the curves of ``slots`` are relative to."""
        if self.reference is None:
            return skeleton.rest_rotations[self.slot_joint[slots]]
        return self.reference[slots]

    @property
    def present(self) -> np.ndarray:
        """``(NUM_SLOTS,)`` bool: slots the rig has."""
        return self.slot_joint >= 0

    def dof_mask(self) -> np.ndarray:
        """``(NUM_DOFS,)`` bool: curve columns the rig has."""
        return np.repeat(self.present, 3)


def _unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 1e-9 else fallback


def check_hand_frames(skeleton: Skeleton, hand: HandSide, path=None) -> None:
    """Refuse a hand whose rest joint frames are mirrored (left-handed).

    A negative scale on the wrist, a finger joint or any of their ancestors makes the
    frames reflections, which the anatomical frames of :func:`hand_rig` (rotations)
    cannot express.

    Raises
    ------
    UnsupportedRigError
        Naming the side and the highest joint with a negative scale.
    """
    world = skeleton.rest_world_xforms()
    joints = [skeleton.index(hand.wrist)] + [skeleton.index(j) for f in FINGERS for j in hand.fingers.get(f, ())]
    bad = [j for j in joints if np.linalg.det(world[j, :3, :3]) < 0]
    if not bad:
        return
    scales = np.asarray(skeleton.rest_scales, dtype=np.float64)
    flipped = [a for a in reversed(skeleton.chain_to_root(bad[0])) if np.prod(scales[a]) < 0]
    culprit = skeleton.joint_names[flipped[0] if flipped else bad[0]]
    raise UnsupportedRigError(
        f"the {hand.side} hand's joint frames are mirrored (a negative scale on '{culprit}'); finger motion "
        f"needs right-handed joint frames: freeze the mirror into the rig's rest pose first", path=path)


def hand_rig(skeleton: Skeleton, hand: HandSide, pose: Clip | None = None) -> HandRig:
    """Map a hand's finger chains onto the slots and compute their anatomical frames.

    Parameters
    ----------
    skeleton : Skeleton
    hand : HandSide
    pose : Clip, optional
        A clip whose first frame is the reference pose of the fingers instead of the
        rest pose (the curves are then relative to it): for body-only inputs whose
        frozen fingers hold the rig's natural pose while its rest (a BVH zero pose)
        does not.
    """
    check_hand_frames(skeleton, hand)
    if pose is None:
        rest = skeleton.rest_world_xforms()
    else:
        rest = pose.slice(0, 1).world_xforms()[0]
    pos = rest[:, :3, 3]
    rot = rest[:, :3, :3] / np.linalg.norm(rest[:, :3, :3], axis=-2, keepdims=True)
    w = skeleton.index(hand.wrist)
    chains = {f: [skeleton.index(j) for j in hand.fingers[f]] for f in FINGERS}
    non_thumb = [f for f in FINGERS[1:] if chains[f]]
    centroid = {f: pos[chains[f]].mean(axis=0) for f in FINGERS if chains[f]}
    if non_thumb:
        f_dir = _unit(np.mean([centroid[f] for f in non_thumb], axis=0) - pos[w], np.array([1.0, 0, 0]))
    else:
        f_dir = _unit(centroid.get("thumb", pos[w] + 1) - pos[w], np.array([1.0, 0, 0]))
    if len(non_thumb) >= 2:
        s_dir = centroid[non_thumb[0]] - centroid[non_thumb[-1]]
    elif non_thumb and chains["thumb"]:
        s_dir = centroid["thumb"] - centroid[non_thumb[0]]
    else:
        s_dir = np.array([0.0, 0.0, 1.0])
    normal = _unit(np.cross(f_dir, s_dir), np.array([0.0, 1.0, 0.0]))
    slot_joint = np.full(NUM_SLOTS, -1, dtype=np.int64)
    frame = np.zeros((NUM_SLOTS, 4))
    frame[:, 3] = 1.0
    unmapped = []
    for fi, f in enumerate(FINGERS):
        chain = chains[f]
        for d, j in enumerate(reversed(chain)):
            if d >= SLOTS_PER_FINGER:
                unmapped.append(skeleton.joint_names[j])
                continue
            k = list(chain).index(j)
            if k + 1 < len(chain):
                x = pos[chain[k + 1]] - pos[j]
            else:
                kids = skeleton.children(j)
                x = pos[kids[0]] - pos[j] if kids else pos[j] - pos[int(skeleton.parents[j])]
            x = _unit(x, f_dir)
            y = _unit(normal - x * np.dot(normal, x), _unit(np.cross(x, [0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])))
            z = np.cross(x, y)
            A = np.stack([x, y, z], axis=1)
            C = A.T @ rot[j]
            slot = fi * SLOTS_PER_FINGER + d
            slot_joint[slot] = j
            frame[slot] = matrix_to_quat(C)
    reference = None
    if pose is not None:
        reference = np.zeros((NUM_SLOTS, 4))
        reference[:, 3] = 1.0
        ok = slot_joint >= 0
        reference[ok] = pose.rotations[0, slot_joint[ok]]
    return HandRig(hand.side, slot_joint, frame, tuple(unmapped), reference)


def canonical_curves(clip: Clip, rig: HandRig) -> np.ndarray:
    """Canonical finger DOF curves of a clip.

    Returns
    -------
    (T, NUM_DOFS) float
        Degrees; columns of slots the rig lacks are zero.
    """
    slots = np.nonzero(rig.present)[0]
    return local_to_canonical(clip.skeleton, rig, clip.rotations[:, rig.slot_joint[slots]])


def local_to_canonical(skeleton: Skeleton, rig: HandRig, local: np.ndarray) -> np.ndarray:
    """Canonical curves ``(T, NUM_DOFS)`` degrees from the local rotations ``(T, S, 4)`` xyzw of the
    rig's present slots (in slot order: the joints ``rig.slot_joint[rig.present]``)."""
    local = np.asarray(local, dtype=np.float64)
    T = local.shape[0]
    out = np.zeros((T, NUM_SLOTS, 3))
    slots = np.nonzero(rig.present)[0]
    if len(slots):
        rest = rig.reference_rotations(skeleton, slots)
        rel = quat_multiply(quat_conjugate(rest)[None], local)
        C = rig.frame[slots]
        can = quat_multiply(quat_multiply(C[None], rel), quat_conjugate(C)[None])
        out[:, slots] = unwrap_deg(quat_to_euler_deg(can, ORDER), axis=0)
    return out.reshape(T, NUM_DOFS)


def canonical_to_local(skeleton: Skeleton, rig: HandRig, curves: np.ndarray) -> np.ndarray:
    """Local rotations ``(T, S, 4)`` xyzw of the rig's present slots from canonical curves
    ``(T, NUM_DOFS)`` degrees (the inverse of :func:`local_to_canonical`)."""
    curves = np.asarray(curves, dtype=np.float64)
    T = curves.shape[0]
    slots = np.nonzero(rig.present)[0]
    can = euler_xyz_deg_to_quat(curves.reshape(T, NUM_SLOTS, 3)[:, slots])
    return np.einsum("sij,tsj->tsi", canonical_to_local_matrices(skeleton, rig, slots), can, optimize=True)


def canonical_to_local_matrices(skeleton: Skeleton, rig: HandRig, slots: np.ndarray) -> np.ndarray:
    """Per slot the ``(4, 4)`` matrix ``K`` with ``local = K @ canonical`` (quaternions xyzw), ``(S, 4, 4)``.

    ``local = reference ⊗ C⁻¹ ⊗ canonical ⊗ C`` (``C`` the slot's anatomical frame) with
    the constant factors multiplied out once: ``K = L(reference) L(C⁻¹) R(C)``, where
    ``L(a) b = a ⊗ b`` and ``R(c) b = b ⊗ c``. Equal to the three Hamilton products to
    rounding (``tests/test_finger_transfer_fast.py``), and one small matrix product per
    frame and joint instead of three.
    """
    C = rig.frame[slots]
    return _left_matrices(rig.reference_rotations(skeleton, slots)) @ _left_matrices(quat_conjugate(C)) @ \
        _right_matrices(C)


def _left_matrices(a: np.ndarray) -> np.ndarray:
    """``(..., 4, 4)`` matrices ``L(a)`` with ``L(a) @ b = a ⊗ b`` (Hamilton product, xyzw)."""
    x, y, z, w = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    return np.stack([np.stack([w, -z, y, x], -1), np.stack([z, w, -x, y], -1),
                     np.stack([-y, x, w, z], -1), np.stack([-x, -y, -z, w], -1)], -2)


def _right_matrices(c: np.ndarray) -> np.ndarray:
    """``(..., 4, 4)`` matrices ``R(c)`` with ``R(c) @ b = b ⊗ c`` (Hamilton product, xyzw)."""
    x, y, z, w = np.moveaxis(np.asarray(c, dtype=np.float64), -1, 0)
    return np.stack([np.stack([w, z, -y, x], -1), np.stack([-z, w, x, y], -1),
                     np.stack([y, -x, w, z], -1), np.stack([-x, -y, -z, w], -1)], -2)


def apply_canonical_curves(clip: Clip, rig: HandRig, curves: np.ndarray) -> Clip:
    """A copy of ``clip`` whose finger joints follow canonical curves ``(T, NUM_DOFS)`` degrees."""
    joints, local = canonical_local_rotations(clip, rig, curves)
    return clip.with_joint_rotations(joints, local) if joints else clip


def canonical_local_rotations(clip: Clip, rig: HandRig, curves: np.ndarray) -> tuple[list[int], np.ndarray]:
    """The finger joints of ``rig`` and their local rotations ``(T, n, 4)`` for canonical curves ``(T, NUM_DOFS)``.

    What :func:`apply_canonical_curves` writes into the clip (a caller with both hands
    writes them at once: one copy of the clip's arrays instead of two).
    """
    curves = np.asarray(curves, dtype=np.float64)
    T = clip.num_frames
    if curves.shape != (T, NUM_DOFS):
        raise ValueError(f"Expected curves to have shape ({T}, {NUM_DOFS}), got {curves.shape}")
    slots = np.nonzero(rig.present)[0]
    if not len(slots):
        return [], np.zeros((T, 0, 4))
    joints = rig.slot_joint[slots]
    return [int(j) for j in joints], canonical_to_local(clip.skeleton, rig, curves)


def euler_xyz_deg_to_quat(e: np.ndarray) -> np.ndarray:
    """Intrinsic XYZ Euler angles in degrees ``(..., 3)`` to quaternions ``(..., 4)`` xyzw.

    The same as ``euler_deg_to_quat(e, "XYZ")`` (``q = qx ⊗ qy ⊗ qz``), in plain NumPy
    (several times faster than going through scipy for large batches).
    """
    h = np.radians(np.asarray(e, dtype=np.float64)) / 2
    cx, cy, cz = np.cos(h[..., 0]), np.cos(h[..., 1]), np.cos(h[..., 2])
    sx, sy, sz = np.sin(h[..., 0]), np.sin(h[..., 1]), np.sin(h[..., 2])
    return np.stack([
        sx * cy * cz + cx * sy * sz,
        cx * sy * cz - sx * cy * sz,
        cx * cy * sz + sx * sy * cz,
        cx * cy * cz - sx * sy * sz,
    ], axis=-1)


def mirror_curves(curves: np.ndarray) -> np.ndarray:
    """Canonical curves ``(T, NUM_DOFS)`` of the other hand doing the mirrored motion."""
    curves = np.asarray(curves, dtype=np.float64)
    if curves.ndim != 2 or curves.shape[1] != NUM_DOFS:
        raise ValueError(f"Expected curves to have shape (T, {NUM_DOFS}), got {curves.shape}")
    return curves * MIRROR_SIGNS

"""Markers and rig axes for splicing (Majkowska et al. 2006, section 3.1).

Wrist, hand and forearm markers from joints at fixed offsets (:class:`MarkerOffsets`),
positions in centimetres with Y up, the trunk's heading for the eq. 7 alternative, and
the hands' rest axes that finger transfer between rigs goes through. Used by
:mod:`usdhands.algorithms.splicing.splice`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from usdhands.jit import njit
from usdhands.model.clip import Clip
from usdhands.model.handmap import FINGERS, HandSide
from usdhands.model.rotations import matrix_to_quat

# -- markers ------------------------------------------------------------------------
@dataclass(frozen=True)
class MarkerOffsets:
    """Where the four markers sit, as points in joints' local frames (asset units).

    Parameters
    ----------
    wrist_a, wrist_b : (3,) float
        The two wrist markers ``p1, p2`` in the wrist joint's frame.
    forearm : (3,) float
        The forearm marker ``p3`` in the forearm joint's frame.
    hand : (3,) float
        The hand marker ``p4`` in the wrist joint's frame.
    """

    wrist_a: tuple
    wrist_b: tuple
    forearm: tuple
    hand: tuple

    def as_array(self) -> np.ndarray:
        """``(4, 3)`` float: p1, p2, p3, p4."""
        return np.array([self.wrist_a, self.wrist_b, self.forearm, self.hand], dtype=np.float64)


def _first_base(skeleton, chain: Sequence[str]) -> int | None:
    """The knuckle of a finger chain: its first joint, or the second after a metacarpal."""
    if not chain:
        return None
    names = [skeleton.index(n) for n in chain]
    if len(names) >= 4 or "metacarpal" in chain[0].lower():
        return names[1] if len(names) > 1 else names[0]
    return names[0]


def _hand_rest_axes(skeleton, side: HandSide, rest: np.ndarray):
    """Wrist and knuckle rest positions, unit vectors along and across the hand, hand length."""
    pos = rest[:, :3, 3]
    knuckles = {f: _first_base(skeleton, side.fingers[f]) for f in FINGERS}
    hand_j = next((knuckles[f] for f in ("middle", "index", "ring", "pinky") if knuckles[f] is not None), None)
    if hand_j is None:
        raise ValueError(f"hand {side.side!r} has no finger joints to place the hand marker on")
    W = pos[skeleton.index(side.wrist)]
    H = pos[hand_j]
    length = float(np.linalg.norm(H - W))
    if length < 1e-9:
        raise ValueError(f"hand {side.side!r}: the knuckle {skeleton.joint_names[hand_j]!r} sits on the wrist")
    along = (H - W) / length
    a = next((knuckles[f] for f in ("index", "thumb", "middle") if knuckles[f] is not None and knuckles[f] != hand_j),
             None)
    b = next((knuckles[f] for f in ("pinky", "ring") if knuckles[f] is not None and knuckles[f] != hand_j), None)
    across = None
    if a is not None and b is not None:
        across = pos[a] - pos[b]
    elif a is not None:
        across = pos[a] - H
    elif b is not None:
        across = H - pos[b]
    if across is not None:
        across = across - along * np.dot(across, along)
    if across is None or np.linalg.norm(across) < 1e-9 * length:
        helper = np.array([0.0, 1.0, 0.0]) if abs(along[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        across = np.cross(along, helper)
    across = across / np.linalg.norm(across)
    return W, H, along, across, length


def hand_rest_basis(skeleton, side: HandSide) -> np.ndarray:
    """Rotation ``(3, 3)`` whose columns are the hand's rest axes in the rig's world frame.

    Columns: along the hand (wrist → middle knuckle), across it (pinky → index
    knuckle, made perpendicular), and their cross product.
    """
    _, _, along, across, _ = _hand_rest_axes(skeleton, side, skeleton.rest_world_xforms())
    return np.stack([along, across, np.cross(along, across)], axis=1)


def transfer_axes(body_skeleton, body_side: HandSide, hand_skeleton, hand_side: HandSide,
                  pairs: Sequence[tuple[str, str]]) -> np.ndarray:
    """Per pair the quaternion ``c`` (xyzw, ``(k, 4)``) with ``r_body = c · r_hand · c⁻¹``.

    ``r`` is a joint's rotation relative to its rest in its own rest frame. ``c`` maps the
    hand rig's joint frame at rest into the body rig's through the two hands' rest axes
    (:func:`hand_rest_basis`), so rigs with other joint axis conventions, or other rest
    orientations of the hand, exchange the same finger motion.
    """
    M = hand_rest_basis(body_skeleton, body_side) @ hand_rest_basis(hand_skeleton, hand_side).T
    gb = body_skeleton.rest_world_xforms()[[body_skeleton.index(b) for b, _ in pairs], :3, :3]
    gh = hand_skeleton.rest_world_xforms()[[hand_skeleton.index(h) for _, h in pairs], :3, :3]
    c = np.swapaxes(_rot_only(gb), -1, -2) @ M @ _rot_only(gh)
    return matrix_to_quat(c)


def _angle_between(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na < 1e-12 or nb < 1e-12:
        return 0.0
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b) / (na * nb), -1.0, 1.0))))


def choose_transfer(body_skeleton, hand_skeleton, pairs: Sequence[tuple[str, str]], tolerance_deg: float = 10.0) -> str:
    """How to carry finger rotations between two rigs: ``"local"``, ``"copy"`` or ``"hand"``.

    The joint frames of a pair coincide when the joint's rest offset (in its parent's
    frame) and its first child's rest offset (in its own frame) point the same way in
    both rigs, within ``tolerance_deg``. When every pair's frames coincide, the same
    local rotation is the same pose in both rigs: ``"local"`` when the rest rotations
    agree too (then it equals ``"copy"``), ``"copy"`` otherwise. Otherwise the rigs
    use other joint axes: ``"hand"``.
    """
    same_frames = same_rest = True
    for b, h in pairs:
        jb, jh = body_skeleton.index(b), hand_skeleton.index(h)
        if _angle_between(body_skeleton.rest_translations[jb], hand_skeleton.rest_translations[jh]) > tolerance_deg:
            same_frames = False
        cb, ch = body_skeleton.children(jb), hand_skeleton.children(jh)
        if cb and ch and _angle_between(body_skeleton.rest_translations[cb[0]],
                                        hand_skeleton.rest_translations[ch[0]]) > tolerance_deg:
            same_frames = False
        rb, rh = body_skeleton.rest_rotations[jb], hand_skeleton.rest_rotations[jh]
        if np.degrees(2 * np.arccos(min(abs(float(np.dot(rb, rh))), 1.0))) > tolerance_deg:
            same_rest = False
    if not same_frames:
        return "hand"
    return "local" if same_rest else "copy"


def default_marker_offsets(skeleton, side: HandSide, *, wrist_width: float = 0.25,
                           forearm_distance: float = 1.0) -> MarkerOffsets:
    """Marker offsets derived from the rest pose.

    The hand marker sits on the middle knuckle (the first finger found of middle,
    index, ring, pinky); the wrist markers sit ``± wrist_width`` hand lengths from the
    wrist across the palm (the line from the pinky to the index knuckle, or to the
    thumb); the forearm marker sits ``forearm_distance`` hand lengths from the wrist
    towards the elbow (away from the hand when the forearm joint is at the wrist,
    as in hand-only captures). A hand length is the rest distance wrist to knuckle.

    Raises
    ------
    ValueError
        The side has no forearm, or no finger to place the hand marker on.
    """
    if side.forearm is None:
        raise ValueError(f"hand {side.side!r} has no forearm joint; markers need one")
    rest = skeleton.rest_world_xforms()
    w = skeleton.index(side.wrist)
    fa = skeleton.index(side.forearm)
    pos = rest[:, :3, 3]
    W, H, along, across, length = _hand_rest_axes(skeleton, side, rest)
    to_elbow = pos[fa] - W
    if np.linalg.norm(to_elbow) > 0.1 * length:
        to_elbow = to_elbow / np.linalg.norm(to_elbow)
    else:
        to_elbow = -along
    p = np.array([W + across * wrist_width * length, W - across * wrist_width * length,
                  W + to_elbow * forearm_distance * length, H])
    inv_w = np.linalg.inv(rest[w])
    inv_f = np.linalg.inv(rest[fa])
    loc = lambda M, x: (M @ np.append(x, 1.0))[:3]
    return MarkerOffsets(tuple(loc(inv_w, p[0])), tuple(loc(inv_w, p[1])), tuple(loc(inv_f, p[2])),
                         tuple(loc(inv_w, p[3])))


def _to_yup_cm(points: np.ndarray, skeleton) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64) * (skeleton.meters_per_unit * 100.0)
    if skeleton.up_axis == "Z":
        p = np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)
    return p


def yup_cm_positions(clip: Clip, joints: Sequence[int], world: np.ndarray | None = None) -> np.ndarray:
    """World positions ``(T, len(joints), 3)`` of joints in centimetres with Y up."""
    world = clip.world_xforms() if world is None else world
    return _to_yup_cm(world[:, list(joints)][:, :, :3, 3], clip.skeleton)


def markers_from_joints(clip: Clip, side: HandSide, offsets: MarkerOffsets | None = None,
                        world: np.ndarray | None = None) -> np.ndarray:
    """The four markers of one hand per frame.

    Parameters
    ----------
    clip : Clip
    side : HandSide
        Needs ``wrist`` and ``forearm``.
    offsets : MarkerOffsets, optional
        :func:`default_marker_offsets` when omitted.
    world : (T, J, 4, 4) float, optional
        ``clip.world_xforms()`` when already computed.

    Returns
    -------
    (T, 4, 3) float
        p1, p2 (wrist), p3 (forearm), p4 (hand), centimetres, Y up.
    """
    sk = clip.skeleton
    offsets = default_marker_offsets(sk, side) if offsets is None else offsets
    world = clip.world_xforms() if world is None else world
    return markers_from_xforms(world[:, sk.index(side.wrist)], world[:, sk.index(side.forearm)], offsets, sk)


def markers_from_xforms(wrist: np.ndarray, forearm: np.ndarray, offsets: MarkerOffsets, skeleton) -> np.ndarray:
    """:func:`markers_from_joints` from the wrist's and the forearm's world transforms, two ``(T, 4, 4)``.

    Compiled; the same bits as ``np.einsum("tkab,kb->tka", frames, offsets)`` on the frames
    ``(wrist, wrist, forearm, wrist)`` (its sum over ``b`` runs left to right from 0; a test
    holds the two together).
    """
    off = np.concatenate([offsets.as_array(), np.ones((4, 1))], axis=1)  # (4, 4)
    pts = np.empty((wrist.shape[0], 4, 3))
    _markers_kernel(np.ascontiguousarray(wrist, dtype=np.float64), np.ascontiguousarray(forearm, dtype=np.float64),
                    off, pts)
    return _to_yup_cm(pts, skeleton)


@njit(cache=True)
def _markers_kernel(wrist, forearm, off, out):  # pragma: no cover - compiled
    for t in range(wrist.shape[0]):
        for k in range(4):
            frame = forearm[t] if k == 2 else wrist[t]
            for a in range(3):
                s = 0.0
                for b in range(4):
                    s += frame[a, b] * off[k, b]
                out[t, k, a] = s


def trunk_yaw_deg(clip: Clip, joint: int, world: np.ndarray | None = None) -> np.ndarray:
    """Heading of a joint (the hips) about the vertical axis relative to its rest, ``(T,)`` degrees."""
    world = clip.world_xforms() if world is None else world
    return trunk_yaw_from_xforms(world[:, joint], clip.skeleton, joint)


def trunk_yaw_from_xforms(xforms: np.ndarray, skeleton, joint: int) -> np.ndarray:
    """:func:`trunk_yaw_deg` from the joint's world transforms ``(T, 4, 4)``."""
    sk = skeleton
    R = xforms[:, :3, :3]
    R = R / np.linalg.norm(R, axis=-2, keepdims=True)
    rest = sk.rest_world_xforms()[joint, :3, :3]
    rest = rest / np.linalg.norm(rest, axis=-2, keepdims=True)
    rel = R @ rest.T  # world-space rotation from the rest heading
    if sk.up_axis == "Z":
        fwd = rel[:, :, 1]  # any horizontal axis works: (x, y) plane for Z up
        return np.degrees(np.unwrap(np.arctan2(-fwd[:, 0], fwd[:, 1])))
    fwd = rel[:, :, 2]
    return np.degrees(np.unwrap(np.arctan2(fwd[:, 0], fwd[:, 2])))



def _rot_only(m: np.ndarray) -> np.ndarray:
    return m / np.maximum(np.linalg.norm(m, axis=-2, keepdims=True), 1e-12)

"""Splicing a separately captured hand performance onto a body performance.

Majkowska, Zordan and Faloutsos 2006, *Automatic splicing for hand and body
animations* (sections 3 and 4). For each hand:

1. **Markers** (:func:`markers_from_joints`): two wrist markers ``p1, p2``, a forearm
   marker ``p3`` and a hand marker ``p4`` per frame, from joints at fixed offsets in
   the wrist's and the forearm's local frames (:class:`MarkerOffsets`), or real
   marker positions given as arrays. Centimetres, Y up.
2. **First pass** (phase matching): the shoulder is subtracted from the markers, the
   hand clip is turned about the vertical axis onto the body (eq. 7, windows of 5
   frames, or the trunk angles), and DTW in the band of eq. 3 (30 % of the body
   length), bent through the user's constraints (eq. 4–5), minimises the distance of
   eq. 6: how many signs of the first and second derivatives of the markers differ.
3. **Second pass** (within phases): DTW in a narrower band (10 %) around the first
   path, still through the constraints, over the angle between the hand vectors once
   the forearms are aligned (eq. 8–9), in degrees. By default the forearms are aligned
   as joint frames (:func:`hand_directions`); ``forearm_align="vector"`` is the paper's
   minimal rotation between the markers' forearm vectors.
4. **Merge**: a body frame matched to several hand frames takes their median
   (a fractional frame, sampled by slerp); where the hand frame jumps ahead, the
   finger motion is cross-faded over a window (:func:`transfer_fingers`).

Finger rotations are transferred relative to each skeleton's rest pose:
``q_body = rest_body * (rest_hand⁻¹ * q_hand)`` when both rigs' finger joints share
their axis conventions and rest rotations, as they are when only the declared rest
rotations differ (a glTF character and its BVH export), otherwise through the hands'
rest axes (:func:`transfer_axes`); ``SpliceOptions.transfer`` chooses
(:func:`choose_transfer`). Finger joints are paired
finger by finger from the distal end of each chain, so a chain with a metacarpal
pairs with one without.

A hand clip without a shoulder joint (a hand-only capture such as a Leap Motion
BVH rooted at the forearm) is used without subtraction: the capture's trunk is
assumed still, as in the paper's hand sessions, and the signs of derivatives do not
change when a constant is subtracted (eq. 7 fits the horizontal translation too).
Subtracting the forearm instead would erase the arm motion the first pass relies on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from numba import njit
from scipy.signal import savgol_filter

from usdhands.algorithms.dtw import Band, Constraint, WarpResult, check_constraints, dtw
from usdhands.model.clip import Clip
from usdhands.model.handmap import FINGERS, HandSide
from usdhands.model.rotations import matrix_to_quat, quat_conjugate, quat_multiply, quat_slerp, trs_to_xform

__all__ = [
    "MarkerOffsets", "SpliceOptions", "SideAlignment", "FingerTransfer",
    "FirstPassInput", "default_marker_offsets", "markers_from_joints", "yup_cm_positions", "trunk_yaw_deg",
    "sign_features", "first_pass_cost", "first_pass_cost_naive", "hand_angle_cost",
    "hand_angle_cost_naive", "window_yaw_naive", "align_hands", "median_alignment",
    "phase_boundaries", "pair_finger_joints", "transfer_fingers", "forearm_hand_vectors",
    "SpliceResult", "splice_clips", "partial_world_xforms", "hand_rest_basis", "transfer_axes", "choose_transfer",
    "hand_directions", "direction_angle_cost", "fit_rotation", "forearm_rest_basis",
]


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
    return _to_yup_cm(world[:, list(joints), :3, 3], clip.skeleton)


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
    w = sk.index(side.wrist)
    fa = sk.index(side.forearm)
    off = np.concatenate([offsets.as_array(), np.ones((4, 1))], axis=1)  # (4, 4)
    frames = np.stack([world[:, w], world[:, w], world[:, fa], world[:, w]], axis=1)  # (T, 4, 4, 4)
    pts = np.einsum("tkab,kb->tka", frames, off)[..., :3]
    return _to_yup_cm(pts, sk)


def trunk_yaw_deg(clip: Clip, joint: int, world: np.ndarray | None = None) -> np.ndarray:
    """Heading of a joint (the hips) about the vertical axis relative to its rest, ``(T,)`` degrees."""
    sk = clip.skeleton
    world = clip.world_xforms() if world is None else world
    R = world[:, joint, :3, :3]
    R = R / np.linalg.norm(R, axis=-2, keepdims=True)
    rest = sk.rest_world_xforms()[joint, :3, :3]
    rest = rest / np.linalg.norm(rest, axis=-2, keepdims=True)
    rel = R @ rest.T  # world-space rotation from the rest heading
    if sk.up_axis == "Z":
        fwd = rel[:, :, 1]  # any horizontal axis works: (x, y) plane for Z up
        return np.degrees(np.unwrap(np.arctan2(-fwd[:, 0], fwd[:, 1])))
    fwd = rel[:, :, 2]
    return np.degrees(np.unwrap(np.arctan2(fwd[:, 0], fwd[:, 2])))


# -- first pass: signs of derivatives (eq. 6, 7) ----------------------------------------
def _smooth_window(T: int, window: int) -> int:
    w = min(window, T if T % 2 else T - 1)
    return w


def sign_features(markers: np.ndarray, fps: float, *, window: int = 7,
                  dead_zone: float = 0.05) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Smoothed first and second derivatives of markers and their dead zones.

    Parameters
    ----------
    markers : (T, K, 3) float
        Positions, centimetres.
    fps : float
        Frames per second.
    window : int
        Savitzky–Golay window in frames (odd; cubic fit), against noise.
    dead_zone : float
        A derivative component smaller than this fraction of the clip's RMS derivative
        counts as zero (sign 0), so holds (``v = 0``) are seen as holds.

    Returns
    -------
    vel : (T, K, 3) float
        cm/s.
    acc : (T, K, 3) float
        cm/s².
    eps_v, eps_a : float
        The dead zones in cm/s and cm/s².
    """
    x = np.asarray(markers, dtype=np.float64)
    T = x.shape[0]
    if T < 3:
        raise ValueError(f"Expected at least 3 frames, got {T}")
    w = _smooth_window(T, window)
    if w >= 5:
        vel = savgol_filter(x, w, 3, deriv=1, delta=1.0 / fps, axis=0, mode="interp")
        acc = savgol_filter(x, w, 3, deriv=2, delta=1.0 / fps, axis=0, mode="interp")
    else:
        vel = np.gradient(x, 1.0 / fps, axis=0)
        acc = np.gradient(vel, 1.0 / fps, axis=0)
    eps_v = dead_zone * float(np.sqrt(np.mean(vel ** 2)))
    eps_a = dead_zone * float(np.sqrt(np.mean(acc ** 2)))
    return vel, acc, eps_v, eps_a


@njit(cache=True)
def _sgn(x, eps):  # pragma: no cover - compiled
    if x > eps:
        return 1.0
    if x < -eps:
        return -1.0
    return 0.0


@njit(cache=True)
def _window_cos_sin(X, Z, Xh, Zh, SX, SZ, SXh, SZh, i, j, half):  # pragma: no cover - compiled
    """cos and sin of eq. 7's angle (num and den normalised, no atan2).

    ``X, Z`` ``(n, K)`` are the body markers' horizontal coordinates, ``SX, SZ`` ``(n,)``
    their sums over the markers; ``Xh, Zh, SXh, SZh`` the same for the hand.
    """
    n = X.shape[0]
    m = Xh.shape[0]
    K = X.shape[1]
    sxz = 0.0
    sxx = 0.0
    bx = 0.0
    bz = 0.0
    hx = 0.0
    hz = 0.0
    cnt = 0
    for k in range(-half, half + 1):
        a = i + k
        b = j + k
        if a < 0 or b < 0 or a >= n or b >= m:
            continue
        for mk in range(K):
            sxz += X[a, mk] * Zh[b, mk] - Xh[b, mk] * Z[a, mk]
            sxx += X[a, mk] * Xh[b, mk] + Z[a, mk] * Zh[b, mk]
        bx += SX[a]
        bz += SZ[a]
        hx += SXh[b]
        hz += SZh[b]
        cnt += K
    num = sxz - (bx * hz - hx * bz) / cnt
    den = sxx - (bx * hx + bz * hz) / cnt
    r = np.sqrt(num * num + den * den)
    if r == 0.0:
        return 1.0, 0.0  # atan2(0, 0) = 0
    return den / r, num / r


@njit(cache=True)
def _first_pass_kernel(rows, cols, P, Q, vb, ab, vh, ah, eps_vb, eps_ab, eps_vh, eps_ah,
                       half, use_trunk, yaw_b, yaw_h):  # pragma: no cover - compiled
    N = rows.shape[0]
    K = P.shape[1]
    out = np.empty(N)
    X = np.ascontiguousarray(P[:, :, 0])
    Z = np.ascontiguousarray(P[:, :, 2])
    Xh = np.ascontiguousarray(Q[:, :, 0])
    Zh = np.ascontiguousarray(Q[:, :, 2])
    SX = X.sum(axis=1)
    SZ = Z.sum(axis=1)
    SXh = Xh.sum(axis=1)
    SZh = Zh.sum(axis=1)
    n = vb.shape[0]
    m = vh.shape[0]
    SB = np.empty((n, K, 6))  # body signs: v then a, x y z
    for i in range(n):
        for mk in range(K):
            for ax in range(3):
                SB[i, mk, ax] = _sgn(vb[i, mk, ax], eps_vb)
                SB[i, mk, 3 + ax] = _sgn(ab[i, mk, ax], eps_ab)
    SH = np.empty((m, K, 2))  # hand signs of the vertical components
    for j in range(m):
        for mk in range(K):
            SH[j, mk, 0] = _sgn(vh[j, mk, 1], eps_vh)
            SH[j, mk, 1] = _sgn(ah[j, mk, 1], eps_ah)
    for c in range(N):
        i = rows[c]
        j = cols[c]
        if use_trunk:
            th = yaw_b[i] - yaw_h[j]
            co = np.cos(th)
            si = np.sin(th)
        else:
            co, si = _window_cos_sin(X, Z, Xh, Zh, SX, SZ, SXh, SZh, i, j, half)
        d = 0.0
        for mk in range(K):
            # R_y(θ) applied to the hand's derivatives: x' = c x + s z, z' = -s x + c z
            x = vh[j, mk, 0]
            z = vh[j, mk, 2]
            e = SB[i, mk, 0] - _sgn(co * x + si * z, eps_vh)
            d += e * e
            e = SB[i, mk, 2] - _sgn(-si * x + co * z, eps_vh)
            d += e * e
            x = ah[j, mk, 0]
            z = ah[j, mk, 2]
            e = SB[i, mk, 3] - _sgn(co * x + si * z, eps_ah)
            d += e * e
            e = SB[i, mk, 5] - _sgn(-si * x + co * z, eps_ah)
            d += e * e
            e = SB[i, mk, 1] - SH[j, mk, 0]  # vertical components do not turn
            d += e * e
            e = SB[i, mk, 4] - SH[j, mk, 1]
            d += e * e
        out[c] = d
    return out


@dataclass(frozen=True)
class FirstPassInput:
    """What eq. 6 and 7 need of both clips (built by :func:`align_hands`).

    Parameters
    ----------
    P, Q : (n, K, 3), (m, K, 3) float
        Body and hand markers, shoulder subtracted, cm, Y up.
    vb, ab, vh, ah : (n, K, 3), (n, K, 3), (m, K, 3), (m, K, 3) float
        Their first (cm/s) and second (cm/s²) derivatives.
    eps : (4,) float
        Dead zones of vb, ab, vh, ah.
    half : int
        Half-width of eq. 7's window in frames (2 for 5 frames).
    yaw_b, yaw_h : (n,), (m,) float or None
        Trunk headings in degrees; None to use eq. 7.
    """

    P: np.ndarray
    Q: np.ndarray
    vb: np.ndarray
    ab: np.ndarray
    vh: np.ndarray
    ah: np.ndarray
    eps: tuple
    half: int
    yaw_b: np.ndarray | None
    yaw_h: np.ndarray | None


def first_pass_cost(inp: FirstPassInput, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Eq. 6 on the given cells (numba); see :func:`first_pass_cost_naive` for the definition."""
    use_trunk = inp.yaw_b is not None
    yb = np.radians(inp.yaw_b) if use_trunk else np.zeros(1)
    yh = np.radians(inp.yaw_h) if use_trunk else np.zeros(1)
    return _first_pass_kernel(np.ascontiguousarray(rows, np.int64), np.ascontiguousarray(cols, np.int64),
                              inp.P, inp.Q, inp.vb, inp.ab, inp.vh, inp.ah, *inp.eps, inp.half,
                              use_trunk, yb, yh)


def window_yaw_naive(P: np.ndarray, Q: np.ndarray, i: int, j: int, half: int = 2) -> float:
    """Eq. 7 for one pair of frames in NumPy: the rotation about Y (radians) taking Q's window onto P's.

    Parameters
    ----------
    P : (n, K, 3) float
        Body markers, Y up.
    Q : (m, K, 3) float
        Hand markers, Y up.
    i, j : int
        Frames; the window holds frames ``i + k, j + k`` for ``|k| <= half`` inside both clips.
    """
    ks = [k for k in range(-half, half + 1) if 0 <= i + k < len(P) and 0 <= j + k < len(Q)]
    a = P[[i + k for k in ks]].reshape(-1, 3)
    b = Q[[j + k for k in ks]].reshape(-1, 3)
    n = len(a)
    x, z, xp, zp = a[:, 0], a[:, 2], b[:, 0], b[:, 2]
    num = np.sum(x * zp - xp * z) - (x.sum() * zp.sum() - xp.sum() * z.sum()) / n
    den = np.sum(x * xp + z * zp) - (x.sum() * xp.sum() + z.sum() * zp.sum()) / n
    return float(np.arctan2(num, den))


def first_pass_cost_naive(inp: FirstPassInput) -> np.ndarray:
    """Eq. 6 on every cell, ``(n, m)``, in plain NumPy (the reference twin).

    ``D(i, j) = Σ_markers |sgn(v_i) − sgn(R v'_j)|² + |sgn(a_i) − sgn(R a'_j)|²`` with
    ``R = R_y(θ(i, j))`` from eq. 7 (or the trunk angles).
    """
    n, m = inp.P.shape[0], inp.Q.shape[0]
    eps_vb, eps_ab, eps_vh, eps_ah = inp.eps
    sg = lambda x, e: np.where(x > e, 1.0, np.where(x < -e, -1.0, 0.0))
    out = np.empty((n, m))
    for i in range(n):
        for j in range(m):
            if inp.yaw_b is not None:
                th = np.radians(inp.yaw_b[i] - inp.yaw_h[j])
            else:
                th = window_yaw_naive(inp.P, inp.Q, i, j, inp.half)
            R = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
            rv = inp.vh[j] @ R.T
            ra = inp.ah[j] @ R.T
            out[i, j] = (np.sum((sg(inp.vb[i], eps_vb) - sg(rv, eps_vh)) ** 2)
                         + np.sum((sg(inp.ab[i], eps_ab) - sg(ra, eps_ah)) ** 2))
    return out


# -- second pass: forearm-aligned hand angle (eq. 8, 9) ---------------------------------
def forearm_hand_vectors(markers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit forearm and hand vectors of eq. 8, two ``(T, 3)`` from markers ``(T, 4, 3)``."""
    mid = 0.5 * (markers[:, 0] + markers[:, 1])
    f = markers[:, 2] - mid
    h = markers[:, 3] - mid
    unit = lambda v: v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)
    return unit(f), unit(h)


def _rot_only(m: np.ndarray) -> np.ndarray:
    return m / np.maximum(np.linalg.norm(m, axis=-2, keepdims=True), 1e-12)


def hand_directions(clip: Clip, side: HandSide, offsets: MarkerOffsets | None = None,
                    world: np.ndarray | None = None) -> np.ndarray:
    """The hand vector of eq. 8 in the forearm joint's frame, ``(T, 3)`` unit vectors.

    ``u(t) = R_f(t)ᵀ h(t)``, with ``R_f`` the forearm joint's world rotation: the forearm
    is aligned as a whole frame rather than by the minimal rotation between forearm
    vectors, so the twist about the forearm stays fixed. Two rigs' forearm frames may
    differ by a constant rotation (other joint axes); :func:`align_hands` removes it
    with a least-squares fit over the first pass's matches.
    """
    sk = clip.skeleton
    offsets = default_marker_offsets(sk, side) if offsets is None else offsets
    world = clip.world_xforms() if world is None else world
    w = sk.index(side.wrist)
    fa = sk.index(side.forearm)
    o = offsets.as_array()
    hv = o[3] - 0.5 * (o[0] + o[1])  # in the wrist frame
    Rw = _rot_only(world[:, w, :3, :3])
    Rf = _rot_only(world[:, fa, :3, :3])
    u = np.einsum("tji,tjk,k->ti", Rf, Rw, hv)
    return u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-12)


def forearm_rest_basis(skeleton, side: HandSide, offsets: MarkerOffsets | None = None) -> np.ndarray:
    """Rest-pose axes of the hand in the forearm joint's frame, ``(3, 3)`` (columns).

    Columns: the hand vector of eq. 8, the wrist markers' across direction (made
    perpendicular), their cross product, all at rest and in forearm-local coordinates.
    ``B_body · B_handᵀ`` maps :func:`hand_directions` of the hand rig onto the body rig's
    when both rest poses hold the hand alike.
    """
    offsets = default_marker_offsets(skeleton, side) if offsets is None else offsets
    rest = skeleton.rest_world_xforms()
    rw = _rot_only(rest[skeleton.index(side.wrist), :3, :3])
    rf = _rot_only(rest[skeleton.index(side.forearm), :3, :3])
    o = offsets.as_array()
    e1 = rf.T @ rw @ (o[3] - 0.5 * (o[0] + o[1]))
    e1 = e1 / np.linalg.norm(e1)
    e2 = rf.T @ rw @ (o[0] - o[1])
    e2 = e2 - e1 * np.dot(e1, e2)
    if np.linalg.norm(e2) < 1e-9:
        helper = np.array([0.0, 1.0, 0.0]) if abs(e1[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        e2 = np.cross(e1, helper)
    e2 = e2 / np.linalg.norm(e2)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=1)


def fit_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The rotation ``(3, 3)`` minimising ``Σ |a_k − R b_k|²`` over rows of ``(N, 3)`` arrays (Kabsch)."""
    H = np.asarray(b, dtype=np.float64).T @ np.asarray(a, dtype=np.float64)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    return Vt.T @ np.diag([1.0, 1.0, d]) @ U.T


@njit(cache=True)
def _angle_kernel(rows, cols, ub, uh):  # pragma: no cover - compiled
    N = rows.shape[0]
    out = np.empty(N)
    for c in range(N):
        i = rows[c]
        j = cols[c]
        d = ub[i, 0] * uh[j, 0] + ub[i, 1] * uh[j, 1] + ub[i, 2] * uh[j, 2]
        if d > 1.0:
            d = 1.0
        elif d < -1.0:
            d = -1.0
        out[c] = np.degrees(np.arccos(d))
    return out


def direction_angle_cost(ub: np.ndarray, uh: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Angle in degrees between unit vectors ``ub[rows]`` ``(n, 3)`` and ``uh[cols]`` ``(m, 3)`` (numba)."""
    return _angle_kernel(np.ascontiguousarray(rows, np.int64), np.ascontiguousarray(cols, np.int64),
                         np.ascontiguousarray(ub, np.float64), np.ascontiguousarray(uh, np.float64))


@njit(cache=True)
def _hand_angle_kernel(rows, cols, fb, hb, fh, hh):  # pragma: no cover - compiled
    N = rows.shape[0]
    out = np.empty(N)
    for c in range(N):
        i = rows[c]
        j = cols[c]
        a0, a1, a2 = fh[j, 0], fh[j, 1], fh[j, 2]  # f' (rotate onto f)
        b0, b1, b2 = fb[i, 0], fb[i, 1], fb[i, 2]
        v0, v1, v2 = hh[j, 0], hh[j, 1], hh[j, 2]
        cth = a0 * b0 + a1 * b1 + a2 * b2
        if cth > -1.0 + 1e-9:
            # Rodrigues with k = a x b: R v = c v + k x v + k (k.v) / (1 + c)
            k0 = a1 * b2 - a2 * b1
            k1 = a2 * b0 - a0 * b2
            k2 = a0 * b1 - a1 * b0
            kv = (k0 * v0 + k1 * v1 + k2 * v2) / (1.0 + cth)
            r0 = cth * v0 + (k1 * v2 - k2 * v1) + k0 * kv
            r1 = cth * v1 + (k2 * v0 - k0 * v2) + k1 * kv
            r2 = cth * v2 + (k0 * v1 - k1 * v0) + k2 * kv
        else:
            # opposite vectors: half turn about an axis perpendicular to a
            if abs(a0) < 0.9:
                p0, p1, p2 = 0.0, -a2, a1
            else:
                p0, p1, p2 = a2, 0.0, -a0
            nn = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
            p0 /= nn
            p1 /= nn
            p2 /= nn
            pv = p0 * v0 + p1 * v1 + p2 * v2
            r0 = 2.0 * pv * p0 - v0
            r1 = 2.0 * pv * p1 - v1
            r2 = 2.0 * pv * p2 - v2
        d = hb[i, 0] * r0 + hb[i, 1] * r1 + hb[i, 2] * r2
        nr = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        d = d / max(nr, 1e-12)
        if d > 1.0:
            d = 1.0
        elif d < -1.0:
            d = -1.0
        out[c] = np.degrees(np.arccos(d))
    return out


def hand_angle_cost(fb: np.ndarray, hb: np.ndarray, fh: np.ndarray, hh: np.ndarray,
                    rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Eq. 9 in degrees on the given cells (numba).

    Parameters
    ----------
    fb, hb : (n, 3) float
        Unit forearm and hand vectors of the body clip.
    fh, hh : (m, 3) float
        The same for the hand clip.
    rows, cols : (N,) int
        Cells.
    """
    return _hand_angle_kernel(np.ascontiguousarray(rows, np.int64), np.ascontiguousarray(cols, np.int64),
                              np.ascontiguousarray(fb), np.ascontiguousarray(hb),
                              np.ascontiguousarray(fh), np.ascontiguousarray(hh))


def hand_angle_cost_naive(fb: np.ndarray, hb: np.ndarray, fh: np.ndarray, hh: np.ndarray) -> np.ndarray:
    """Eq. 9 on every cell, ``(n, m)`` degrees, with scipy's rotation alignment (the twin)."""
    from scipy.spatial.transform import Rotation

    out = np.empty((len(fb), len(fh)))
    for i in range(len(fb)):
        for j in range(len(fh)):
            R, _ = Rotation.align_vectors(fb[i][None], fh[j][None])
            v = R.apply(hh[j])
            c = np.dot(hb[i], v) / (np.linalg.norm(hb[i]) * np.linalg.norm(v))
            out[i, j] = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
    return out


# -- the two passes ---------------------------------------------------------------------
@dataclass(frozen=True)
class SpliceOptions:
    """Parameters of the alignment (defaults from the paper where it gives them).

    Parameters
    ----------
    band1, band2 : float
        Band half-widths of the first and second pass as fractions of the body length.
    yaw : {"window", "trunk", "none"}
        Rotation about the vertical axis: eq. 7 over ``yaw_window`` frames, the
        difference of trunk headings, or none.
    yaw_window : int
        Frames per eq. 7 window (5 in the paper: 20 marker positions).
    hand_trunk_yaw_deg : float
        Heading of the hand capture's trunk when its skeleton has no root (``"trunk"``).
    smooth_window : int
        Savitzky–Golay window (frames) for the derivatives.
    dead_zone : float
        Fraction of the RMS derivative under which a sign counts as 0.
    blend_window : int
        Frames on each side of a jump in the hand timing that are cross-faded.
    jump_frames : float
        A step of the matched hand frame larger than the clips' mean rate plus this
        many frames is a discontinuity to blend.
    min_phase : int
        Shortest phase, in frames, reported among the phase boundaries.
    forearm_align : {"frame", "vector"}
        Second pass: align the forearms as joint frames (:func:`hand_directions`,
        needs joints) or, as in the paper, by the minimal rotation between the
        forearm vectors of the markers (eq. 9).
    refit : int
        With ``forearm_align="frame"``: how many times the rest-pose guess of the
        rotation between the two rigs' forearm frames is refitted on the second pass's
        matches.
    transfer : {"auto", "local", "copy", "hand"}
        How finger rotations go from one rig to the other (:func:`transfer_fingers`);
        ``"auto"`` asks :func:`choose_transfer`.
    auto_transfer_deg : float
        The threshold of ``"auto"``.
    still_range_cm : float
        A hand whose wrist moves less than this (range of the wrist markers relative to
        the shoulder, centimetres, largest over the axes) in either clip carries no
        timing: when the other hand moves, the still hand takes the other hand's
        alignment (both hands of a take share one timing). 0 turns this off.
    """

    band1: float = 0.3
    band2: float = 0.1
    yaw: str = "window"
    yaw_window: int = 5
    hand_trunk_yaw_deg: float = 0.0
    smooth_window: int = 7
    dead_zone: float = 0.05
    blend_window: int = 4
    jump_frames: float = 2.0
    min_phase: int = 4
    forearm_align: str = "frame"
    refit: int = 1
    transfer: str = "auto"
    auto_transfer_deg: float = 10.0
    still_range_cm: float = 5.0

    def __post_init__(self) -> None:
        if self.transfer not in ("local", "copy", "hand", "auto"):
            raise ValueError(f"Expected transfer 'auto', 'local', 'copy' or 'hand', got {self.transfer!r}")
        if self.forearm_align not in ("frame", "vector"):
            raise ValueError(f"Expected forearm_align 'frame' or 'vector', got {self.forearm_align!r}")
        if self.yaw not in ("window", "trunk", "none"):
            raise ValueError(f"Expected yaw 'window', 'trunk' or 'none', got {self.yaw!r}")
        for k in ("band1", "band2"):
            v = getattr(self, k)
            if not v > 0:
                raise ValueError(f"Expected {k} > 0, got {v}")
        if self.yaw_window < 1 or self.yaw_window % 2 == 0:
            raise ValueError(f"Expected an odd yaw_window >= 1, got {self.yaw_window}")


@dataclass(frozen=True, eq=False)
class SideAlignment:
    """The alignment of one hand.

    Parameters
    ----------
    side : str
    first, second : WarpResult
        The two passes (path rows are body frames, columns hand frames).
    alignment : (n,) float
        For each body frame the hand frame used (median of the second path's matches;
        .5 where the median falls between two frames).
    phases : (P, 2) float
        Phase boundaries: body frame and the hand frame the first pass matched to it.
    """

    side: str
    first: WarpResult
    second: WarpResult
    alignment: np.ndarray
    phases: np.ndarray


def median_alignment(path: np.ndarray, n: int) -> np.ndarray:
    """For each of ``n`` rows the median column the path visits, ``(n,)`` float.

    A monotone path visits consecutive columns within a row, so the median is the
    mean of the row's first and last column.
    """
    path = np.asarray(path)
    rows = np.arange(n)
    starts = np.searchsorted(path[:, 0], rows, side="left")
    stops = np.searchsorted(path[:, 0], rows, side="right")
    if np.any(stops <= starts):
        raise ValueError(f"Expected a path that visits every row 0..{n - 1}")
    return 0.5 * (path[starts, 1] + path[stops - 1, 1])


def phase_boundaries(vel: np.ndarray, eps: float, min_phase: int) -> np.ndarray:
    """Frames where the sign pattern of the wrist's velocity changes, ``(P,)`` int.

    Parameters
    ----------
    vel : (T, 3) float
        Velocity of the wrist centre (cm/s).
    eps : float
        Dead zone (cm/s): smaller components count as 0.
    min_phase : int
        Runs shorter than this many frames do not start a phase.
    """
    code = np.where(vel > eps, 1, np.where(vel < -eps, -1, 0))
    key = code[:, 0] * 9 + code[:, 1] * 3 + code[:, 2]
    change = np.nonzero(key[1:] != key[:-1])[0] + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [len(key)]])
    out = []
    cur = None
    for s, e in zip(starts, ends):
        if e - s < min_phase:
            continue
        if cur is not None and key[s] != cur and s > 0:
            out.append(int(s))
        cur = key[s]
    return np.array(out, dtype=np.int64)


def align_hands(body_markers: np.ndarray, hand_markers: np.ndarray, fps: float, *,
                body_ref: np.ndarray | None = None, hand_ref: np.ndarray | None = None,
                constraints: Sequence[Constraint] = (), options: SpliceOptions = SpliceOptions(),
                body_yaw_deg: np.ndarray | None = None, hand_yaw_deg: np.ndarray | None = None,
                body_hand_dirs: np.ndarray | None = None, hand_hand_dirs: np.ndarray | None = None,
                frame_rotation: np.ndarray | None = None, side: str = "right") -> SideAlignment:
    """Two-pass DTW of one hand's markers (section 3 and 4 of the paper).

    Parameters
    ----------
    body_markers : (n, 4, 3) float
        p1, p2 (wrist), p3 (forearm), p4 (hand) of the body clip, cm, Y up.
    hand_markers : (m, 4, 3) float
        The same for the hand clip, at the same frame rate.
    fps : float
        Frame rate of both.
    body_ref, hand_ref : (n, 3), (m, 3) float, optional
        Shoulder positions (cm, Y up) subtracted from the markers; omitted: nothing
        subtracted (a still trunk).
    constraints : sequence of Constraint
        Body frame to hand frame pairs with tolerances.
    options : SpliceOptions
    body_yaw_deg, hand_yaw_deg : (n,), (m,) float, optional
        Trunk headings in degrees, needed for ``options.yaw == "trunk"``.
    body_hand_dirs, hand_hand_dirs : (n, 3), (m, 3) float, optional
        Forearm-aligned unit hand vectors (:func:`hand_directions`); with
        ``options.forearm_align == "frame"`` the second pass compares these, otherwise
        it aligns the markers' forearm vectors (eq. 8–9).
    frame_rotation : (3, 3) float, optional
        A guess of the rotation from the hand rig's forearm frame to the body rig's
        (``forearm_rest_basis(body) @ forearm_rest_basis(hands).T``); tried, refitted,
        against no rotation.

    Returns
    -------
    SideAlignment
    """
    P = np.array(body_markers, dtype=np.float64)
    Q = np.array(hand_markers, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3 or Q.ndim != 3 or Q.shape[1:] != P.shape[1:]:
        raise ValueError(f"Expected markers of shapes (n, K, 3) and (m, K, 3), got {P.shape} and {Q.shape}")
    n, m = P.shape[0], Q.shape[0]
    if body_ref is not None:
        P -= np.asarray(body_ref, dtype=np.float64)[:, None, :]
    if hand_ref is not None:
        Q -= np.asarray(hand_ref, dtype=np.float64)[:, None, :]
    cons = check_constraints(list(constraints), n, m)
    vb, ab, evb, eab = sign_features(P, fps, window=options.smooth_window, dead_zone=options.dead_zone)
    vh, ah, evh, eah = sign_features(Q, fps, window=options.smooth_window, dead_zone=options.dead_zone)
    yaw_b = yaw_h = None
    if options.yaw == "trunk":
        if body_yaw_deg is None:
            raise ValueError("yaw='trunk' needs body_yaw_deg")
        yaw_b = np.asarray(body_yaw_deg, dtype=np.float64)
        yaw_h = (np.full(m, options.hand_trunk_yaw_deg) if hand_yaw_deg is None
                 else np.asarray(hand_yaw_deg, dtype=np.float64))
    elif options.yaw == "none":
        yaw_b, yaw_h = np.zeros(n), np.zeros(m)
    inp = FirstPassInput(np.ascontiguousarray(P), np.ascontiguousarray(Q), vb, ab, vh, ah,
                        (evb, eab, evh, eah), options.yaw_window // 2, yaw_b, yaw_h)
    band1 = Band.diagonal(n, m, options.band1, cons)
    first = dtw(lambda r, c: first_pass_cost(inp, r, c), band1, shape=(n, m))
    band2 = Band.around_path(first.path, n, m, options.band2).intersect(Band.diagonal(n, m, np.inf, cons))
    if options.forearm_align == "frame" and body_hand_dirs is not None and hand_hand_dirs is not None:
        ub = np.asarray(body_hand_dirs, dtype=np.float64)
        uh = np.asarray(hand_hand_dirs, dtype=np.float64)
        if ub.shape != (n, 3) or uh.shape != (m, 3):
            raise ValueError(f"Expected hand directions of shapes ({n}, 3) and ({m}, 3), got {ub.shape} and {uh.shape}")
        # The two rigs' forearm frames may differ by a constant rotation. Candidates: none (same
        # joint axes), and the rest-pose guess refitted on the second pass's matches; the one
        # whose second pass costs less wins.
        candidates = [(np.eye(3), 0)]
        if frame_rotation is not None:
            G = np.asarray(frame_rotation, dtype=np.float64)
            if G.shape != (3, 3):
                raise ValueError(f"Expected frame_rotation of shape (3, 3), got {G.shape}")
            if np.degrees(np.arccos(np.clip((np.trace(G) - 1) / 2, -1, 1))) > 1.0:
                candidates.append((G, options.refit))
        second = None
        for R, refits in candidates:
            for k in range(refits + 1):
                uh_r = uh @ R.T
                res = dtw(lambda r, c: direction_angle_cost(ub, uh_r, r, c), band2, shape=(n, m))
                if k < refits:
                    match = np.clip(np.round(median_alignment(res.path, n)).astype(int), 0, m - 1)
                    R = fit_rotation(ub, uh[match])
            if second is None or res.cost < second.cost:
                second = res
    else:
        fb, hb = forearm_hand_vectors(P)
        fh, hh = forearm_hand_vectors(Q)
        second = dtw(lambda r, c: hand_angle_cost(fb, hb, fh, hh, r, c), band2, shape=(n, m))
    align = median_alignment(second.path, n)
    wrist_v = 0.5 * (vb[:, 0] + vb[:, 1])
    pb = phase_boundaries(wrist_v, evb, options.min_phase)
    first_align = median_alignment(first.path, n)
    phases = np.stack([pb.astype(float), first_align[pb]], axis=1) if pb.size else np.zeros((0, 2))
    return SideAlignment(side=side, first=first, second=second, alignment=align, phases=phases)


# -- merging: fingers onto the body -------------------------------------------------------
def pair_finger_joints(body_side: HandSide, hand_side: HandSide) -> tuple[list[tuple[str, str]], list[str], list[str]]:
    """Pair finger joints of two rigs by finger and position from the fingertip.

    Returns
    -------
    pairs : list of (body joint, hand joint)
    body_unmatched : list of str
        Body finger joints with no counterpart (they keep the body's animation).
    hand_unmatched : list of str
        Hand finger joints not used.
    """
    pairs, bu, hu = [], [], []
    for f in FINGERS:
        b = list(body_side.fingers[f])
        h = list(hand_side.fingers[f])
        k = min(len(b), len(h))
        pairs += list(zip(b[len(b) - k:], h[len(h) - k:]))
        bu += b[:len(b) - k]
        hu += h[:len(h) - k]
    return pairs, bu, hu


@dataclass(frozen=True, eq=False)
class FingerTransfer:
    """Finger rotations for the body.

    Parameters
    ----------
    joints : list of int
        Body skeleton indices.
    rotations : (n, len(joints), 4) float
        Local rotations, xyzw.
    seams : (S,) int
        Body frames after which the hand timing jumped and the motion was cross-faded.
    """

    joints: list
    rotations: np.ndarray
    seams: np.ndarray


def _sample(rel: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``rel (m, k, 4)`` at fractional frames ``t (n,)`` by slerp."""
    m = rel.shape[0]
    t = np.clip(t, 0.0, m - 1)
    i0 = np.minimum(np.floor(t).astype(int), max(m - 2, 0))
    i1 = np.minimum(i0 + 1, m - 1)
    w = (t - i0)[:, None] * np.ones(rel.shape[1])
    return quat_slerp(rel[i0], rel[i1], w)


def transfer_fingers(body: Clip, hands: Clip, pairs: Sequence[tuple[str, str]], alignment: np.ndarray, *,
                     blend_window: int = 4, jump_frames: float = 2.0, mode: str = "local",
                     axes: np.ndarray | None = None) -> FingerTransfer:
    """Finger rotations of ``hands`` at the aligned frames, put on ``body``'s joints.

    Parameters
    ----------
    body, hands : Clip
        Same frame rate.
    pairs : sequence of (body joint name, hand joint name)
    alignment : (n,) float
        Hand frame for each body frame (fractional allowed).
    blend_window : int
        Half-width (frames) of the cross-fade at a jump.
    jump_frames : float
        Extra hand frames per body frame beyond the mean rate that make a jump.
    mode : {"local", "copy", "hand"}
        ``"local"``: rotations relative to rest, ``q_body = rest_body · rest_hand⁻¹ ·
        q_hand``; ``"copy"``: local rotations as they are, ``q_body = q_hand`` (rigs
        whose joint frames coincide but whose declared rest rotations differ, such as
        a glTF character and its BVH export); ``"hand"``: rotations relative to rest
        carried through the hands' rest axes, ``q_body = rest_body · c · rest_hand⁻¹ ·
        q_hand · c⁻¹`` with ``c`` from ``axes``.
    axes : (len(pairs), 4) float, optional
        :func:`transfer_axes`, for ``mode="hand"``.
    """
    if mode not in ("local", "copy", "hand"):
        raise ValueError(f"Expected mode 'local', 'copy' or 'hand', got {mode!r}")
    if mode == "hand" and axes is None:
        raise ValueError("mode='hand' needs axes (transfer_axes)")
    a = np.asarray(alignment, dtype=np.float64)
    n = body.num_frames
    if a.shape != (n,):
        raise ValueError(f"Expected alignment of shape ({n},), got {a.shape}")
    bj = [body.skeleton.index(b) for b, _ in pairs]
    hj = [hands.skeleton.index(h) for _, h in pairs]
    if not pairs:
        return FingerTransfer([], np.zeros((n, 0, 4)), np.zeros(0, np.int64))
    rel = np.array(hands.rotations[:, hj])
    if mode != "copy":
        rel = quat_multiply(quat_conjugate(hands.skeleton.rest_rotations[hj])[None], rel)
    # keep consecutive quaternions in one hemisphere so slerp and blends take short arcs
    if rel.shape[0] > 1:
        step = np.where(np.sum(rel[1:] * rel[:-1], axis=-1) < 0, -1.0, 1.0)
        rel[1:] *= np.cumprod(step, axis=0)[..., None]
    out = _sample(rel, a)
    rate = (hands.num_frames - 1) / max(n - 1, 1)
    steps = np.diff(a)
    seams = np.nonzero(steps > rate + jump_frames)[0]
    w = int(blend_window)
    if w > 0:
        for s in seams:
            lo, hi = max(s - w + 1, 0), min(s + w, n - 1)
            t = np.arange(lo, hi + 1)
            left_t = np.where(t <= s, a[t], a[s] + (t - s) * rate)
            right_t = np.where(t >= s + 1, a[t], a[s + 1] - (s + 1 - t) * rate)
            alpha = (t - lo + 1) / (hi - lo + 2)
            alpha = alpha * alpha * (3 - 2 * alpha)  # smoothstep
            ql = _sample(rel, left_t)
            qr = _sample(rel, right_t)
            out[t] = quat_slerp(ql, qr, alpha[:, None] * np.ones(len(pairs)))
    if mode == "copy":
        return FingerTransfer(bj, out, seams.astype(np.int64))
    if mode == "hand":
        c = np.asarray(axes, dtype=np.float64)
        if c.shape != (len(pairs), 4):
            raise ValueError(f"Expected axes of shape ({len(pairs)}, 4), got {c.shape}")
        out = quat_multiply(quat_multiply(c[None], out), quat_conjugate(c)[None])
    rots = quat_multiply(body.skeleton.rest_rotations[bj][None], out)
    return FingerTransfer(bj, rots, seams.astype(np.int64))


@dataclass(frozen=True, eq=False)
class SpliceResult:
    """The body clip with spliced fingers and what was found on the way.

    Parameters
    ----------
    clip : Clip
        The body clip, finger joints replaced.
    sides : dict of str to SideAlignment
        Per hand.
    transfers : dict of str to FingerTransfer
    pairs : dict of str to list of (body joint, hand joint)
    body_unmatched, hand_unmatched : dict of str to list of str
        Finger joints without a counterpart, per hand.
    transfer_modes : dict of str to str
        ``"local"``, ``"copy"`` or ``"hand"`` per hand (what ``"auto"`` chose).
    timing_from : dict of str to str
        Per hand, the hand whose alignment it uses: itself, or the other hand when its
        own arm is still (``SpliceOptions.still_range_cm``).
    wrist_range_cm : dict of str to (float, float)
        Per hand, the wrist's range relative to the shoulder in BODY and in HANDS.
    """

    clip: Clip
    sides: dict
    transfers: dict
    pairs: dict
    body_unmatched: dict
    hand_unmatched: dict
    transfer_modes: dict
    timing_from: dict = field(default_factory=dict)
    wrist_range_cm: dict = field(default_factory=dict)


def splice_clips(body: Clip, hands: Clip, body_sides: dict, hand_sides: dict, *,
                 constraints: Sequence[Constraint] = (), options: SpliceOptions = SpliceOptions(),
                 body_offsets: dict | None = None, hand_offsets: dict | None = None,
                 body_markers: dict | None = None, hand_markers: dict | None = None,
                 progress=None) -> SpliceResult:
    """Splice the fingers of ``hands`` onto ``body``, each hand on its own.

    Parameters
    ----------
    body : Clip
        Full-body clip.
    hands : Clip
        Hand clip at the same frame rate (resample first).
    body_sides, hand_sides : dict of str to HandSide
        The hands to splice, keyed ``"left"``/``"right"``; the same keys in both.
    constraints : sequence of Constraint
        Body frame to hand frame pairs (frames of these two clips), used for every hand.
    options : SpliceOptions
    body_offsets, hand_offsets : dict of str to MarkerOffsets, optional
        Marker placement per hand; :func:`default_marker_offsets` otherwise.
    body_markers, hand_markers : dict of str to (T, 4, 3) float, optional
        Real marker positions per hand (p1, p2 wrist, p3 forearm, p4 hand; centimetres,
        Y up; one row per frame of ``body`` / ``hands``), used instead of markers placed
        on the joints. The second pass with ``forearm_align="frame"`` still compares the
        joints' frames; ``"vector"`` uses these markers (eq. 8–9).
    progress : callable, optional
        ``progress(done, total, label)``.

    Raises
    ------
    ValueError
        Frame rates that differ, sides that do not match, a hand without forearm.
    """
    if abs(body.fps - hands.fps) > 1e-6 * body.fps:
        raise ValueError(f"Expected clips at the same frame rate, got {body.fps} and {hands.fps}")
    if set(body_sides) != set(hand_sides) or not body_sides:
        raise ValueError(f"Expected the same non-empty sides, got {sorted(body_sides)} and {sorted(hand_sides)}")
    wb = partial_world_xforms(body, [j for s in body_sides.values() for j in _side_joints(body.skeleton, s)])
    wh = partial_world_xforms(hands, [j for s in hand_sides.values() for j in _side_joints(hands.skeleton, s)])
    out = body
    sides, transfers, pairs_all, bun, hun, modes, ranges = {}, {}, {}, {}, {}, {}, {}
    order = [s for s in ("left", "right") if s in body_sides]
    for k, s in enumerate(order):
        bs, hs = body_sides[s], hand_sides[s]
        bo = (body_offsets or {}).get(s) or default_marker_offsets(body.skeleton, bs)
        ho = (hand_offsets or {}).get(s) or default_marker_offsets(hands.skeleton, hs)
        bm = _given_markers(body_markers, s, body.num_frames, "body") if body_markers and s in body_markers \
            else markers_from_joints(body, bs, bo, wb)
        hm = _given_markers(hand_markers, s, hands.num_frames, "hand") if hand_markers and s in hand_markers \
            else markers_from_joints(hands, hs, ho, wh)
        bref = _ref(body, bs, wb)
        href = _ref(hands, hs, wh)
        yb = yh = None
        if options.yaw == "trunk":
            # a root counts as a trunk only on rigs with a shoulder (a hand-only rig's root is its forearm)
            yb = (trunk_yaw_deg(body, body.skeleton.index(bs.root), wb) if bs.root and bs.shoulder
                  else np.zeros(body.num_frames))
            yh = trunk_yaw_deg(hands, hands.skeleton.index(hs.root), wh) if hs.root and hs.shoulder else None
        al = align_hands(bm, hm, body.fps, body_ref=bref, hand_ref=href, constraints=constraints,
                         options=options, body_yaw_deg=yb, hand_yaw_deg=yh,
                         body_hand_dirs=hand_directions(body, bs, bo, wb),
                         hand_hand_dirs=hand_directions(hands, hs, ho, wh),
                         frame_rotation=forearm_rest_basis(body.skeleton, bs, bo)
                         @ forearm_rest_basis(hands.skeleton, hs, ho).T, side=s)
        sides[s] = al
        ranges[s] = (_wrist_range_cm(bm, bref), _wrist_range_cm(hm, href))
        if progress is not None:
            progress(k + 1, len(order) + 1, s)
    timing = {s: s for s in order}
    if options.still_range_cm > 0 and len(order) == 2:
        still = {s: min(ranges[s]) < options.still_range_cm for s in order}
        for s, other in zip(order, order[::-1]):
            if still[s] and not still[other]:
                timing[s] = other
    for s in order:
        bs, hs = body_sides[s], hand_sides[s]
        al = sides[timing[s]]
        pairs, bu, hu = pair_finger_joints(bs, hs)
        mode = options.transfer
        if mode == "auto":
            mode = choose_transfer(body.skeleton, hands.skeleton, pairs, options.auto_transfer_deg) if pairs else "local"
        axes = transfer_axes(body.skeleton, bs, hands.skeleton, hs, pairs) if mode == "hand" and pairs else None
        modes[s] = mode
        tr = transfer_fingers(body, hands, pairs, al.alignment, blend_window=options.blend_window,
                              jump_frames=options.jump_frames, mode=mode, axes=axes)
        if tr.joints:
            out = out.with_joint_rotations(tr.joints, tr.rotations)
        transfers[s], pairs_all[s], bun[s], hun[s] = tr, pairs, bu, hu
    sides = {s: sides[timing[s]] for s in order}
    if progress is not None:
        progress(len(order) + 1, len(order) + 1, "fingers")
    return SpliceResult(out, sides, transfers, pairs_all, bun, hun, modes, timing, ranges)


def _wrist_range_cm(markers: np.ndarray, ref: np.ndarray | None) -> float:
    """Largest range over the axes of the wrist markers' midpoint, relative to ``ref`` (cm)."""
    w = 0.5 * (markers[:, 0] + markers[:, 1])
    if ref is not None:
        w = w - ref
    return float(np.ptp(w, axis=0).max())


def _given_markers(markers: dict, side: str, frames: int, what: str) -> np.ndarray:
    m = np.asarray(markers[side], dtype=np.float64)
    if m.shape != (frames, 4, 3):
        raise ValueError(f"Expected {what} markers of the {side} hand of shape ({frames}, 4, 3), got {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError(f"Expected finite {what} markers of the {side} hand, got NaN or infinite values")
    return m


def partial_world_xforms(clip: Clip, joints: Sequence[int]) -> np.ndarray:
    """World transforms ``(T, J, 4, 4)`` computed only for ``joints`` and their ancestors.

    Other joints are left zero; pass the result as ``world=`` to the marker functions
    (forward kinematics of a whole 60-joint character costs more than the alignment).
    """
    sk = clip.skeleton
    need = sorted({a for j in joints for a in sk.chain_to_root(int(j))})
    local = trs_to_xform(clip.translations[:, need], clip.rotations[:, need], clip.scales[:, need])
    world = np.zeros((clip.num_frames, sk.num_joints, 4, 4))
    for k, j in enumerate(need):  # parents come before children
        p = int(sk.parents[j])
        world[:, j] = local[:, k] if p < 0 else world[:, p] @ local[:, k]
    return world


def _side_joints(skeleton, side: HandSide) -> list[int]:
    names = [side.wrist, side.forearm, side.shoulder, side.root]
    return [skeleton.index(n) for n in names if n is not None]


def _ref(clip: Clip, side: HandSide, world: np.ndarray) -> np.ndarray | None:
    """Shoulder positions (cm, Y up), or None for a rig without a shoulder (still trunk)."""
    if side.shoulder is None:
        return None
    return yup_cm_positions(clip, [clip.skeleton.index(side.shoulder)], world)[:, 0]

"""Turning hand tracks (wrist targets, hand orientations, finger poses) into clips.

A gesture is authored per hand as a list of :class:`HandKey` in the frame of the hips
(centimetres; +X the character's left, +Y up, +Z forward). Between "stop" keys the
wrist follows a clamped cubic spline through the "pass" keys, so it comes to rest at
every stop key (holds and the rest pose) and keeps moving through pass keys (the
preparation flowing into the stroke). Finger poses follow a monotone (PCHIP)
interpolation, so they never overshoot their keys.

The arms are posed by analytic two-bone inverse kinematics: the elbow lies in the
plane of the shoulder, the wrist target and a pole vector; the forearm takes the twist
that leaves the wrist with swing only. The spine, neck and head carry a small idle
motion, the clavicles an elevation curve (shrugs, raised arms).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline, PchipInterpolator

from usdhands.model.clip import Clip
from usdhands.model.rotations import (
    euler_deg_to_quat, matrix_to_quat, quat_multiply, quat_slerp, quat_to_matrix, trs_to_xform,
)
from usdhands.model.skeleton import Skeleton, forward_kinematics
from usdhands.samples.hand_poses import mirror_pose, relaxed_pose
from usdhands.samples.humanoid import FINGER_NAMES

__all__ = ["HandKey", "HandTrack", "BodyIdle", "rest_key", "mirror_key", "build_clip", "FPS"]

FPS = 30.0
_M = np.array([-1.0, 1.0, 1.0])  # mirror across the body's mid plane (x -> -x)


@dataclass
class HandKey:
    """One key of a hand's track, for the **right** hand unless built by :func:`mirror_key`.

    Parameters
    ----------
    t : float
        Seconds from the start of the clip.
    pos : (3,) float
        Wrist target in the hips frame, cm.
    fingers_dir : (3,) float
        Direction the fingers point (hand's +Y), hips frame.
    palm : (3,) float
        Palm normal, pointing out of the palm, hips frame.
    pose : (15, 3) float
        Finger pose in the left-hand convention of :mod:`usdhands.samples.hand_poses`
        (degrees relative to rest); the right hand gets it mirrored.
    stop : bool
        The wrist comes to rest at this key.
    shoulder_lift : float
        Clavicle elevation, degrees.
    """

    t: float
    pos: np.ndarray
    fingers_dir: np.ndarray
    palm: np.ndarray
    pose: np.ndarray
    stop: bool = True
    shoulder_lift: float = 0.0


@dataclass
class HandTrack:
    """The keys of one hand (sorted by time) plus additive finger motion.

    ``finger_extra`` holds functions ``times (T,) -> (T, 15, 3)`` degrees added to the
    interpolated pose (the rolling fingers of "turn", micro-motion in holds).
    ``elbow_out`` and ``elbow_back`` move the IK pole (how far the elbow swings out
    or back, about -0.4..0.4); ``twist_share`` is the part of the hand's twist the
    forearm takes (the rest stays in the wrist joint), people differ in both.
    """

    side: str
    keys: list[HandKey] = field(default_factory=list)
    finger_extra: list = field(default_factory=list)
    elbow_out: float = 0.0
    elbow_back: float = 0.0
    twist_share: float = 1.0


@dataclass
class BodyIdle:
    """A standing idle: slow sway of the hips and spine, breathing, small head motion.

    All amplitudes in degrees (rotations) or cm (translations); phases in radians.
    """

    phases: np.ndarray
    sway_cm: float = 0.6
    spine_deg: float = 1.2
    head_deg: float = 2.5
    lean_forward_deg: float = 0.0

    @staticmethod
    def random(rng: np.random.Generator) -> "BodyIdle":
        """An idle with random phases and slightly varied amplitudes."""
        return BodyIdle(phases=rng.uniform(0, 2 * np.pi, 8), sway_cm=rng.uniform(0.3, 0.9),
                        spine_deg=rng.uniform(0.6, 1.6), head_deg=rng.uniform(1.5, 3.5))


def rest_key(t: float, side: str = "right", pose: np.ndarray | None = None, jitter: np.ndarray | None = None) -> HandKey:
    """The arm hanging relaxed at the side, palm toward the thigh."""
    pos = np.array([-19.0, -7.0, 3.5]) + (0 if jitter is None else jitter)
    key = HandKey(t, pos, np.array([-0.05, -1.0, 0.12]), np.array([1.0, 0.0, 0.05]),
                  relaxed_pose() if pose is None else np.asarray(pose, dtype=np.float64), True, 0.0)
    return mirror_key(key) if side == "left" else key


def mirror_key(key: HandKey) -> HandKey:
    """The same key for the other hand (positions and directions mirrored; the pose is side-neutral)."""
    return HandKey(key.t, key.pos * _M, key.fingers_dir * _M, key.palm * _M, np.array(key.pose), key.stop,
                   key.shoulder_lift)


# ----------------------------------------------------------------- interpolation

def _key_frame(k: HandKey) -> np.ndarray:
    y = k.fingers_dir / np.linalg.norm(k.fingers_dir)
    z = k.palm - np.dot(k.palm, y) * y
    z /= np.linalg.norm(z)
    return np.stack([np.cross(y, z), y, z], axis=-1)


def _refine(keys: list[HandKey], max_deg: float = 50.0) -> list[HandKey]:
    """Insert keys where the hand turns more than ``max_deg`` between two keys.

    Direction vectors are interpolated component-wise, which fails between nearly
    opposite directions; the inserted key carries the slerp halfway orientation, the
    mean position and pose and the mean time, which leaves the position curve of a
    clamped spline between two stop keys unchanged (a single cubic passes through
    the midpoint at the middle time).
    """
    out = [keys[0]]
    for k in keys[1:]:
        a = out[-1]
        ra, rb = _key_frame(a), _key_frame(k)
        qa, qb = matrix_to_quat(ra), matrix_to_quat(rb)
        ang = float(np.degrees(2 * np.arccos(np.clip(abs(np.dot(qa, qb)), 0.0, 1.0))))
        if ang > max_deg and k.t - a.t > 2e-3:
            qm = quat_slerp(qa, qb, 0.5)
            m = quat_to_matrix(qm)
            mid = HandKey(0.5 * (a.t + k.t), 0.5 * (a.pos + k.pos), m[:, 1], m[:, 2], 0.5 * (a.pose + k.pose),
                          False, 0.5 * (a.shoulder_lift + k.shoulder_lift))
            out.extend(_refine([a, mid, k], max_deg)[1:])
        else:
            out.append(k)
    return out


def _interp_track(keys: list[HandKey], times: np.ndarray) -> dict[str, np.ndarray]:
    keys = _refine(sorted(keys, key=lambda k: k.t))
    kt = np.array([k.t for k in keys])
    if np.any(np.diff(kt) <= 1e-6):
        raise ValueError(f"Key times must increase, got {kt.tolist()}")
    if not keys[0].stop or not keys[-1].stop:
        raise ValueError("The first and last keys of a track must be stop keys")
    # orientations as quaternion components, signs made consistent from key to key;
    # consecutive keys are less than 50° apart (_refine), so the normalised spline of
    # the components turns smoothly and never passes near zero
    quats = np.stack([matrix_to_quat(_key_frame(k)) for k in keys])
    for i in range(1, len(quats)):
        if np.dot(quats[i], quats[i - 1]) < 0:
            quats[i] = -quats[i]
    vec = np.stack([np.concatenate([k.pos, q, [k.shoulder_lift]]) for k, q in zip(keys, quats)])
    out = np.empty((len(times), vec.shape[1]))
    stops = [i for i, k in enumerate(keys) if k.stop]
    tt = np.clip(times, kt[0], kt[-1])
    for a, b in zip(stops[:-1], stops[1:]):
        sel = (tt >= kt[a]) & (tt <= kt[b])
        spline = CubicSpline(kt[a:b + 1], vec[a:b + 1], bc_type="clamped", axis=0)
        out[sel] = spline(tt[sel])
    poses = np.stack([k.pose.reshape(-1) for k in keys])
    fingers = PchipInterpolator(kt, poses, axis=0)(tt).reshape(len(times), 15, 3)
    m = quat_to_matrix(out[:, 3:7] / np.linalg.norm(out[:, 3:7], axis=1, keepdims=True))
    return {"pos": out[:, :3], "y": m[:, :, 1], "z": m[:, :, 2], "lift": out[:, 7], "fingers": fingers}


# ----------------------------------------------------------------- kinematics

def _frames_from_yz(y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Rotation matrices (T, 3, 3) with columns X = Y x Z, Y, Z."""
    return np.stack([np.cross(y, z), y, z], axis=-1)


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _two_bone_ik(shoulder: np.ndarray, target: np.ndarray, pole: np.ndarray, l1: float, l2: float):
    """Elbow position and unit bone directions; all (T, 3) world cm."""
    d = target - shoulder
    dist = np.linalg.norm(d, axis=1)
    dhat = d / dist[:, None]
    dist = np.clip(dist, abs(l1 - l2) + 1.0, 0.985 * (l1 + l2))
    a = (l1 ** 2 - l2 ** 2 + dist ** 2) / (2 * dist)
    h = np.sqrt(np.maximum(l1 ** 2 - a ** 2, 0.0))
    p = pole - np.sum(pole * dhat, axis=1, keepdims=True) * dhat
    p = _normalize(p)
    elbow = shoulder + a[:, None] * dhat + h[:, None] * p
    wrist = shoulder + dist[:, None] * dhat
    return elbow, wrist, dhat, p


def _twist_about_y(q: np.ndarray) -> np.ndarray:
    """Angle (radians) of the twist about local Y in the swing-twist split of ``q`` (T, 4)."""
    return 2.0 * np.arctan2(q[:, 1], q[:, 3])


def _axis_angle_quat(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    axis = np.broadcast_to(np.asarray(axis, dtype=np.float64), angle.shape + (3,))
    s = np.sin(angle / 2)[..., None]
    return np.concatenate([axis * s, np.cos(angle / 2)[..., None]], axis=-1)


def _idle_rotations(idle: BodyIdle, times: np.ndarray) -> dict[str, np.ndarray]:
    """Euler XYZ degrees (T, 3) relative to rest for centre joints; hips translation offset."""
    ph = idle.phases
    w = 2 * np.pi * np.array([0.11, 0.17, 0.23, 0.29, 0.07, 0.13, 0.19, 0.31])
    s = lambda k: np.sin(w[k] * times + ph[k])
    T = len(times)
    e = {}
    e["Hips"] = np.stack([0.6 * s(0), 1.5 * s(1), 0.8 * s(2)], axis=1) * idle.spine_deg
    e["Spine"] = np.stack([0.5 * s(3) + idle.lean_forward_deg / 3, -0.6 * s(1), -0.4 * s(2)], axis=1) * idle.spine_deg
    breathe = np.sin(2 * np.pi * 0.25 * times + ph[4])
    e["Spine1"] = np.stack([0.6 * breathe, -0.4 * s(1), -0.3 * s(2)], axis=1) * idle.spine_deg
    e["Spine2"] = np.stack([0.8 * breathe + idle.lean_forward_deg / 3, -0.3 * s(1), -0.2 * s(2)], axis=1) * idle.spine_deg
    e["Neck"] = np.stack([0.3 * s(5), 0.3 * s(6), 0.2 * s(7)], axis=1) * idle.head_deg
    e["Head"] = np.stack([0.5 * s(5) + 0.2 * s(7), 0.6 * s(6), 0.3 * s(3)], axis=1) * idle.head_deg
    trans = np.stack([idle.sway_cm * s(1), 0.2 * breathe, 0.3 * idle.sway_cm * s(4)], axis=1)
    e["_hips_translation"] = trans
    del T
    return e


def build_clip(skeleton: Skeleton, tracks: list[HandTrack], duration: float, idle: BodyIdle,
               name: str, fps: float = FPS) -> Clip:
    """Sample the tracks into a clip of the sample humanoid.

    Parameters
    ----------
    skeleton : Skeleton
        :func:`usdhands.samples.humanoid.humanoid_skeleton`.
    tracks : list of HandTrack
        One per hand ("left", "right"); a missing hand stays at rest.
    duration : float
        Seconds; the clip has ``round(duration * fps) + 1`` frames.
    idle : BodyIdle
    name : str
        The clip's name.
    """
    sk = skeleton
    T = int(round(duration * fps)) + 1
    times = np.arange(T) / fps
    J = sk.num_joints
    rest_q = np.asarray(sk.rest_rotations)
    rot = np.broadcast_to(rest_q, (T, J, 4)).copy()
    trans = np.broadcast_to(sk.rest_translations, (T, J, 3)).copy()
    idx = {n: i for i, n in enumerate(sk.short_names)}

    idle_e = _idle_rotations(idle, times)
    for n, e in idle_e.items():
        if n.startswith("_"):
            continue
        rot[:, idx[n]] = quat_multiply(rest_q[idx[n]], euler_deg_to_quat(e))
    trans[:, idx["Hips"]] += idle_e["_hips_translation"]

    by_side = {t.side: t for t in tracks}
    for side in ("left", "right"):
        if side not in by_side:
            by_side[side] = HandTrack(side, [rest_key(0.0, side), rest_key(duration, side)])
    samples = {s: _interp_track(by_side[s].keys, times) for s in ("left", "right")}
    for s in ("left", "right"):
        for extra in by_side[s].finger_extra:
            samples[s]["fingers"] = samples[s]["fingers"] + extra(times)

    # clavicles: elevation about local Z (left +, right - by mirror symmetry)
    for s in ("left", "right"):
        pre = "Left" if s == "left" else "Right"
        sign = 1.0 if s == "left" else -1.0
        lift = samples[s]["lift"]
        e = np.stack([np.zeros(T), np.zeros(T), sign * lift], axis=1)
        rot[:, idx[f"{pre}Shoulder"]] = quat_multiply(rest_q[idx[f"{pre}Shoulder"]], euler_deg_to_quat(e))

    # world transforms of the body so far (spine, clavicles)
    local = trs_to_xform(trans, rot)
    world = forward_kinematics(sk.parents, local)
    hips_w = world[:, idx["Hips"]]

    for s in ("left", "right"):
        pre = "Left" if s == "left" else "Right"
        j_cl, j_up, j_lo, j_h = (idx[f"{pre}{n}"] for n in ("Shoulder", "Arm", "ForeArm", "Hand"))
        l1 = float(np.linalg.norm(sk.rest_translations[j_lo]))
        l2 = float(np.linalg.norm(sk.rest_translations[j_h]))
        cl_w = world[:, j_cl]
        shoulder = (cl_w @ np.append(sk.rest_translations[j_up], 1.0))[:, :3]
        smp = samples[s]
        hips_r = hips_w[:, :3, :3]
        target = np.einsum("tij,tj->ti", hips_r, smp["pos"]) + hips_w[:, :3, 3]
        y = np.einsum("tij,tj->ti", hips_r, smp["y"])
        z = np.einsum("tij,tj->ti", hips_r, smp["z"])
        hand_w = _frames_from_yz(y, z)
        # the elbow points down and back, a little outward; it rises with the hand
        out = 1.0 if s == "left" else -1.0
        # The pole must stay away from the shoulder-wrist line: down for an arm reaching
        # forward or sideways, back for an arm hanging down, outward in both cases.
        tr = by_side[s]
        reach = _normalize(target - shoulder)
        dy = np.einsum("ti,ti->t", reach, hips_r[:, :, 1])
        w = np.clip(1.0 - dy ** 2, 0.0, 1.0)
        raise_ = np.clip((smp["pos"][:, 1] - 10.0) / 40.0, 0.0, 1.0)
        pole_h = np.stack([(0.35 + tr.elbow_out + 0.3 * raise_) * out, -w,
                           -(1.0 - w) - (0.3 + tr.elbow_back) * w + 0.5 * raise_ * w], axis=1)
        pole = np.einsum("tij,tj->ti", hips_r, pole_h)
        elbow, wrist, dhat, p = _two_bone_ik(shoulder, target, pole, l1, l2)
        u = _normalize(elbow - shoulder)
        f = _normalize(wrist - elbow)
        hinge = _normalize(np.cross(p, dhat))
        up_w = np.stack([hinge, u, np.cross(hinge, u)], axis=-1)
        fz = np.cross(hinge, f)
        fore0 = np.stack([hinge, f, fz], axis=-1)
        q_rel = matrix_to_quat(np.einsum("tji,tjk->tik", fore0, hand_w))
        q_rel = np.where(q_rel[:, 3:4] < 0, -q_rel, q_rel)  # twist in (-180, 180] before unwrapping
        tw = np.unwrap(_twist_about_y(q_rel)) * tr.twist_share
        fore_w = fore0 @ quat_to_matrix(_axis_angle_quat([0.0, 1.0, 0.0], tw))
        rot[:, j_up] = matrix_to_quat(np.einsum("tji,tjk->tik", cl_w[:, :3, :3], up_w))
        rot[:, j_lo] = matrix_to_quat(np.einsum("tji,tjk->tik", up_w, fore_w))
        rot[:, j_h] = matrix_to_quat(np.einsum("tji,tjk->tik", fore_w, hand_w))
        # fingers
        fingers = smp["fingers"] if s == "left" else mirror_pose(smp["fingers"])
        for fi, fname in enumerate(FINGER_NAMES):
            for k in range(3):
                j = idx[f"{pre}Hand{fname}{k + 1}"]
                rot[:, j] = quat_multiply(rest_q[j], euler_deg_to_quat(fingers[:, 3 * fi + k]))

    # continuous quaternion signs over time (w >= 0 at frame 0, then nearest)
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    flip = np.sum(rot[1:] * rot[:-1], axis=-1) < 0
    sign = np.cumprod(np.where(np.concatenate([np.zeros((1, J), bool), flip]), -1.0, 1.0), axis=0)
    rot *= sign[..., None]
    first = np.where(rot[0, :, 3] < 0, -1.0, 1.0)
    rot *= first[None, :, None]
    return Clip(sk, fps, rot, trans, name=name)

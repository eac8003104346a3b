"""Synthetic body and hand-session clips with a known time warp (tests, benchmark, docs).

The body clip is a character (hips, spine, two arms with five three-joint fingers)
that walks, turns and gestures with smooth random motion of the arms, wrists and
fingers. The hand session replays the same performance through a known smooth,
non-linear, monotone time warp, with the arm's rotations about the shoulder scaled by
0.5–0.8 (a small capture volume), a still trunk turned by a constant heading, and a
little noise. ``truth[i]`` is the (fractional) hand frame that belongs to body frame i.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usdhands.model import Clip, HandSide, Skeleton
from usdhands.model.rotations import euler_deg_to_quat, matrix_to_quat

FINGER_NAMES = ("Thumb", "Index", "Middle", "Ring", "Pinky")
UE_FINGERS = ("thumb", "index", "middle", "ring", "pinky")
LEAP_FINGERS = ("Thumb", "Index", "Mid", "Ring", "Pinky")
KNUCKLES = {"Thumb": (2.0, -1.0, 3.0), "Index": (9.0, 0.0, 2.5), "Middle": (9.5, 0.0, 0.5),
            "Ring": (9.0, 0.0, -1.5), "Pinky": (8.0, 0.0, -3.5)}
PHALANX = {"Thumb": (3.0, 0.0, 1.5), "Index": (4.0, 0.0, 0.0), "Middle": (4.5, 0.0, 0.0),
           "Ring": (4.0, 0.0, 0.0), "Pinky": (3.0, 0.0, 0.0)}


def _names(style: str) -> dict:
    """Joint names by role for a naming style: 'mixamo' or 'ue'."""
    if style == "mixamo":
        out = {"hips": "Hips", "spine": "Spine", "chest": "Spine1"}
        for s, S in (("l", "Left"), ("r", "Right")):
            out.update({f"clav_{s}": f"{S}Shoulder", f"arm_{s}": f"{S}Arm", f"fore_{s}": f"{S}ForeArm",
                        f"hand_{s}": f"{S}Hand"})
            for f in FINGER_NAMES:
                for k in (1, 2, 3):
                    out[f"{f}{k}_{s}"] = f"{S}Hand{f}{k}"
        return out
    if style == "ue":
        out = {"hips": "pelvis", "spine": "spine_01", "chest": "spine_02"}
        for s in ("l", "r"):
            out.update({f"clav_{s}": f"clavicle_{s}", f"arm_{s}": f"upperarm_{s}", f"fore_{s}": f"lowerarm_{s}",
                        f"hand_{s}": f"hand_{s}"})
            for f, u in zip(FINGER_NAMES, UE_FINGERS):
                for k in (1, 2, 3):
                    out[f"{f}{k}_{s}"] = f"{u}_0{k}_{s}"
        return out
    raise ValueError(style)


def body_skeleton(style: str = "mixamo") -> Skeleton:
    """The full character, Y up, centimetres."""
    nm = _names(style)
    names, parents, trans = [], [], []

    def add(role, parent, t):
        names.append(nm[role])
        parents.append(-1 if parent is None else names.index(nm[parent]))
        trans.append(t)

    add("hips", None, (0, 100, 0))
    add("spine", "hips", (0, 20, 0))
    add("chest", "spine", (0, 20, 0))
    for s, sg in (("l", 1.0), ("r", -1.0)):
        add(f"clav_{s}", "chest", (sg * 5, 15, 0))
        add(f"arm_{s}", f"clav_{s}", (sg * 12, 0, 0))
        add(f"fore_{s}", f"arm_{s}", (sg * 28, 0, 0))
        add(f"hand_{s}", f"fore_{s}", (sg * 25, 0, 0))
        for f in FINGER_NAMES:
            kx, ky, kz = KNUCKLES[f]
            px, py, pz = PHALANX[f]
            add(f"{f}1_{s}", f"hand_{s}", (sg * kx, ky, kz))
            add(f"{f}2_{s}", f"{f}1_{s}", (sg * px, py, pz))
            add(f"{f}3_{s}", f"{f}2_{s}", (sg * px * 0.7, py, pz * 0.7))
    J = len(names)
    rest_q = np.tile([0.0, 0.0, 0.0, 1.0], (J, 1))
    return Skeleton(names, np.array(parents), np.array(trans, float), rest_q, meters_per_unit=0.01,
                    name=f"Body_{style}")


def body_handside(skeleton: Skeleton, side: str, style: str = "mixamo") -> HandSide:
    """The HandSide of :func:`body_skeleton` (built by hand, independent of detection)."""
    nm = _names(style)
    s = side[0]
    return HandSide(side=side, wrist=nm[f"hand_{s}"], forearm=nm[f"fore_{s}"], shoulder=nm[f"arm_{s}"],
                    root=nm["hips"],
                    fingers={fl: tuple(nm[f"{f}{k}_{s}"] for k in (1, 2, 3))
                             for f, fl in zip(FINGER_NAMES, UE_FINGERS)})


def _smooth_signal(rng, t: np.ndarray, amp: float, nfreq: int = 3, fmin: float = 0.15,
                   fmax: float = 0.7) -> np.ndarray:
    f = rng.uniform(fmin, fmax, nfreq)
    ph = rng.uniform(0, 2 * np.pi, nfreq)
    a = rng.uniform(0.4, 1.0, nfreq)
    return amp * np.sum(a[:, None] * np.sin(2 * np.pi * f[:, None] * t[None] + ph[:, None]), axis=0) / a.sum()


@dataclass
class Performance:
    """Analytic joint angles (degrees) of the gesture performance as functions of time."""

    seed: int

    def angles(self, t: np.ndarray) -> dict:
        """Role → (T, 3) Euler XYZ degrees, plus 'hips_t' (T, 3) cm and 'hips_yaw' (T,) degrees."""
        out = {}
        for s, sg in (("l", 1.0), ("r", -1.0)):
            rng = np.random.default_rng(self.seed * 100 + (1 if s == "l" else 2))
            arm = np.stack([_smooth_signal(rng, t, 35), _smooth_signal(rng, t, 30) + sg * 10,
                            _smooth_signal(rng, t, 40) - sg * 45], axis=-1)
            fore = np.stack([np.zeros_like(t), _smooth_signal(rng, t, 45, fmin=0.2, fmax=0.8) - sg * 50,
                             np.zeros_like(t)], axis=-1)
            hand = np.stack([_smooth_signal(rng, t, 25, fmin=0.3, fmax=1.0),
                             _smooth_signal(rng, t, 20, fmin=0.3, fmax=1.0),
                             _smooth_signal(rng, t, 35, fmin=0.3, fmax=1.0)], axis=-1)
            out[f"arm_{s}"], out[f"fore_{s}"], out[f"hand_{s}"] = arm, fore, hand
            for f in FINGER_NAMES:
                curl = 30 + _smooth_signal(rng, t, 35, fmin=0.2, fmax=0.9)
                spread = _smooth_signal(rng, t, 8)
                for k in (1, 2, 3):
                    e = np.zeros((len(t), 3))
                    e[:, 2] = -sg * curl * (1.0 if k == 1 else 0.8)
                    e[:, 1] = spread if k == 1 else 0.0
                    out[f"{f}{k}_{s}"] = e
        rng = np.random.default_rng(self.seed)
        out["hips_t"] = np.stack([_smooth_signal(rng, t, 10), 100 + 2 * np.sin(2 * np.pi * 1.7 * t),
                                  25.0 * t], axis=-1)
        out["hips_yaw"] = _smooth_signal(rng, t, 25, fmin=0.05, fmax=0.15)
        return out


def _clip_from_angles(sk: Skeleton, style: str, ang: dict, fps: float, *, arm_scale=None, yaw_offset=0.0,
                      still_trunk=False, noise_deg=0.0, rng=None) -> Clip:
    nm = _names(style)
    T = len(ang["hips_yaw"])
    rot = np.tile([0.0, 0.0, 0.0, 1.0], (T, sk.num_joints, 1))
    trans = np.broadcast_to(sk.rest_translations, (T, sk.num_joints, 3)).copy()
    for role, e in ang.items():
        if role.startswith("hips"):
            continue
        e = np.array(e)
        if arm_scale is not None and role.split("_")[0] in ("arm", "fore"):
            e = e * arm_scale[:, None]
        if noise_deg and role.split("_")[0] in ("arm", "fore", "hand"):
            e = e + rng.normal(0, noise_deg, e.shape)
        rot[:, sk.index(nm[role])] = euler_deg_to_quat(e)
    h = sk.index(nm["hips"])
    if still_trunk:
        trans[:, h] = sk.rest_translations[h]
        yaw = np.full(T, yaw_offset)
    else:
        trans[:, h] = ang["hips_t"]
        yaw = ang["hips_yaw"] + yaw_offset
    rot[:, h] = euler_deg_to_quat(np.stack([np.zeros(T), yaw, np.zeros(T)], -1))
    return Clip(sk, fps, rot, trans)


@dataclass
class SpliceCase:
    body: Clip
    hands: Clip
    truth: np.ndarray  # (n,) hand frame for each body frame
    warp: np.ndarray  # (m,) body frame (fractional) of each hand frame
    style_body: str
    style_hands: str


def make_case(n: int = 300, fps: float = 30.0, *, seed: int = 0, style_body: str = "mixamo",
              style_hands: str = "mixamo", hand_ratio: float = 1.1, warp_amount: float = 0.35,
              noise_deg: float = 0.5, yaw_offset: float = 30.0, partial: bool = False) -> SpliceCase:
    """Body clip and its hand session with a known warp.

    ``partial=True`` makes the hand session a Leap-like partial skeleton rooted at a
    forearm joint placed on the wrist (``rForeArm``/``lForeArm``, ``rHand``, ``rIndex1``...).
    """
    perf = Performance(seed)
    tb = np.arange(n) / fps
    body_sk = body_skeleton(style_body)
    body = _clip_from_angles(body_sk, style_body, perf.angles(tb), fps)
    m = int(round(n * hand_ratio))
    u = np.linspace(0.0, 1.0, m)
    k = 2.0
    warp = (n - 1) * (u + warp_amount * np.sin(2 * np.pi * k * u) / (2 * np.pi * k))
    rng = np.random.default_rng(seed + 7)
    scale = 0.65 + 0.15 * np.sin(2 * np.pi * 0.7 * u + 0.3)
    hand_sk = body_skeleton(style_hands)
    hands = _clip_from_angles(hand_sk, style_hands, perf.angles(warp / fps), fps, arm_scale=scale,
                              yaw_offset=yaw_offset, still_trunk=True, noise_deg=noise_deg, rng=rng)
    if partial:
        hands = leap_like(hands, style_hands)
    truth = np.interp(np.arange(n), warp, np.arange(m))
    return SpliceCase(body, hands, truth, warp, style_body, style_hands)


def leap_like(full: Clip, style: str) -> Clip:
    """A partial hand skeleton like the Leap Motion BVH files: root ``{l,r}ForeArm`` on the wrist."""
    nm = _names(style)
    world = full.world_xforms()
    names, parents, trans, src = [], [], [], []
    for s in ("l", "r"):
        root = len(names)
        names.append(f"{s}ForeArm")
        parents.append(-1)
        trans.append(full.skeleton.rest_world_positions()[full.skeleton.index(nm[f"hand_{s}"])])
        src.append(None)
        hand = len(names)
        names.append(f"{s}Hand")
        parents.append(root)
        trans.append((0.0, 0.0, 0.0))
        src.append(nm[f"hand_{s}"])
        for f, lf in zip(FINGER_NAMES, LEAP_FINGERS):
            prev = hand
            for k in (1, 2, 3):
                j = full.skeleton.index(nm[f"{f}{k}_{s}"])
                names.append(f"{s}{lf}{k}")
                parents.append(prev)
                trans.append(full.skeleton.rest_translations[j])
                src.append(nm[f"{f}{k}_{s}"])
                prev = len(names) - 1
    J = len(names)
    sk = Skeleton(names, np.array(parents), np.array(trans, float), np.tile([0.0, 0, 0, 1], (J, 1)),
                  meters_per_unit=0.01, name="LeapHands")
    T = full.num_frames
    rot = np.tile([0.0, 0.0, 0.0, 1.0], (T, J, 1))
    tr = np.broadcast_to(sk.rest_translations, (T, J, 3)).copy()
    for j, srcname in enumerate(src):
        if srcname is not None:
            rot[:, j] = full.rotations[:, full.skeleton.index(srcname)]
    for s in ("l", "r"):
        r = names.index(f"{s}ForeArm")
        fa = full.skeleton.index(nm[f"fore_{s}"])
        wr = full.skeleton.index(nm[f"hand_{s}"])
        R = world[:, fa, :3, :3]
        rot[:, r] = matrix_to_quat(R / np.linalg.norm(R, axis=-2, keepdims=True))
        tr[:, r] = world[:, wr, :3, 3]
    return Clip(sk, full.fps, rot, tr)


def reaxis(clip: Clip, seed: int = 0) -> Clip:
    """The same motion on a rig whose every joint frame is turned by a random constant rotation.

    World positions stay the same; local rotations, rest rotations and rest translations
    all change (``q'_j = C_parent⁻¹ q_j C_j``, ``t'_j = C_parent⁻¹ t_j``), like two DCCs'
    exports of one character with other joint axis conventions.
    """
    from scipy.spatial.transform import Rotation

    sk = clip.skeleton
    J = sk.num_joints
    C = Rotation.random(J, random_state=seed)
    Cp = [Rotation.identity() if p < 0 else C[int(p)] for p in sk.parents]
    rest_q = np.array([(Cp[j].inv() * Rotation.from_quat(np.array(sk.rest_rotations[j])) * C[j]).as_quat() for j in range(J)])
    rest_t = np.array([Cp[j].inv().apply(np.array(sk.rest_translations[j])) for j in range(J)])
    new_sk = Skeleton(sk.joint_names, sk.parents, rest_t, rest_q, meters_per_unit=sk.meters_per_unit,
                      up_axis=sk.up_axis, name=sk.name + "_reaxis")
    rot = np.empty_like(clip.rotations)
    tr = np.empty_like(clip.translations)
    for j in range(J):
        rot[:, j] = (Cp[j].inv() * Rotation.from_quat(np.array(clip.rotations[:, j])) * C[j]).as_quat()
        tr[:, j] = Cp[j].inv().apply(np.array(clip.translations[:, j]))
    return Clip(new_sk, clip.fps, rot, tr)


def leap_handside(side: str) -> HandSide:
    """HandSide of :func:`leap_like` (no shoulder, forearm on the wrist)."""
    s = side[0]
    return HandSide(side=side, wrist=f"{s}Hand", forearm=f"{s}ForeArm", shoulder=None, root=None,
                    fingers={fl: tuple(f"{s}{lf}{k}" for k in (1, 2, 3))
                             for fl, lf in zip(UE_FINGERS, LEAP_FINGERS)})


def write_example(folder, n: int = 300, seed: int = 1) -> None:
    """Write ``body.bvh`` (Mixamo-style names), ``hands.bvh`` (Leap-style partial rig) and
    ``truth.json`` (the hand frame belonging to each body frame) into ``folder``."""
    import json
    from pathlib import Path

    from usdhands.formats.io import write_asset
    from usdhands.model.asset import Asset

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    case = make_case(n, seed=seed, partial=True)
    for clip, name in ((case.body, "body.bvh"), (case.hands, "hands.bvh")):
        write_asset(Asset("synthetic", (clip.skeleton,), (clip,), ()), folder / name)
    (folder / "truth.json").write_text(json.dumps({"hand_frame_of_body_frame": [round(float(v), 3)
                                                                              for v in case.truth]}))


if __name__ == "__main__":
    import sys

    if len(sys.argv) != 2:
        sys.exit("usage: python tests/splice_synth.py OUTPUT_FOLDER")
    write_example(sys.argv[1])


def hand_session(clip: Clip, sides, *, hand_ratio: float = 1.1, warp_amount: float = 0.35,
                 noise_deg: float = 0.5, seed: int = 0) -> tuple[Clip, np.ndarray]:
    """A hand session made from any clip with hands: the recipe of :func:`make_case`.

    Known smooth non-linear monotone time warp; the rotations of each side's shoulder
    and forearm joints scaled towards rest by 0.5-0.8 (slerp); the root held at its
    first frame (a still trunk); noise on the arm joints.

    Parameters
    ----------
    clip : Clip
    sides : iterable of HandSide
        Hands whose arms get the amplitude scaling.

    Returns
    -------
    hands : Clip
    truth : (n,) float
        Hand frame belonging to each body frame.
    """
    from usdhands.model.rotations import quat_conjugate, quat_multiply, quat_slerp

    n = clip.num_frames
    m = int(round(n * hand_ratio))
    u = np.linspace(0.0, 1.0, m)
    k = 2.0
    warp = (n - 1) * (u + warp_amount * np.sin(2 * np.pi * k * u) / (2 * np.pi * k))
    i0 = np.clip(np.floor(warp).astype(int), 0, n - 2)
    w = warp - i0
    J = clip.num_joints
    rot = quat_slerp(clip.rotations[i0], clip.rotations[i0 + 1], np.repeat(w[:, None], J, 1))
    tr = clip.translations[i0] * (1 - w)[:, None, None] + clip.translations[i0 + 1] * w[:, None, None]
    rng = np.random.default_rng(seed)
    scale = 0.65 + 0.15 * np.sin(2 * np.pi * 0.7 * u + 0.3)
    sk = clip.skeleton
    arm = [sk.index(n_) for s in sides for n_ in (s.shoulder, s.forearm) if n_ is not None]
    rest = sk.rest_rotations[arm]
    rel = quat_multiply(quat_conjugate(rest)[None], rot[:, arm])
    ident = np.broadcast_to([0.0, 0.0, 0.0, 1.0], rel.shape)
    rel = quat_slerp(ident, rel, np.repeat(scale[:, None], len(arm), 1))
    noise = euler_deg_to_quat(rng.normal(0.0, noise_deg, rel.shape[:-1] + (3,)))
    rot[:, arm] = quat_multiply(quat_multiply(rest[None], rel), noise)
    roots = np.nonzero(sk.parents < 0)[0]
    rot[:, roots] = clip.rotations[0, roots]
    tr[:, roots] = clip.translations[0, roots]
    truth = np.interp(np.arange(n), warp, np.arange(m))
    return Clip(sk, clip.fps, rot, tr, name="hand_session"), truth

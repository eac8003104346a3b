"""A small labelled gesture set built for the synthesis tests (ground truth they control).

A minimal Y-up rig in centimetres with identity rest rotations: Hips, Spine, and per
side an arm (upper arm along ±X), a hand and five three-joint fingers. Each gesture
type has its own stroke pose of the arm (shoulder, elbow, wrist angles) and its own
finger pose; a sample goes rest → stroke (preparation) → hold → rest (retraction)
with random variations of pose and timing.
"""

from __future__ import annotations

import numpy as np

from usdhands.model import Clip, HandMap, HandSide, Skeleton
from usdhands.model.rotations import euler_deg_to_quat

FINGERS = ("Thumb", "Index", "Middle", "Ring", "Pinky")
GESTURES = ("attention", "big", "doubt", "ok", "pp", "small", "turn", "wipe")
FPS = 30.0


def tiny_skeleton(hand_scale: float = 1.0, body_scale: float = 1.0, metacarpals: bool = False) -> Skeleton:
    """The rig; ``body_scale`` scales every bone; ``metacarpals`` adds ``<Finger>0`` joints (not the thumb)."""
    names, parents, trans = [], [], []

    def add(name, parent, t):
        names.append(name)
        parents.append(-1 if parent is None else names.index(parent))
        trans.append(np.asarray(t, dtype=float) * body_scale)

    add("Hips", None, (0, 100, 0))
    add("Spine", "Hips", (0, 40, 0))
    for side, sx in (("Left", 1.0), ("Right", -1.0)):
        add(f"{side}Arm", "Spine", (18 * sx, 5, 0))
        add(f"{side}ForeArm", f"{side}Arm", (28 * sx, 0, 0))
        add(f"{side}Hand", f"{side}ForeArm", (25 * sx, 0, 0))
        for fi, f in enumerate(FINGERS):
            base = np.array((3 * sx, -1, 4) if f == "Thumb" else (9 * sx, 0, 3 - 2 * (fi - 1)))
            parent = f"{side}Hand"
            if metacarpals and f != "Thumb":
                add(f"{side}Hand{f}0", parent, np.array((2 * sx, 0, base[2])) * hand_scale)
                parent, base = f"{side}Hand{f}0", base - np.array((2 * sx, 0, base[2]))
            add(f"{side}Hand{f}1", parent, base * hand_scale)
            add(f"{side}Hand{f}2", f"{side}Hand{f}1", np.array((4 * sx, 0, 0)) * hand_scale)
            add(f"{side}Hand{f}3", f"{side}Hand{f}2", np.array((3 * sx, 0, 0)) * hand_scale)
    J = len(names)
    rest_q = np.zeros((J, 4))
    rest_q[:, 3] = 1
    return Skeleton(names, np.array(parents), np.array(trans), rest_q, meters_per_unit=0.01, name="Tiny")


def tiny_handmap(metacarpals: bool = False) -> HandMap:
    sides = {}
    for side in ("left", "right"):
        S = side.capitalize()
        first = lambda f: (0, 1, 2, 3) if metacarpals and f != "Thumb" else (1, 2, 3)  # noqa: E731
        sides[side] = HandSide(side=side, wrist=f"{S}Hand", forearm=f"{S}ForeArm", shoulder=f"{S}Arm",
                               root="Hips",
                               fingers={f.lower(): tuple(f"{S}Hand{f}{i}" for i in first(f)) for f in FINGERS})
    return HandMap(**sides)


# arm pose: shoulder (x, y, z), elbow z-flex, wrist (x, y, z), degrees, left side
_REST_ARM = np.array([0.0, 0.0, -75.0, 0.0, 0.0, 0.0, 0.0])
_REST_FINGERS = np.array([10.0, 10.0, 10.0, 15.0, 15.0])  # curl per finger, degrees per joint


def _type_tables(seed: int = 7):
    rng = np.random.default_rng(seed)
    arms, fingers = {}, {}
    for g in GESTURES:
        arms[g] = np.array([rng.uniform(-50, 50), rng.uniform(-60, 30), rng.uniform(-40, 30),
                            rng.uniform(10, 100), rng.uniform(-70, 70), rng.uniform(-40, 40), rng.uniform(-40, 40)])
        fingers[g] = rng.uniform(0, 80, size=5)
    return arms, fingers


def _smooth(u):
    u = np.clip(u, 0, 1)
    return u * u * (3 - 2 * u)


def gesture_clip(skeleton: Skeleton, label: str, rng: np.random.Generator, with_fingers: bool = True) -> Clip:
    """One sample of gesture ``label``."""
    arms, fings = _type_tables()
    prep, hold, retr = rng.uniform(0.6, 0.9), rng.uniform(0.5, 0.9), rng.uniform(0.6, 0.9)
    lead, tail = 0.15, 0.15
    T = int(round((lead + prep + hold + retr + tail) * FPS))
    t = np.arange(T) / FPS
    w = _smooth((t - lead) / prep) - _smooth((t - lead - prep - hold) / retr)  # 0 rest .. 1 stroke
    J = skeleton.num_joints
    rot = np.zeros((T, J, 4))
    rot[..., 3] = 1
    for side, sgn in (("Left", 1.0), ("Right", -1.0)):
        arm = arms[label] + rng.normal(0, 6, size=7)
        finger = np.clip(fings[label] + rng.normal(0, 4, size=5), 0, 90)
        pose = _REST_ARM[None] * (1 - w[:, None]) + arm[None] * w[:, None]  # (T, 7)
        sh = pose[:, 0:3].copy()
        el = np.stack([np.zeros(T), np.zeros(T), pose[:, 3]], axis=1)
        wr = pose[:, 4:7].copy()
        if sgn < 0:  # mirror across x: (a, b, c) -> (a, -b, -c)
            sh[:, 1:] *= -1
            el[:, 1:] *= -1
            wr[:, 1:] *= -1
        rot[:, skeleton.index(f"{side}Arm")] = euler_deg_to_quat(sh)
        rot[:, skeleton.index(f"{side}ForeArm")] = euler_deg_to_quat(el)
        rot[:, skeleton.index(f"{side}Hand")] = euler_deg_to_quat(wr)
        if with_fingers:
            curl = _REST_FINGERS[None] * (1 - w[:, None]) + finger[None] * w[:, None]  # (T, 5)
            for fi, f in enumerate(FINGERS):
                e = np.zeros((T, 3))
                e[:, 2] = -curl[:, fi] * sgn
                for i in (1, 2, 3):
                    rot[:, skeleton.index(f"{side}Hand{f}{i}")] = euler_deg_to_quat(e)
    trans = np.broadcast_to(skeleton.rest_translations, (T, J, 3)).copy()
    trans[:, 0, 0] += 3 * np.sin(t)  # a little root motion
    return Clip(skeleton, FPS, rot, trans, name=f"{label}")


def gesture_set(repetitions: int = 6, seed: int = 0, skeleton: Skeleton | None = None) -> list[tuple[str, Clip]]:
    """``repetitions`` samples of each of :data:`GESTURES`, deterministic in ``seed``."""
    sk = skeleton or tiny_skeleton()
    rng = np.random.default_rng(seed)
    out = []
    for r in range(repetitions):
        for g in GESTURES:
            c = gesture_clip(sk, g, rng)
            out.append((g, c.replace(name=f"{g}_{r:02d}")))
    return out

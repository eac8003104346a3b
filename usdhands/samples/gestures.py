"""A labelled gesture database with ground-truth finger motion, generated.

The eight gesture types of Jörg, Hodgins and Safonova (2012, §4): attention, big,
doubt shrug, ok, palm presentation, small, turn and wipe. Each take starts with the
arms hanging relaxed, then runs through preparation and stroke (one fluent motion),
a post-stroke hold and the retraction back to rest, at 30 fps, 2 to 4 seconds long.
Takes of a type vary hand height, distance from the body, lateral placement, pacing,
amplitude and the exact hand orientation and finger pose, as the paper's recordings
did; a type is performed with one hand (the right) or both, as is natural for it.

What makes a type a type (right hand, in the frame of the hips):

================= =============================================== =================================
type              wrist motion and orientation                    fingers
================= =============================================== =================================
attention         raised high in front, fingers up, palm forward  index extended, others curled
big               both hands sweep from the centre wide outwards  open, spread
doubt_shrug       forearms out, palms up, shoulders lift          open, spread
ok                up in front at chest height, small down beat    thumb-index ring, others straight
palm_presentation forearm forward, palm up                        open, flat
small             small forward motion close to the body          loose half-curl, thumb near index
turn              circles in front, the wrist rolling             loose curl, rolling
wipe              horizontal palm-down sweep outwards             flat, together
================= =============================================== =================================

Everything is deterministic: the same ``seed`` gives the same clips, bit for bit.

Public API, used by tests and by the synthesis code:

- :func:`gesture_database` ``(seed=0) -> list[(label, Clip)]``, 64 takes
- :func:`gesture_take` ``(gesture, take, seed=0) -> Clip``
- :func:`conversation_clip` ``(seed=0) -> Clip`` (about 29 s of chained gestures)
- :func:`conversation_annotations` ``(seed=0) -> list[GestureSpan]``
- :func:`body_only` ``(clip) -> Clip`` (fingers frozen at rest)
- :func:`humanoid_skeleton` ``() -> Skeleton``
- :func:`wave_clip` ``() -> Clip`` (idle and a wave, for ``humanoid.usda``)
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from usdhands.model.clip import Clip
from usdhands.samples.hand_poses import GESTURE_TYPES, relaxed_pose, varied_pose
from usdhands.samples.humanoid import humanoid_skeleton
from usdhands.samples.motion import FPS, BodyIdle, HandKey, HandTrack, build_clip, mirror_key, rest_key

__all__ = [
    "GESTURE_TYPES", "TAKES_PER_TYPE", "TWO_HANDED", "GestureSpan", "gesture_database", "gesture_take",
    "gesture_hands", "conversation_clip", "conversation_annotations", "body_only", "humanoid_skeleton",
    "wave_clip", "FINGER_JOINT_PATTERN",
]

TAKES_PER_TYPE = 8
MIN_TAKE_S = 2.0  # a slow retraction rather than a take under 2 s

# Spread of the takes of a type: height, distance, lateral placement (multipliers of
# each type's own ranges, in cm per unit), and hand-orientation tilt (degrees, s.d.).
VARIATION = (1.7, 1.6, 2.0, 6.0)

# Which takes use both hands (the others use the right hand only).
TWO_HANDED: dict[str, tuple[int, ...]] = {
    "attention": (),
    "big": tuple(range(8)),
    "doubt_shrug": tuple(range(8)),
    "ok": (),
    "palm_presentation": (6, 7),
    "small": (),
    "turn": (4, 5, 6, 7),
    "wipe": (5, 6, 7),
}

# Short names of finger joints in common rigs (Mixamo, UE, Unity/VRM, generic): the
# joints body_only() freezes when no explicit list is given.
FINGER_JOINT_PATTERN = re.compile(r"(thumb|index|middle|ring|pinky|pinkie|little)", re.IGNORECASE)


@dataclass(frozen=True)
class GestureSpan:
    """One gesture of the conversation clip: its type, hands, and time span in seconds."""

    gesture: str
    hands: tuple[str, ...]
    start: float
    end: float


def _v(*x: float) -> np.ndarray:
    return np.array(x, dtype=np.float64)


@dataclass(frozen=True)
class _TakeParams:
    height: float  # -1..1
    distance: float  # -1..1
    lateral: float  # -1..1
    amplitude: float  # ~0.75..1.25
    pace: float  # duration factor ~0.85..1.3
    tilt: np.ndarray  # rotation vector (radians) applied to the hand orientation
    rng: np.random.Generator


def _take_params(gesture: str, take: int, seed: int) -> _TakeParams:
    """Stratified variation: each type covers the range of heights, distances and paces."""
    rng_type = np.random.default_rng([seed, 1000 + GESTURE_TYPES.index(gesture)])
    grid = np.linspace(-1.0, 1.0, TAKES_PER_TYPE)
    heights, dists, lats, paces = (rng_type.permutation(grid) for _ in range(4))
    rng = np.random.default_rng([seed, GESTURE_TYPES.index(gesture), take])
    k = take % TAKES_PER_TYPE
    return _TakeParams(
        height=float(VARIATION[0] * (heights[k] + rng.uniform(-0.1, 0.1))),
        distance=float(VARIATION[1] * (dists[k] + rng.uniform(-0.1, 0.1))),
        lateral=float(VARIATION[2] * (lats[k] + rng.uniform(-0.1, 0.1))),
        amplitude=float(rng.uniform(0.78, 1.22)),
        pace=float(1.075 + 0.2 * paces[k] + rng.uniform(-0.03, 0.03)),
        tilt=rng.normal(0.0, np.radians(VARIATION[3]), 3),
        rng=rng,
    )


def _key(t, pos, g, n, pose, stop=True, lift=0.0, tilt=None) -> HandKey:
    g, n = np.asarray(g, float), np.asarray(n, float)
    if tilt is not None:
        r = Rotation.from_rotvec(tilt)
        g, n = r.apply(g), r.apply(n)
    return HandKey(float(t), np.asarray(pos, float), g, n, np.asarray(pose, float), stop, float(lift))


def _blend(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    return (1 - w) * a + w * b


def _gesture_keys(gesture: str, p: _TakeParams, t0: float, end: HandKey,
                  relaxed: np.ndarray) -> tuple[list[HandKey], list, float]:
    """Right-hand keys of one gesture starting at ``t0`` (after the track's last key), ending at ``end``'s place.

    Returns the keys (``end`` moved to the gesture's end time), extra finger motion
    functions, and the end time.
    """
    H, D, L, A, pace, tilt = p.height, p.distance, p.lateral, p.amplitude, p.pace, p.tilt
    rng = p.rng
    pose = varied_pose(gesture, rng)
    mid = _blend(relaxed, pose, 0.55)
    prep, stroke, hold, retract = (x * pace for x in (0.5, 0.45, 0.8, 0.8))
    drift = lambda: rng.normal(0.0, 0.35, 3)
    small_tilt = lambda: tilt + rng.normal(0.0, np.radians(2.0), 3)
    hold_pose = lambda: pose + rng.normal(0.0, 1.0, (15, 3)) * [1, 0, 0.5]
    extras = []
    keys: list[HandKey] = []
    t = t0
    if gesture == "attention":
        top = _v(-19 + 2 * L, 56 + 6 * H, 20 + 4 * D)
        keys.append(_key(t + prep, _v(-20, 18 + 4 * H, 20 + 3 * D), (0, 0.7, 0.7), (0.7, -0.2, 0.4), mid, False, 2, tilt))
        keys.append(_key(t + prep + stroke * 0.6, top, (0, 1, 0.1), (0.15, -0.1, 1), pose, False, 5, tilt))
        t_s = t + prep + stroke
        end_pos = top + _v(0.3, 5 * A, 1)
        keys.append(_key(t_s, end_pos, (0.02, 1, 0.0), (0.2, 0, 1), pose, True, 6, tilt))
        keys.append(_key(t_s + hold, end_pos + drift(), (0.02, 1, 0.0), (0.2, 0, 1), hold_pose(), True, 6, small_tilt()))
        t_h = t_s + hold
    elif gesture == "big":
        keys.append(_key(t + prep, _v(-12, 15 + 4 * H, 24 + 3 * D), (0.2, 0.5, 1), (0.8, 0.1, 0.3), mid, False, 1, tilt))
        keys.append(_key(t + prep + stroke * 0.3, _v(-15, 24 + 6 * H, 28 + 4 * D), (0, 0.8, 0.6), (1, 0, 0.1), pose,
                         False, 2, tilt))
        t_s = t + prep + stroke * 1.2
        end_pos = _v(-44 * A - 3 * L, 28 + 7 * H, 24 + 4 * D)
        keys.append(_key(t_s, end_pos, (-0.35, 0.55, 0.8), (0.8, 0, 0.6), pose, True, 5, tilt))
        keys.append(_key(t_s + hold, end_pos + drift(), (-0.35, 0.55, 0.8), (0.8, 0, 0.6), hold_pose(), True, 5,
                         small_tilt()))
        t_h = t_s + hold
    elif gesture == "doubt_shrug":
        keys.append(_key(t + prep * 0.9, _v(-24, -2 + 2 * H, 10 + 2 * D), (-0.3, -0.5, 0.8), (0.5, 0.5, 0), mid, False,
                         5 * A, tilt))
        t_s = t + prep + stroke * 0.7
        end_pos = _v(-33 - 3 * A - 2 * L, 3 + 5 * H, 18 + 4 * D)
        keys.append(_key(t_s, end_pos, (-0.75, 0.05, 0.6), (-0.2, 1, 0.05), pose, True, 12 * A, tilt))
        keys.append(_key(t_s + hold, end_pos + drift(), (-0.75, 0.05, 0.6), (-0.2, 1, 0.05), hold_pose(), True,
                         11 * A, small_tilt()))
        t_h = t_s + hold
    elif gesture == "ok":
        beat = _v(-16 + 2 * L, 31 + 6 * H, 30 + 4 * D)
        keys.append(_key(t + prep, _v(-18, 12 + 4 * H, 20 + 3 * D), (0.1, 0.4, 1), (0.9, 0.1, 0.2), mid, False, 1, tilt))
        keys.append(_key(t + prep + stroke * 0.5, beat, (0.2, 0.95, 0.1), (0.45, 0, 0.9), pose, False, 2, tilt))
        t_s = t + prep + stroke
        end_pos = beat + _v(0.5, -4 * A, 1)
        keys.append(_key(t_s, end_pos, (0.2, 0.95, 0.15), (0.45, -0.05, 0.9), pose, True, 2, tilt))
        keys.append(_key(t_s + hold, end_pos + drift(), (0.2, 0.95, 0.15), (0.45, -0.05, 0.9), hold_pose(), True, 2,
                         small_tilt()))
        t_h = t_s + hold
    elif gesture == "palm_presentation":
        keys.append(_key(t + prep, _v(-21, 2 * H, 16 + 3 * D), (-0.1, -0.2, 1), (0.8, 0.5, 0), mid, False, 0, tilt))
        t_s = t + prep + stroke
        end_pos = _v(-24 - 3 * A + 2 * L, 8 + 5 * H, 38 + 5 * D)
        keys.append(_key(t_s, end_pos, (-0.3, 0.1, 1), (0.15, 1, 0), pose, True, 1, tilt))
        keys.append(_key(t_s + hold, end_pos + drift(), (-0.3, 0.1, 1), (0.15, 1, 0), hold_pose(), True, 1,
                         small_tilt()))
        t_h = t_s + hold
    elif gesture == "small":
        s0 = _v(-14 + L, 12 + 4 * H, 17 + 3 * D)
        keys.append(_key(t + prep * 0.8, _v(-17, 4 + 3 * H, 14 + 2 * D), (0.2, -0.3, 1), (1, 0, 0), mid, False, 0, tilt))
        keys.append(_key(t + prep, s0, (0.25, 0, 1), (1, 0.2, -0.1), pose, False, 0, tilt))
        t_s = t + prep + stroke * 0.8
        end_pos = s0 + _v(0.5, 0.5, 6 * A)
        keys.append(_key(t_s, end_pos, (0.3, 0.1, 1), (1, 0.3, -0.2), pose, True, 0, tilt))
        keys.append(_key(t_s + hold, end_pos + drift(), (0.3, 0.1, 1), (1, 0.3, -0.2), hold_pose(), True, 0,
                         small_tilt()))
        t_h = t_s + hold
    elif gesture == "turn":
        c = _v(-20 + 2 * L, 24 + 5 * H, 34 + 4 * D)
        r = 6.5 * A
        turns = 1.5 if (rng.uniform() < 0.5 or pace > 1.15) else 2.0
        t_prep = t + prep
        keys.append(_key(t + prep * 0.6, _v(-19, 6 + 3 * H, 18 + 3 * D), (0.1, 0.1, 1), (0.9, 0.3, 0), mid, False, 0,
                         tilt))
        n_keys = int(turns * 8)
        period = 0.72 * pace
        theta_of = lambda tt: 2 * np.pi * (tt - t_prep) / period
        g0, n0 = _v(0.15, 0.35, 1), _v(0.8, 0.5, 0.1)
        for i in range(n_keys + 1):
            th = 2 * np.pi * i / 8
            roll = Rotation.from_rotvec([np.radians(25) * np.sin(th), 0, 0])
            pos = c + _v(0, r * np.cos(th), r * np.sin(th))
            keys.append(_key(t_prep + i * period / 8, pos, roll.apply(g0), roll.apply(n0), pose, i == n_keys, 2, tilt))
        t_s = t_prep + n_keys * period / 8
        end_roll = Rotation.from_rotvec([np.radians(25) * np.sin(2 * np.pi * n_keys / 8), 0, 0])
        hold = 0.35 * pace
        keys.append(_key(t_s + hold, keys[-1].pos + drift() * 0.5, end_roll.apply(g0), end_roll.apply(n0), hold_pose(),
                         True, 2, small_tilt()))
        t_h = t_s + hold

        def wave(times, t_a=t_prep, t_b=t_s, amp=10.0 * A):
            w = np.clip((times - t_a) / 0.25, 0, 1) * np.clip((t_b - times) / 0.25, 0, 1)
            out = np.zeros((len(times), 15, 3))
            for f in range(1, 5):  # index .. pinky roll after one another
                phase = theta_of(times) - 0.7 * f
                out[:, 3 * f:3 * f + 3, 0] = (amp * w * np.sin(phase))[:, None] * [1.0, 0.8, 0.5]
            out[:, 0:3, 0] = (0.4 * amp * w * np.sin(theta_of(times)))[:, None]
            return out
        extras.append(wave)
    elif gesture == "wipe":
        s0 = _v(-2 + L, 13 + 4 * H, 33 + 4 * D)
        keys.append(_key(t + prep * 0.8, _v(-10, 8 + 3 * H, 24 + 3 * D), (0.3, -0.2, 1), (0.3, -1, 0), mid, False, 1,
                         tilt))
        keys.append(_key(t + prep, s0, (0.4, 0, 1), (0, -1, 0), pose, False, 1, tilt))
        t_s = t + prep + stroke * 1.1
        end_pos = _v(-40 * A + 2 * L, 12 + 4 * H, 28 + 4 * D)
        keys.append(_key(t_s, end_pos, (-0.3, 0, 1), (0, -1, 0.05), pose, True, 2, tilt))
        hold = 0.45 * pace
        keys.append(_key(t_s + hold, end_pos + drift(), (-0.3, 0, 1), (0, -1, 0.05), hold_pose(), True, 2, small_tilt()))
        t_h = t_s + hold
    else:
        raise ValueError(f"Unknown gesture type {gesture!r}; expected one of {GESTURE_TYPES}")
    t_end = max(t_h + retract, t0 + MIN_TAKE_S)
    keys.append(_retraction_via(keys[-1], end, t_h + 0.45 * (t_end - t_h)))
    keys.append(HandKey(t_end, end.pos, end.fingers_dir, end.palm, end.pose, True, end.shoulder_lift))
    return keys, extras, t_end


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _retraction_via(hold: HandKey, end: HandKey, t: float) -> HandKey:
    """Halfway down from the hold: the hand passes in front, fingers forward, palm turning in.

    Fixes the way the hand turns between orientations up to 180° apart (fingers up,
    palm forward, to fingers down, palm in), as a person's hand does, not the other
    way round through the arm.
    """
    g = _unit(_unit(hold.fingers_dir) + _unit(end.fingers_dir) + _v(0, 0, 0.8))
    n = _unit(hold.palm) + _unit(end.palm)
    if np.linalg.norm(n) < 0.3:
        n = end.palm
    pos = 0.5 * (hold.pos + end.pos) + _v(0, 0, 3.0)
    return HandKey(t, pos, g, _unit(n), 0.5 * (hold.pose + end.pose), False,
                   0.5 * (hold.shoulder_lift + end.shoulder_lift))


def _micro_motion(rng: np.random.Generator, amp: float = 0.8):
    """Smooth small finger motion (degrees) so that holds are never frozen."""
    freqs = rng.uniform(0.3, 1.2, (3, 15))
    phases = rng.uniform(0, 2 * np.pi, (3, 15))

    def f(times):
        out = np.zeros((len(times), 15, 3))
        for k in range(3):
            out[:, :, 0] += amp / 3 * np.sin(2 * np.pi * freqs[k] * times[:, None] + phases[k])
        return out
    return f


def _arm_style(rng: np.random.Generator) -> dict:
    """How this take holds its elbow and splits the forearm twist (varies from take to take)."""
    return {"elbow_out": float(rng.uniform(-0.35, 0.45)), "elbow_back": float(rng.uniform(-0.3, 0.4)),
            "twist_share": float(rng.uniform(0.6, 0.95))}


def _mirror_track_keys(keys: list[HandKey], rng: np.random.Generator, delay: float) -> list[HandKey]:
    """The left hand's keys for a two-handed gesture: mirrored, slightly smaller and later."""
    out = []
    scale = rng.uniform(0.88, 1.0)
    for i, k in enumerate(keys):
        m = mirror_key(k)
        if 0 < i < len(keys) - 1:
            m.t += delay
            m.pos = m.pos * [scale, 1, 1] + rng.normal(0, 0.5, 3)
            m.pose = m.pose + rng.normal(0, 1.5, (15, 3)) * [1, 0, 0.5]
        out.append(m)
    return out


def gesture_hands(gesture: str, take: int) -> tuple[str, ...]:
    """The hands a take uses: ``("right",)`` or ``("left", "right")``."""
    if gesture not in GESTURE_TYPES:
        raise ValueError(f"Unknown gesture type {gesture!r}; expected one of {GESTURE_TYPES}")
    return ("left", "right") if take in TWO_HANDED[gesture] else ("right",)


def gesture_take(gesture: str, take: int, seed: int = 0) -> Clip:
    """One take of a gesture type, with ground-truth finger motion.

    Parameters
    ----------
    gesture : str
        One of :data:`GESTURE_TYPES`.
    take : int
        0 to 7 (:data:`TAKES_PER_TYPE`); larger numbers give further variations.
    seed : int

    Returns
    -------
    Clip
        Named ``"<gesture>_<take>"`` (take as two digits), 30 fps, 2 to 4 seconds, on
        :func:`humanoid_skeleton`.
    """
    if gesture not in GESTURE_TYPES:
        raise ValueError(f"Unknown gesture type {gesture!r}; expected one of {GESTURE_TYPES}")
    if take < 0:
        raise ValueError(f"Expected take >= 0, got {take}")
    p = _take_params(gesture, take, seed)
    rng = p.rng
    relaxed = relaxed_pose() + rng.normal(0, 2.0, (15, 3)) * [1, 0, 0.5]
    start = rest_key(0.0, "right", relaxed, rng.normal(0, 0.6, 3))
    end = rest_key(0.0, "right", relaxed, rng.normal(0, 0.6, 3))
    keys, extras, t_end = _gesture_keys(gesture, p, 0.0, end, relaxed)
    right = HandTrack("right", [start] + keys, extras + [_micro_motion(rng)], **_arm_style(rng))
    if "left" in gesture_hands(gesture, take):
        lkeys = _mirror_track_keys([start] + keys, rng, delay=float(rng.integers(0, 3)) / FPS)
        left = HandTrack("left", lkeys, extras + [_micro_motion(rng)], **_arm_style(rng))
    else:
        lpose = relaxed_pose() + rng.normal(0, 2.0, (15, 3)) * [1, 0, 0.5]
        left = HandTrack("left", [rest_key(0.0, "left", lpose), rest_key(t_end, "left", lpose)],
                         [_micro_motion(rng)])
    idle = BodyIdle.random(rng)
    return build_clip(humanoid_skeleton(), [left, right], t_end, idle, name=f"{gesture}_{take:02d}")


def gesture_database(seed: int = 0, takes: int = TAKES_PER_TYPE) -> list[tuple[str, Clip]]:
    """Every take of every gesture type: ``[(label, clip), ...]``, 8 x ``takes`` entries.

    Labels are the type names of :data:`GESTURE_TYPES` (``"doubt_shrug"``,
    ``"palm_presentation"``: no spaces); clips are named ``"<label>_<take:02d>"``.
    """
    return [(g, gesture_take(g, k, seed)) for g in GESTURE_TYPES for k in range(takes)]


# ------------------------------------------------------------------ conversation

_CONVERSATION = [
    ("palm_presentation", ("right",)), ("small", ("right",)), ("turn", ("right",)), ("ok", ("right",)),
    ("big", ("left", "right")), ("wipe", ("right",)), ("doubt_shrug", ("left", "right")),
    ("attention", ("right",)), ("small", ("left",)),
    ("turn", ("left", "right")),
]


def _low_rest_key(t: float, relaxed: np.ndarray) -> HandKey:
    """Between gestures: the hand low in front of the body, not all the way down."""
    return _key(t, _v(-11, 0, 14), (0.35, -0.6, 0.7), (0.9, 0.3, 0.1), relaxed, True, 0)


def _conversation_plan(seed: int):
    rng = np.random.default_rng([seed, 7777])
    relaxed = relaxed_pose()
    tracks = {"left": [rest_key(0.0, "left", relaxed)], "right": [rest_key(0.0, "right", relaxed)]}
    extras = {"left": [], "right": []}
    spans = []
    t = 0.0
    for i, (gesture, hands) in enumerate(_CONVERSATION):
        p = _take_params(gesture, 100 + i, seed)
        for side in ("left", "right"):  # hold still through the pause before the gesture
            k = tracks[side][-1]
            if t - k.t > 1e-3:
                tracks[side].append(HandKey(t, k.pos, k.fingers_dir, k.palm, k.pose, True, k.shoulder_lift))
        last = tracks["right"][-1] if "right" in hands else mirror_key(tracks["left"][-1])
        end = _low_rest_key(0.0, relaxed) if rng.uniform() < 0.6 else rest_key(0.0, "right", relaxed)
        keys, ex, t_end = _gesture_keys(gesture, p, t, end, relaxed)
        if "right" in hands:
            tracks["right"] += keys
            extras["right"] += ex
        if "left" in hands:
            lk = [mirror_key(k) for k in keys] if "right" not in hands else _mirror_track_keys(
                [last] + keys, rng, 1.0 / FPS)[1:]
            tracks["left"] += lk
            extras["left"] += ex
        for side in ("left", "right"):  # an idle hand stays where it is
            if side not in hands:
                k = tracks[side][-1]
                tracks[side].append(HandKey(t_end, k.pos, k.fingers_dir, k.palm, k.pose, True, k.shoulder_lift))
        spans.append(GestureSpan(gesture, tuple(hands), round(t, 4), round(t_end, 4)))
        t = t_end + float(rng.uniform(0.15, 0.6))  # a pause before the next gesture
    for side in ("left", "right"):
        k = tracks[side][-1]
        tracks[side].append(HandKey(t, k.pos, k.fingers_dir, k.palm, k.pose, True, k.shoulder_lift))
    return tracks, extras, spans, t, rng


def conversation_clip(seed: int = 0) -> Clip:
    """About 29 seconds of conversational gesturing: ten gestures chained, ground-truth fingers.

    Gestures follow one another with short pauses, returning to rest or only to a low
    position in front of the body; :func:`conversation_annotations` gives each
    gesture's type, hands and time span.
    """
    tracks, extras, _, duration, rng = _conversation_plan(seed)
    ht = [HandTrack(s, tracks[s], extras[s] + [_micro_motion(rng)]) for s in ("left", "right")]
    return build_clip(humanoid_skeleton(), ht, duration, BodyIdle.random(rng), name="conversation")


def conversation_annotations(seed: int = 0) -> list[GestureSpan]:
    """The gestures of :func:`conversation_clip`: type, hands and seconds from the clip start."""
    return _conversation_plan(seed)[2]


# ------------------------------------------------------------------ wave

def wave_clip(seed: int = 0) -> Clip:
    """A short idle then a friendly wave of the right hand (about 3.3 s), for ``humanoid.usda``."""
    rng = np.random.default_rng([seed, 4242])
    relaxed = relaxed_pose()
    open_hand = varied_pose("big", rng, 0.3)
    up = _v(-30, 52, 12)
    keys = [rest_key(0.0, "right", relaxed), rest_key(0.5, "right", relaxed)]
    keys.append(_key(1.0, _v(-28, 20, 15), (-0.1, 0.6, 0.8), (0.4, 0, 1), _blend(relaxed, open_hand, 0.6), False, 3))
    t = 1.3
    keys.append(_key(t, up, (-0.15, 1, 0), (0, 0, 1), open_hand, True, 6))
    for i in range(4):
        t += 0.3
        side = -1 if i % 2 == 0 else 1
        keys.append(_key(t, up + _v(4 * side, -1, 0), (0.45 * side - 0.15, 1, 0), (0, 0, 1), open_hand, True, 6))
    end = rest_key(t + 0.8, "right", relaxed)
    keys.append(_retraction_via(keys[-1], end, t + 0.35))
    keys.append(end)
    tracks = [HandTrack("right", keys, [_micro_motion(rng)]),
              HandTrack("left", [rest_key(0.0, "left", relaxed), rest_key(t + 0.8, "left", relaxed)],
                        [_micro_motion(rng)])]
    return build_clip(humanoid_skeleton(), tracks, t + 0.8, BodyIdle.random(rng), name="idle_wave")


# ------------------------------------------------------------------ body only

def body_only(clip: Clip, finger_joints: list[int] | None = None) -> Clip:
    """The clip with its fingers frozen at their rest rotations: an input for synthesis.

    Parameters
    ----------
    clip : Clip
    finger_joints : list of int, optional
        Joints to freeze; by default every joint whose short name names a finger
        (:data:`FINGER_JOINT_PATTERN`: thumb, index, middle, ring, pinky).

    Returns
    -------
    Clip
        Named ``"<name>_bodyonly"``; every other joint's channels are unchanged.
    """
    sk = clip.skeleton
    if finger_joints is None:
        finger_joints = [j for j, n in enumerate(sk.short_names) if FINGER_JOINT_PATTERN.search(n)]
    if not finger_joints:
        raise ValueError(f"No finger joints found in skeleton {sk.name!r}")
    rot = np.array(clip.rotations)
    rot[:, finger_joints] = sk.rest_rotations[finger_joints]
    trans = np.array(clip.translations)
    trans[:, finger_joints] = sk.rest_translations[finger_joints]
    return clip.replace(rotations=rot, translations=trans, name=f"{clip.name}_bodyonly")


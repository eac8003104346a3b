"""Collision correction of finger motion with a no-penetration guarantee (seed 002, §3.3 and §3.5).

For each finger chain of each hand:

1. Broad phase: frames whose capsules' bounding box is farther from every collider's
   than the radius plus the margin are clear and cost nothing.
2. Detection: the clearance search along each capsule axis
   (:func:`~usdhands.algorithms.interaction.clearance.axis_clearance`) finds the frames
   where the chain penetrates. A chain that never does is left bit-for-bit unchanged.
3. The chain's whole curve (every frame, not only around the contacts) is smoothed by
   the RTS Kalman smoother (the paper's smoothing step, against capture noise and the
   correction's own jitter) and clamped into the joint limits.
4. IK: per frame, the least opening of that smoothed pose along the chain's path that
   clears every collider (:meth:`~usdhands.algorithms.interaction.ik.ChainPoser.least_opening`),
   by bisection with the clearance test, on every other frame (a frame between tries its
   neighbours' larger bound first, :data:`BISECT_EVERY`): the bound. With ``ik: ccd`` the path first goes to
   the pose cyclic coordinate descent finds (:meth:`~usdhands.algorithms.interaction.ik.ChainPoser.ccd`).
5. The opening is smoothed with the bound as a constraint
   (:func:`~usdhands.algorithms.interaction.smoothing.bounded_smooth`), so it never
   falls below what clears; every frame opened past its bound is tested again, one that
   fails (where opening further touches something else) gets an upper bound (the clear
   opening below) and the opening is smoothed again; one still failing takes its bound,
   which was tested.

So every changed frame passed the clearance test, whose resolution bounds what can slip
through: nothing penetrates deeper than half of ``tolerance_mm`` minus the margin.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from usdhands.algorithms.interaction.clearance import axis_clearance
from usdhands.algorithms.interaction.finger_geometry import FingerChain, InteractionConfig, finger_chains
from usdhands.algorithms.interaction.ik import ChainGroup, ChainPoser, group_stride
from usdhands.algorithms.interaction.known_distances import ChainDistances
from usdhands.algorithms.interaction.palm import palm_depth_mm
from usdhands.algorithms.interaction.posing import FingersPosed, chain_reach, reachable_frames
from usdhands.algorithms.interaction.smoothing import bounded_smooth, rts_smooth, smoothness_weight
from usdhands.model.clip import Clip
from usdhands.model.finger_dofs import finger_curves
from usdhands.model.handmap import HandMap
from usdhands.model.rotations import quat_angle_deg

__all__ = ["CorrectionReport", "correct_clip", "chain_posers", "penetration_depth_mm", "finger_jitter",
           "finger_angles", "rest_branch", "with_fingers_posed"]


@dataclass
class CorrectionReport:
    """What a correction did.

    Attributes
    ----------
    penetration_before_mm, penetration_after_mm : (T,) float
        Deepest penetration of a finger or the palm (:mod:`~usdhands.algorithms.interaction.palm`)
        into any collider per frame, mm (0 where clear), measured along the capsule axes to
        0.05 mm (an upper bound).
    frames_corrected : int
        Frames where the IK pushed some finger out (the smoothing also changes the other
        frames of a corrected finger, by less).
    jitter_before, jitter_after : float
        Mean absolute angular acceleration of the finger curves, deg/s².
    max_change_deg : float
        Largest change of a finger joint's rotation, degrees.
    unresolved : list of (str, int)
        Chain and frame where even the open finger touches (the palm or wrist is inside a prop),
        and, with the report measured, ``("left palm", frame)`` where the palm itself is in a
        collider deeper than half of ``tolerance_mm`` (the correction never moves it).
    chains_corrected : list of str
    """

    penetration_before_mm: np.ndarray
    penetration_after_mm: np.ndarray
    frames_corrected: int
    jitter_before: float
    jitter_after: float
    max_change_deg: float
    unresolved: list = field(default_factory=list)
    chains_corrected: list = field(default_factory=list)

    @staticmethod
    def _stats(depth: np.ndarray) -> dict:
        hit = depth > 0
        return {"max": float(depth.max(initial=0.0)), "mean": float(depth[hit].mean()) if hit.any() else 0.0,
                "frames": int(hit.sum())}

    def to_dict(self) -> dict:
        """The summary with the keys of ``usdhands correct --json``."""
        return {
            "penetration_before_mm": self._stats(self.penetration_before_mm),
            "penetration_after_mm": self._stats(self.penetration_after_mm),
            "frames_corrected": int(self.frames_corrected),
            "jitter_before": float(self.jitter_before),
            "jitter_after": float(self.jitter_after),
            "max_change_deg": float(self.max_change_deg),
        }


def with_fingers_posed(clip: Clip, handmap: HandMap, world: np.ndarray | None) -> np.ndarray:
    """World transforms ``(T, J, 4, 4)`` of ``clip``, reusing ``world`` for every joint that is neither
    a finger joint of ``handmap`` nor below one: the finger joints and their descendants are posed
    from the clip's own local transforms (a clip that differs from the one ``world`` was computed
    for only in its fingers, such as a synthesized or corrected one). ``None``: full forward kinematics."""
    if world is None:
        return clip.world_xforms()
    from usdhands.model.rotations import trs_to_xform

    parents = clip.skeleton.parents
    fingers = {clip.skeleton.index(j) for hand in handmap.sides for j in hand.finger_joints}
    dirty = np.zeros(clip.num_joints, dtype=bool)
    for j in range(clip.num_joints):  # parents come before children
        dirty[j] = j in fingers or (parents[j] >= 0 and dirty[parents[j]])
    js = np.nonzero(dirty)[0]
    out = np.array(world)
    if len(js):
        local = trs_to_xform(clip.translations[:, js], clip.rotations[:, js], clip.scales[:, js])
        for i, j in enumerate(js):
            p = int(parents[j])
            out[:, j] = local[:, i] if p < 0 else out[:, p] @ local[:, i]
    return out


def chain_posers(clip: Clip, handmap: HandMap, config: InteractionConfig,
                 world: np.ndarray | None = None) -> list[ChainPoser]:
    """A :class:`ChainPoser` for every finger chain of every hand of ``clip`` (``world``: the clip's
    world transforms ``(T, J, 4, 4)`` when the caller has them)."""
    posed = FingersPosed(clip, None, world)
    return [_poser(clip, chain, posed, given=True) for hand in handmap.sides
            for chain in finger_chains(clip.skeleton, hand, config)]


def _poser(clip: Clip, chain: FingerChain, posed: FingersPosed, given: bool) -> ChainPoser:
    """The chain's :class:`ChainPoser` on the world transforms ``posed`` gives, with its joints' positions
    in the pose given at every frame (``given``) or none (:func:`_near_posed` poses them where needed)."""
    js = list(chain.joints)
    parent = int(clip.skeleton.parents[js[0]])
    pw = posed.at([parent])[0] if parent >= 0 else np.broadcast_to(np.eye(4), (clip.num_frames, 4, 4))
    return ChainPoser(chain, np.ascontiguousarray(pw), np.asarray(clip.translations[:, js]),
                      np.asarray(clip.scales[:, js]), np.asarray(clip.skeleton.rest_rotations[js]),
                      given_points=_given_points(chain, posed) if given else None,
                      between=_between(clip, chain, posed))


def _given_points(chain: FingerChain, posed: FingersPosed, frames: np.ndarray | None = None) -> np.ndarray:
    """The chain's joint positions and tip in the pose given, world, ``(K, n + 1, 3)`` at ``frames``
    (all by default)."""
    ws = posed.at(chain.joints, frames)
    last = ws[-1]
    tip = last[:, :3, :3] @ chain.tip_offset + last[:, :3, 3]
    return np.concatenate([np.stack([w[:, :3, 3] for w in ws], axis=1), tip[:, None]], axis=1)


def _between(clip: Clip, chain: FingerChain, posed: FingersPosed) -> np.ndarray | None:
    """The transforms from each chain joint to the next one's parent where that parent is a joint
    below it rather than itself, ``(T, n, 4, 4)`` (None when every joint is the child of the one before).

    Raises
    ------
    UnsupportedRigError
        A chain joint that is not below the one before it (a flat rig): turning a finger joint
        would not move the rest of the finger.
    """
    from usdhands.errors import UnsupportedRigError

    sk = clip.skeleton
    js = list(chain.joints)
    out = None
    for k in range(1, len(js)):
        p = int(sk.parents[js[k]])
        if p == js[k - 1]:
            continue
        a = p
        while a >= 0 and a != js[k - 1]:
            a = int(sk.parents[a])
        if a < 0:
            raise UnsupportedRigError(
                f"the {chain.name} finger's joints are not a chain: '{sk.joint_names[js[k]]}' is not below "
                f"'{sk.joint_names[js[k - 1]]}', so turning one would not move the next; correcting fingers "
                f"needs each finger joint parented under the one before")
        if out is None:
            out = np.broadcast_to(np.eye(4), (clip.num_frames, len(js), 4, 4)).copy()
        before, parent = posed.at([js[k - 1], p])
        out[:, k] = np.linalg.inv(before) @ parent
    return out


def _reachable(clip: Clip, poser: ChainPoser, colliders, reach: float) -> np.ndarray:
    """Frames ``(K,)`` where some pose of the chain could come within ``reach`` (radius added) of some
    collider's box: every other frame is clear in every pose (:func:`~usdhands.algorithms.interaction.posing.chain_reach`)."""
    chain = poser.chain
    radius = chain_reach(clip, chain.joints, chain.tip_offset, poser.parent_world) + float(chain.radii.max()) + reach
    return reachable_frames(colliders, poser.parent_world[:, :3, 3], radius)


def _near_posed(poser: ChainPoser, posed: FingersPosed, colliders, reach: float,
                candidates: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
    """:func:`_near_frames` of the chain as ``posed`` gives it, posed only at ``candidates`` (frames that
    include every frame :func:`_reachable` with the same or a smaller ``reach`` finds; no other frame can
    be near); ``points``: the chain's :func:`_given_points` at ``candidates`` when the caller has them."""
    if len(candidates) == 0:
        return candidates
    pts = _given_points(poser.chain, posed, candidates) if points is None else points
    r = float(poser.chain.radii.max()) + reach
    return candidates[colliders.bbox_gap(candidates, pts.min(axis=1) - r, pts.max(axis=1) + r) <= 0]


def _near_frames(poser: ChainPoser, colliders, reach: float) -> np.ndarray:
    """Frames where the chain, as given, comes within ``reach`` (radius + margin added) of some collider's box."""
    pts = poser.given_points
    frames = np.arange(len(pts))
    r = float(poser.chain.radii.max()) + reach
    lo = pts.min(axis=1) - r
    hi = pts.max(axis=1) + r
    return frames[colliders.bbox_gap(frames, lo, hi) <= 0]


def rest_branch(angles: np.ndarray) -> np.ndarray:
    """Euler triples ``(..., 3)`` degrees on the branch nearest the rest pose, in ``[-180, 180)``.

    A rotation has two Tait-Bryan triples, ``(a, b, c)`` and ``(a + 180, 180 - b, c + 180)``;
    the conversion returns the one with ``|b| <= 90``, so a finger flexed past 90 degrees about
    the middle axis (a captured rig whose flexion is the order's middle angle) flips between
    them from frame to frame. Each triple becomes the one with the smaller ``sum(|angle|)``.
    """
    e = (np.asarray(angles, dtype=np.float64) + 180.0) % 360.0 - 180.0
    alt = e + np.array([180.0, 0.0, 180.0])
    alt[..., 1] = 180.0 - e[..., 1]
    alt = (alt + 180.0) % 360.0 - 180.0
    flip = np.abs(alt).sum(axis=-1) < np.abs(e).sum(axis=-1)
    return np.where(flip[..., None], alt, e)


def finger_angles(clip: Clip, joints) -> np.ndarray:
    """Euler angles of ``joints`` relative to rest, ``(T, n, 3)`` degrees in ``[-180, 180)``, on the
    branch nearest the rest pose (:func:`rest_branch`).

    Finger joints stay within about 130 degrees of rest on every axis, so angles are kept in
    ``[-180, 180)`` rather than unwrapped over time (a capture glitch that crosses 180 would
    otherwise shift every later frame by 360 and out of the joint limits).
    """
    T, n = clip.num_frames, len(joints)
    return rest_branch(finger_curves(clip, joints).values.reshape(T, n, 3))


def _chain_angles(clip: Clip, chain: FingerChain) -> np.ndarray:
    return finger_angles(clip, chain.joints)


def penetration_depth_mm(clip: Clip, posers: list[ChainPoser], colliders, resolution_mm: float = 0.05) -> np.ndarray:
    """Deepest penetration of any finger capsule into any collider per frame, ``(T,)`` mm.

    An upper bound within ``resolution_mm`` of the exact depth (the axis search's lower bound).
    """
    depth = np.zeros(clip.num_frames)
    for poser in posers:
        np.maximum(depth, _chain_depth_mm(clip, poser, colliders, resolution_mm), out=depth)
    return depth


def _chain_depth_mm(clip: Clip, poser: ChainPoser, colliders, resolution_mm: float = 0.05) -> np.ndarray:
    """Deepest penetration of one chain's capsules per frame, ``(T,)`` mm (:func:`penetration_depth_mm`):
    :func:`_group_depth_mm` of the chain alone at its :func:`_near_frames`."""
    frames = _near_frames(poser, colliders, 0.0)
    angles = _chain_angles(clip, poser.chain)[frames] if len(frames) else None
    mm = 0.001 / clip.skeleton.meters_per_unit
    group = ChainGroup([poser], group_stride(clip.num_frames, 1))
    return _group_depth_mm(group, colliders, {0: (frames, angles)}, None, mm, clip.num_frames, resolution_mm)[0]


def _group_depth_mm(group: ChainGroup, colliders, items: dict, known: ChainDistances | None, mm: float, T: int,
                    resolution_mm: float = 0.05) -> dict:
    """:func:`_chain_depth_mm` of the chains of ``group`` in one search: ``items`` maps a chain's index to
    its near frames ``(K,)`` and angles there ``(K, n, 3)``; ``known``: the group's memo (rows
    ``c * stride + frame``, or None: nothing remembered); ``mm``: clip units per mm. Returns chain index ->
    ``(T,)`` mm."""
    out = {c: np.zeros(T) for c in items}
    live = [c for c, (frames, _) in items.items() if len(frames)]
    if not live:
        return out
    vf, real, aa, bb, need = [], [], [], [], []
    for c in live:
        frames, angles = items[c]
        a, b = group.posers[c].capsules(frames, angles)
        vf.append(group.frames_of(c, frames))
        real.append(frames)
        aa.append(a)
        bb.append(b)
        need.append(np.tile(group.posers[c].chain.radii, (len(frames), 1)))
    need_all, a, b, real = np.concatenate(need), np.concatenate(aa), np.concatenate(bb), np.concatenate(real)
    if known is None:
        K, n = need_all.shape
        lower, _ = axis_clearance(colliders, np.repeat(real, n), a.reshape(-1, 3), b.reshape(-1, 3),
                                  need_all.reshape(-1), resolution_mm * mm, find_depth=True)
        lower = lower.reshape(K, n)
    else:
        lower, _ = known.axis_bounds(colliders, np.concatenate(vf), real, a, b, need_all, resolution_mm * mm,
                                     find_depth=True)
    depth = np.maximum(need_all - lower, 0.0).max(axis=1) / mm
    for c, part in zip(live, np.split(depth, np.cumsum([len(items[c][0]) for c in live])[:-1])):
        out[c][items[c][0]] = part
    return out


def finger_jitter(clip: Clip, joints: list[int]) -> float:
    """Mean absolute angular acceleration of the finger curves of ``joints``, deg/s² (Euler
    curves as :func:`finger_angles` reads them)."""
    if clip.num_frames < 3 or not joints:
        return 0.0
    return float(_jitter_sums(clip, joints).sum() / ((clip.num_frames - 2) * 3 * len(joints)) * clip.fps ** 2)


def _jitter_sums(clip: Clip, joints: list[int]) -> np.ndarray:
    """Sum over frames and axes of the absolute second differences of each joint's curves, ``(len(joints),)``."""
    return _jitter_sums_of(finger_angles(clip, joints))


def _jitter_sums_of(v: np.ndarray) -> np.ndarray:
    """:func:`_jitter_sums` of the joints' :func:`finger_angles` ``v`` ``(T, n, 3)``."""
    return np.abs(np.diff(v, 2, axis=0)).sum(axis=(0, 2))


#: How much more the opening is held to its target where the input penetrates than where it is clear
#: (the fingers that penetrated end touching; the smoothing's anticipation goes before the contact).
FIT_IN_CONTACT = 10.0
#: The target is the bound smoothed over a third of the time scale (above the bound, without the
#: bisection's frame-to-frame noise), so holding the opening to it does not bring that noise back.
PRE_SMOOTH = 3.0
#: Before that, the bound is held at its largest over a quarter of the time scale either side: where
#: the path's clearance is not monotone the least opening can drop to 0 for a frame or two between
#: frames that need the finger open (a curled finger clear of a rim), and the smoothed opening would
#: curl into that gap and out again.
HOLD_OF_TIME_SCALE = 0.25


#: The bound is bisected on every other frame; a frame between takes its neighbours' larger bound where
#: that pose is clear (bisected above it where not): the smoother holds the opening near the bound's
#: running maximum over about a frame either side anyway. On the benchmark's sweep over the mug, 90,629
#: -> 51,466 exact queries and jitter after 281.3 -> 237.2 deg/s^2 (every frame's own bisection noise
#: gone), penetration after 0.049 -> 0.047 mm (:meth:`~usdhands.algorithms.interaction.ik.ChainPoser.least_opening`).
BISECT_EVERY = 2


def _running_max(x: np.ndarray, h: int) -> np.ndarray:
    """The largest of ``x`` within ``h`` samples either side, ``(T,)``."""
    if h <= 0 or len(x) == 0:
        return np.array(x)
    pad = np.concatenate([np.full(h, -np.inf), x, np.full(h, -np.inf)])
    windows = np.lib.stride_tricks.sliding_window_view(pad, 2 * h + 1)
    return windows.max(axis=1)


def _smooth_openings(group: ChainGroup, colliders, items: list, weight: float, margin: float, resolution: float,
                     hold: int = 0, rounds: int = 6, known: ChainDistances | None = None) -> dict:
    """For each chain of ``group``, the smoothed opening ``u`` ``(K,)`` above its bound and its poses
    ``(K, n, 3)``, every frame clear; the chains' tests in step (one per round for all of them, each
    frame's answer its own), each chain's rounds as it would run them alone.

    ``items``: the group's index of each chain to smooth -> ``(frames (K,), base (K, n, 3), bound (K,), via
    (K, n, 3) or None, in_reach (K,) bool)``, ``in_reach`` the frames where some pose of the chain can touch a collider (no other frame
    is tested); ``known``: the group's memo (one row per virtual frame).

    Opening further than the bound can touch something else (clearance along the path need
    not be monotone): each frame whose smoothed pose fails the test gets an upper bound, the
    clear opening nearest below it, and the curve is smoothed again between the bounds; a
    frame still failing after ``rounds`` takes its bound, which was tested. The opening is held
    near a target: the bound's running maximum over ``hold`` frames either side, smoothed
    (:data:`HOLD_OF_TIME_SCALE`, :data:`PRE_SMOOTH`, :data:`FIT_IN_CONTACT`).
    """
    upper = {c: np.ones(len(it[0])) for c, it in items.items()}
    u = {c: np.array(it[2]) for c, it in items.items()}
    bad = {c: np.zeros(0, dtype=np.int64) for c in items}
    active = list(items) if weight > 0 else []
    for r in range(rounds if weight > 0 else 0):
        changed = {}
        for c in active:
            frames, base, bound, via, in_reach = items[c]
            floor = bounded_smooth(_running_max(bound, hold), upper[c], weight / PRE_SMOOTH ** 4)
            u[c] = bounded_smooth(bound, upper[c], weight, fit=np.where(bound > 0, FIT_IN_CONTACT, 1.0), target=floor)
            ch = np.nonzero(u[c] > bound)[0]
            changed[c] = ch[in_reach[ch]]  # the other frames are clear in every pose
        ok = _group_clear(group, colliders, {c: (items[c][0][ch], group.posers[c].angles(
            items[c][1][ch], u[c][ch], None if items[c][3] is None else items[c][3][ch])) for c, ch in changed.items()},
            margin, resolution, known)
        for c in active:
            bad[c] = changed[c][~ok[c]]
        active = [c for c in active if len(bad[c]) and r != rounds - 1]
        if active:
            below = {c: bad[c] for c in active}
            vf, base, lo, hi, via = [], [], [], [], []
            for c in active:
                frames, b, bound, v, _ = items[c]
                vf.append(group.frames_of(c, frames[bad[c]]))
                base.append(b[bad[c]])
                lo.append(bound[bad[c]])
                hi.append(u[c][bad[c]])
                via.append(None if v is None else v[bad[c]])
            up = group.clear_below(colliders, np.concatenate(vf), np.concatenate(base), np.concatenate(lo),
                                   np.concatenate(hi), margin, resolution,
                                   via=None if via[0] is None else np.concatenate(via), known=known)
            for c, part in zip(active, np.split(up, np.cumsum([len(below[c]) for c in active])[:-1])):
                upper[c][below[c]] = part
    out = {}
    for c, (frames, base, bound, via, _) in items.items():
        u[c][bad[c]] = bound[bad[c]]  # every other frame passed the last test
        out[c] = (u[c], group.posers[c].angles(base, u[c], via))
    return out


def _group_clear(group: ChainGroup, colliders, items: dict, margin: float, resolution: float,
                 known: ChainDistances | None) -> dict:
    """One :meth:`ChainGroup.clear` of chains' poses: ``items`` maps a chain's index in ``group`` to clip
    frames ``(K,)`` and angles ``(K, n, 3)``; returns chain index -> ``(K,)`` bool."""
    chains = list(items)
    if not chains:
        return {}
    vf = np.concatenate([group.frames_of(c, items[c][0]) for c in chains])
    ok = group.clear(colliders, vf, np.concatenate([items[c][1] for c in chains]), margin, resolution, known=known)
    return dict(zip(chains, np.split(ok, np.cumsum([len(items[c][0]) for c in chains])[:-1])))


def correct_clip(clip: Clip, handmap: HandMap, colliders, *, margin_mm: float = 0.0,
                 config: InteractionConfig | None = None, smooth: bool = True,
                 measure: bool = True, iterations: int = 9,
                 world: np.ndarray | None = None) -> tuple[Clip, CorrectionReport]:
    """Push penetrating fingers out of the colliders, smoothly, changing as little as possible.

    Parameters
    ----------
    clip : Clip
    handmap : HandMap
        The hands to correct; body joints are never changed.
    colliders : Colliders
        In the clip's units, one transform per clip frame.
    margin_mm : float
        Clearance to keep, mm (0: touching is fine).
    config : InteractionConfig, optional
    smooth : bool
        False: the per-frame bound alone (no Kalman smoothing, no bounded smoother).
    measure : bool
        Measure penetration before and after (the report's depths are zeros otherwise).
    iterations : int
        Bisection steps for the bound (the opening to ``2**-iterations`` of its path).
    world : (T, J, 4, 4) float, optional
        World transforms of a clip that differs from ``clip`` at most in the finger joints of
        ``handmap`` (the input a synthesized clip was made from), when the caller has them: only
        the fingers are posed again.

    Returns
    -------
    Clip, CorrectionReport
    """
    cfg = config or InteractionConfig()
    mm = 0.001 / clip.skeleton.meters_per_unit
    margin = margin_mm * mm
    resolution = cfg.tolerance_mm * mm
    # the fingers posed only where a chain can come near a collider
    posed = FingersPosed(clip, handmap, world)
    posers = [_poser(clip, chain, posed, given=False) for hand in handmap.sides
              for chain in finger_chains(clip.skeleton, hand, cfg)]
    T = clip.num_frames
    finger_joints = sorted({j for p in posers for j in p.chain.joints})
    all_angles = finger_angles(clip, finger_joints)  # (T, len(finger_joints), 3): every chain's, and the jitter's
    rotations = np.array(clip.rotations)
    unresolved, corrected = [], []
    opened = np.zeros(T, dtype=bool)
    weight = smoothness_weight(clip.fps, cfg.smoothing_s) if smooth else 0.0
    # per chain near a collider, what was measured at each frame: the tests below, the report's depths;
    # chains with the same number of joints share one memo (chain c's frame f at row c * stride + f) so
    # that their bisections and smoothing run in step (ChainGroup)
    near_of = {}
    reachable = {}  # per chain near a collider, the frames where some pose of it could touch (with the margin)
    given = {}  # per chain near a collider, its joints in the pose given at those frames (the report's too)
    for poser in posers:
        candidates = _reachable(clip, poser, colliders, margin)
        points = _given_points(poser.chain, posed, candidates) if len(candidates) else None
        near = _near_posed(poser, posed, colliders, margin, candidates, points)
        if len(near):
            near_of[poser.chain.name] = near
            reachable[poser.chain.name] = candidates
            given[poser.chain.name] = points
    stride = group_stride(T, BISECT_EVERY)
    by_size: dict[int, list[ChainPoser]] = {}
    for poser in posers:
        if poser.chain.name in near_of:
            by_size.setdefault(len(poser.chain.joints), []).append(poser)
    known, memo, slot = {}, {}, {}
    for n, ps in by_size.items():
        memo[n] = ChainDistances(len(ps) * stride, n + 1)
        for c, p in enumerate(ps):
            known[p.chain.name] = None if memo[n] is None else memo[n].view(c * stride, c * stride + T)
            slot[p.chain.name] = c
    input_angles = {p.chain.name: all_angles[:, np.searchsorted(finger_joints, p.chain.joints)]
                    for p in posers if p.chain.name in near_of}
    found = {}  # each chain near a collider, tested as given: each size's chains in one test
    for n, ps in by_size.items():
        group = ChainGroup(ps, stride)
        tested = _group_clear(group, colliders, {c: (near_of[p.chain.name], input_angles[p.chain.name][near_of[p.chain.name]])
                                                 for c, p in enumerate(ps)}, margin, resolution, memo[n])
        found.update((ps[c].chain.name, ok) for c, ok in tested.items())
    to_correct = [(p, near_of[p.chain.name], found[p.chain.name]) for p in posers
                  if p.chain.name in near_of and not found[p.chain.name].all()]
    smoothing = smooth and cfg.smoothing_s > 0 and T >= 3
    smoothed = {}
    if smoothing and to_correct:
        # every corrected chain's whole curve (the input's own noise too) in one smoother call: the
        # curves share its gains, each comes out as it would alone
        curves = [input_angles[p.chain.name].reshape(T, -1) for p, _, _ in to_correct]
        out_curves = np.split(rts_smooth(np.concatenate(curves, axis=1), clip.fps, cfg.smoothing_s),
                              np.cumsum([c.shape[1] for c in curves])[:-1], axis=1)
        smoothed = {p.chain.name: c for (p, _, _), c in zip(to_correct, out_curves)}
    work_of = {}  # chain -> (frames, base, work, in_reach, via)
    for poser, near, ok in to_correct:
        seen = known[poser.chain.name]
        angles = input_angles[poser.chain.name]
        corrected.append(poser.chain.name)
        n = len(poser.chain.joints)
        lo, hi = poser.chain.limits[..., 0], poser.chain.limits[..., 1]
        if smooth:
            # the whole curve: the input's own noise is smoothed too, within the joint limits; only the
            # frames where the chain can reach a collider are tested (every other pose is clear)
            frames = np.arange(T)
            base = angles
            if smoothing:
                base = smoothed[poser.chain.name].reshape(T, n, 3)
            base = np.clip(base, lo, hi)
            work = reachable[poser.chain.name]
        else:
            frames = near[~ok]
            base = angles[frames]
            work = np.arange(len(frames))
        in_reach = np.zeros(len(frames), dtype=bool)
        in_reach[work] = True
        via = None
        if cfg.ik == "ccd":
            # cyclic coordinate descent where the pose penetrates, smoothed over twice the time scale
            # (its choice of joint can change from one frame to the next); the path goes through it
            touching = work[~poser.clear(colliders, frames[work], base[work], margin, resolution, known=seen)]
            via = np.clip(base, lo, hi)
            via[touching], _ = poser.ccd(colliders, frames[touching], via[touching], margin, resolution, known=seen)
            if smoothing:
                via = rts_smooth(via.reshape(T, -1), clip.fps, 2 * cfg.smoothing_s).reshape(T, n, 3)
                via = np.clip(via, lo, hi)
        work_of[poser.chain.name] = (frames, base, work, in_reach, via)
    hold = int(round(HOLD_OF_TIME_SCALE * cfg.smoothing_s * clip.fps))
    missed = {}  # per corrected chain, (chain, frame) where even the open pose touches
    for n, ps in by_size.items():
        members = [p for p in ps if p.chain.name in work_of]
        if not members:
            continue
        group = ChainGroup(ps, stride)
        parts = [work_of[p.chain.name] for p in members]
        vf = np.concatenate([group.frames_of(slot[p.chain.name], fr[w]) for p, (fr, _, w, _, _) in zip(members, parts)])
        found, resolved_all = group.least_opening(
            colliders, vf, np.concatenate([b[w] for _, b, w, _, _ in parts]), margin, resolution, iterations,
            via=None if parts[0][4] is None else np.concatenate([v[w] for _, _, w, _, v in parts]),
            known=memo[n], every=BISECT_EVERY)
        items = {}
        sizes = np.cumsum([len(w) for _, _, w, _, _ in parts])[:-1]
        for p, (frames, base, work, in_reach, via), found_c, resolved_c in zip(
                members, parts, np.split(found, sizes), np.split(resolved_all, sizes)):
            bound, resolved = np.zeros(len(frames)), np.ones(len(frames), dtype=bool)
            bound[work], resolved[work] = found_c, resolved_c
            missed[p.chain.name] = [(p.chain.name, int(f)) for f in frames[~resolved]]
            items[slot[p.chain.name]] = (frames, base, bound, via, in_reach)
        smoothed_openings = _smooth_openings(group, colliders, items, weight, margin, resolution, hold=hold,
                                             known=memo[n])
        for c, (frames, _, bound, _, _) in items.items():
            _, new = smoothed_openings[c]
            opened[frames[bound > 0]] = True
            rotations[np.ix_(frames, list(ps[c].chain.joints))] = ps[c].local_rotations(new)
    for name in corrected:
        unresolved.extend(missed[name])
    out = clip.replace(rotations=rotations)
    change = quat_angle_deg(np.asarray(clip.rotations)[:, finger_joints], rotations[:, finger_joints])
    # what was not corrected is bit for bit the input: measured once, before
    changed = [p for p in posers if p.chain.name in corrected]
    moved = sorted({j for p in changed for j in p.chain.joints})
    moved_angles = finger_angles(out, moved) if moved else None  # the report's depths after and jitter
    depth_before = depth_after = np.zeros(T)
    if measure:
        depth_before, depth_after = np.zeros(T), np.zeros(T)
        posed_out = FingersPosed(out, handmap, posed.world)  # only the corrected chains differ from the clip
        for n, ps in by_size.items():  # each size's chains measured together, before and then after
            before, after, after_posers = {}, {}, list(ps)
            for c, p in enumerate(ps):
                candidates = reachable[p.chain.name]  # with the margin: all that can be near at 0
                frames = _near_posed(p, posed, colliders, 0.0, candidates, given[p.chain.name])
                before[c] = (frames, input_angles[p.chain.name][frames])
                if p.chain.name in corrected:
                    after_posers[c] = _poser(out, p.chain, posed_out, given=False)
                    frames = _near_posed(after_posers[c], posed_out, colliders, 0.0, candidates)
                    after[c] = (frames, moved_angles[:, np.searchsorted(moved, p.chain.joints)][frames])
            depth = _group_depth_mm(ChainGroup(ps, stride), colliders, before, memo[n], mm, T)
            for c, d in depth.items():
                np.maximum(depth_before, d, out=depth_before)
                if c not in after:  # not corrected: the input's
                    np.maximum(depth_after, d, out=depth_after)
            for d in _group_depth_mm(ChainGroup(after_posers, stride), colliders, after, memo[n], mm, T).values():
                np.maximum(depth_after, d, out=depth_after)
        for hand in handmap.sides:  # the palm: body joints, the same before and after
            palm = palm_depth_mm(posed, clip.skeleton, hand, [p.chain for p in posers], colliders, cfg)
            np.maximum(depth_before, palm, out=depth_before)
            np.maximum(depth_after, palm, out=depth_after)
            unresolved.extend((f"{hand.side} palm", int(f)) for f in np.nonzero(palm > 0.5 * cfg.tolerance_mm)[0])
    jitter_before = jitter_after = 0.0
    if T >= 3 and finger_joints:
        sums = _jitter_sums_of(all_angles)
        scale = clip.fps ** 2 / ((T - 2) * 3 * len(finger_joints))
        jitter_before = jitter_after = float(sums.sum() * scale)
        if moved:
            sums[np.searchsorted(finger_joints, moved)] = _jitter_sums_of(moved_angles)
            jitter_after = float(sums.sum() * scale)
    report = CorrectionReport(
        penetration_before_mm=depth_before,
        penetration_after_mm=depth_after,
        frames_corrected=int(opened.sum()),
        jitter_before=jitter_before,
        jitter_after=jitter_after,
        max_change_deg=float(change.max(initial=0.0)),
        unresolved=unresolved,
        chains_corrected=corrected,
    )
    return out, report

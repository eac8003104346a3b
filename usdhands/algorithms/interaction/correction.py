"""Collision correction of finger motion with a no-penetration guarantee (seed 002, §3.3 and §3.5).

For each finger chain of each hand:

1. Broad phase: frames whose capsules' bounding box is farther from every collider's
   than the radius plus the margin are clear and cost nothing.
2. Detection: the clearance search along each capsule axis
   (:func:`~usdhands.algorithms.interaction.clearance.axis_clearance`) finds the frames
   where the chain penetrates. A chain that never does is left bit-for-bit unchanged.
3. Around those frames (a window of a few smoothing time scales, ramped at its ends) the
   chain's curves are smoothed by the RTS Kalman smoother (the paper's smoothing step,
   against capture noise and the correction's own jitter).
4. IK: per frame, the least opening of the chain along its path that clears every
   collider (:meth:`~usdhands.algorithms.interaction.ik.ChainPoser.least_opening`),
   by bisection with the clearance test: the bound.
5. The opening is smoothed with the bound as a constraint
   (:func:`~usdhands.algorithms.interaction.smoothing.bounded_smooth`), so it never
   falls below what clears; every frame is tested again and any frame that fails
   (where opening further touches something else) takes its bound, which was tested.

So every changed frame passed the clearance test, whose resolution bounds what can slip
through: nothing penetrates deeper than half of ``tolerance_mm`` minus the margin.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from usdhands.algorithms.interaction.clearance import axis_clearance
from usdhands.algorithms.interaction.finger_geometry import FingerChain, InteractionConfig, finger_chains
from usdhands.algorithms.interaction.ik import ChainPoser
from usdhands.algorithms.interaction.smoothing import bounded_smooth, rts_smooth, smoothness_weight
from usdhands.model.clip import Clip
from usdhands.model.finger_dofs import finger_curves
from usdhands.model.handmap import HandMap
from usdhands.model.rotations import quat_angle_deg

__all__ = ["CorrectionReport", "correct_clip", "chain_posers", "penetration_depth_mm", "finger_jitter"]


@dataclass
class CorrectionReport:
    """What a correction did.

    Attributes
    ----------
    penetration_before_mm, penetration_after_mm : (T,) float
        Deepest finger penetration into any collider per frame, mm (0 where clear),
        measured along the capsule axes to 0.05 mm (an upper bound).
    frames_corrected : int
        Frames where some finger rotation changed.
    jitter_before, jitter_after : float
        Mean absolute angular acceleration of the finger curves, deg/s².
    max_change_deg : float
        Largest change of a finger joint's rotation, degrees.
    unresolved : list of (str, int)
        Chain and frame where even the open finger touches (the palm or wrist is inside a prop).
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


def chain_posers(clip: Clip, handmap: HandMap, config: InteractionConfig) -> list[ChainPoser]:
    """A :class:`ChainPoser` for every finger chain of every hand of ``clip``."""
    world = clip.world_xforms()
    out = []
    for hand in handmap.sides:
        for chain in finger_chains(clip.skeleton, hand, config):
            js = list(chain.joints)
            parent = int(clip.skeleton.parents[js[0]])
            pw = world[:, parent] if parent >= 0 else np.broadcast_to(np.eye(4), (clip.num_frames, 4, 4))
            last = world[:, js[-1]]
            tip = last[:, :3, :3] @ chain.tip_offset + last[:, :3, 3]
            given = np.concatenate([world[:, js][:, :, :3, 3], tip[:, None]], axis=1)
            out.append(ChainPoser(chain, np.ascontiguousarray(pw), np.asarray(clip.translations[:, js]),
                                  np.asarray(clip.scales[:, js]), np.asarray(clip.skeleton.rest_rotations[js]),
                                  given_points=given))
    return out


def _near_frames(poser: ChainPoser, colliders, reach: float) -> np.ndarray:
    """Frames where the chain, as given, comes within ``reach`` (radius + margin added) of some collider's box."""
    pts = poser.given_points
    frames = np.arange(len(pts))
    r = float(poser.chain.radii.max()) + reach
    lo = pts.min(axis=1) - r
    hi = pts.max(axis=1) + r
    return frames[colliders.bbox_gap(frames, lo, hi) <= 0]


def _chain_angles(clip: Clip, chain: FingerChain) -> np.ndarray:
    T, n = clip.num_frames, len(chain.joints)
    return finger_curves(clip, chain.joints).values.reshape(T, n, 3)


def penetration_depth_mm(clip: Clip, posers: list[ChainPoser], colliders, resolution_mm: float = 0.05) -> np.ndarray:
    """Deepest penetration of any finger capsule into any collider per frame, ``(T,)`` mm.

    An upper bound within ``resolution_mm`` of the exact depth (the axis search's lower bound).
    """
    mm = 0.001 / clip.skeleton.meters_per_unit
    depth = np.zeros(clip.num_frames)
    for poser in posers:
        frames = _near_frames(poser, colliders, 0.0)
        if len(frames) == 0:
            continue
        angles = _chain_angles(clip, poser.chain)
        a, b = poser.capsules(frames, angles[frames])
        n = a.shape[1]
        need = np.tile(poser.chain.radii, len(frames))
        lower, _ = axis_clearance(colliders, np.repeat(frames, n), a.reshape(-1, 3), b.reshape(-1, 3), need,
                                  resolution_mm * mm, find_depth=True)
        d = np.maximum(need - lower, 0.0).reshape(len(frames), n).max(axis=1) / mm
        np.maximum.at(depth, frames, d)
    return depth


def finger_jitter(clip: Clip, joints: list[int]) -> float:
    """Mean absolute angular acceleration of the finger curves of ``joints``, deg/s²."""
    if clip.num_frames < 3 or not joints:
        return 0.0
    v = finger_curves(clip, joints).values
    return float(np.abs(np.diff(v, 2, axis=0)).mean() * clip.fps ** 2)


def _runs(frames: np.ndarray) -> list[np.ndarray]:
    """Split sorted frame indices into runs of consecutive frames."""
    if len(frames) == 0:
        return []
    cuts = np.nonzero(np.diff(frames) > 1)[0] + 1
    return np.split(frames, cuts)


def _window(hit: np.ndarray, core: int, ramp: int) -> np.ndarray:
    """Weights ``(T,)``: 1 within ``core`` frames of a hit, falling linearly to 0 over ``ramp`` more."""
    T = len(hit)
    idx = np.nonzero(hit)[0]
    dist = np.full(T, np.inf)
    if len(idx):
        pos = np.searchsorted(idx, np.arange(T))
        left = idx[np.clip(pos - 1, 0, len(idx) - 1)]
        right = idx[np.clip(pos, 0, len(idx) - 1)]
        dist = np.minimum(np.abs(np.arange(T) - left), np.abs(right - np.arange(T))).astype(float)
    w = np.clip(1.0 - (dist - core) / max(ramp, 1), 0.0, 1.0)
    w[dist <= core] = 1.0
    return w


def correct_clip(clip: Clip, handmap: HandMap, colliders, *, margin_mm: float = 0.0,
                 config: InteractionConfig | None = None, smooth: bool = True,
                 measure: bool = True, iterations: int = 9) -> tuple[Clip, CorrectionReport]:
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

    Returns
    -------
    Clip, CorrectionReport
    """
    cfg = config or InteractionConfig()
    mm = 0.001 / clip.skeleton.meters_per_unit
    margin = margin_mm * mm
    resolution = cfg.tolerance_mm * mm
    posers = chain_posers(clip, handmap, cfg)
    T = clip.num_frames
    rotations = np.array(clip.rotations)
    unresolved, corrected = [], []
    core = int(round(2 * cfg.smoothing_s * clip.fps)) if smooth else 0
    ramp = int(round(2 * cfg.smoothing_s * clip.fps)) if smooth else 0
    weight = smoothness_weight(clip.fps, cfg.smoothing_s) if smooth else 0.0
    for poser in posers:
        near = _near_frames(poser, colliders, margin)
        if len(near) == 0:
            continue
        angles = _chain_angles(clip, poser.chain)
        ok = poser.clear(colliders, near, angles[near], margin, resolution)
        hit = np.zeros(T, dtype=bool)
        hit[near[~ok]] = True
        if not hit.any():
            continue
        corrected.append(poser.chain.name)
        n = len(poser.chain.joints)
        w = _window(hit, core, ramp) if smooth else hit.astype(float)
        frames = np.nonzero(w > 0)[0]
        base = np.array(angles)
        if smooth and cfg.smoothing_s > 0:
            for run in _runs(frames):  # the smoother runs over each window only
                sm = rts_smooth(angles[run].reshape(len(run), -1), clip.fps, cfg.smoothing_s).reshape(-1, n, 3)
                base[run] = angles[run] + w[run, None, None] * (sm - angles[run])
        bound, resolved = poser.least_opening(colliders, frames, base[frames], margin, resolution, iterations)
        for f in frames[~resolved]:
            unresolved.append((poser.chain.name, int(f)))
        u = np.array(bound)
        if weight > 0:
            pos = 0
            for run in _runs(frames):
                sl = slice(pos, pos + len(run))
                u[sl] = bounded_smooth(bound[sl], np.ones(len(run)), weight)
                pos += len(run)
        new = poser.angles(base[frames], u)
        changed = u > bound
        if changed.any():
            still = poser.clear(colliders, frames[changed], new[changed], margin, resolution)
            back = np.nonzero(changed)[0][~still]
            new[back] = poser.angles(base[frames[back]], bound[back])
        q = poser.local_rotations(new)
        same = (u <= 0) & np.all(new == angles[frames], axis=(1, 2))
        write = frames[~same]
        rotations[np.ix_(write, list(poser.chain.joints))] = q[~same]
    out = clip.replace(rotations=rotations)
    finger_joints = sorted({j for p in posers for j in p.chain.joints})
    changed_frames = np.any(rotations[:, finger_joints] != np.asarray(clip.rotations)[:, finger_joints], axis=(1, 2))
    change = quat_angle_deg(np.asarray(clip.rotations)[:, finger_joints], rotations[:, finger_joints])
    report = CorrectionReport(
        penetration_before_mm=penetration_depth_mm(clip, posers, colliders) if measure else np.zeros(T),
        penetration_after_mm=(penetration_depth_mm(out, chain_posers(out, handmap, cfg), colliders)
                              if measure else np.zeros(T)),
        frames_corrected=int(changed_frames.sum()),
        jitter_before=finger_jitter(clip, finger_joints),
        jitter_after=finger_jitter(out, finger_joints),
        max_change_deg=float(change.max(initial=0.0)),
        unresolved=unresolved,
        chains_corrected=corrected,
    )
    return out, report

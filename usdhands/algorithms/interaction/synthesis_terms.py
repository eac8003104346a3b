"""Interactions inside finger synthesis (seed 002, §3.1-3.4): what synthesis asks of the colliders.

- **Segmentation by proximity**: besides the wrist-speed cuts, a segment boundary where
  the wrist comes within reach of a collider or leaves it, so a grasp is a segment of its own.
- **The collision term**: each candidate segment's finger curves, applied to the input's
  hand over the input segment (stretched uniformly to its length), are corrected against
  the input's colliders (the corrected database D*, all candidates of all segments near a
  collider in one correction); the segment cost gains ``wc * sum((D - D*)**2) / (n * m)``
  over the segment's n frames and m finger DOFs (degrees), so candidates that would go
  through the props cost more.

:class:`InteractionTerms` is what :func:`~usdhands.algorithms.synthesis.synthesize.synthesize_hand`
takes as ``hooks``: ``cuts(bounds)`` and ``penalty(bounds, candidates)``, at the
database's frame rate.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from usdhands.algorithms.interaction.correction import chain_posers, rest_branch
from usdhands.algorithms.interaction.finger_geometry import InteractionConfig
from usdhands.algorithms.interaction.ik import ChainPoser, least_openings
from usdhands.model.clip import Clip
from usdhands.model.handmap import HandMap, HandSide
from usdhands.model.rotations import quat_conjugate, quat_multiply, quat_to_euler_deg

__all__ = ["InteractionTerms", "wrist_proximity", "wrist_near", "proximity_cuts"]


def wrist_proximity(clip: Clip, hand: HandSide, colliders, cutoff: float = np.inf,
                    world: np.ndarray | None = None) -> np.ndarray:
    """Signed distance from the wrist to the nearest collider per frame, ``(T,)`` clip units (a lower
    bound, the distance to the collider's box, where that exceeds ``cutoff``; ``world``: the clip's
    world transforms when the caller has them)."""
    j = clip.skeleton.index(hand.wrist)
    pos = (clip.world_xforms() if world is None else world)[:, j, :3, 3]
    return colliders.signed_distance(np.arange(clip.num_frames), pos, cutoff)


def wrist_near(clip: Clip, hand: HandSide, colliders, reach: float, world: np.ndarray | None = None) -> np.ndarray:
    """Whether the wrist is nearer than ``reach`` (clip units) to some collider per frame, ``(T,)`` bool:
    ``wrist_proximity(clip, hand, colliders, reach, world) < reach``, measured exactly only where
    bounds do not decide (:meth:`~usdhands.algorithms.interaction.colliders.Colliders.within`)."""
    j = clip.skeleton.index(hand.wrist)
    pos = (clip.world_xforms() if world is None else world)[:, j, :3, 3]
    return colliders.within(np.arange(clip.num_frames), pos, reach)


def proximity_cuts(bounds: np.ndarray, near: np.ndarray, min_frames: int) -> np.ndarray:
    """``bounds`` with a cut added wherever ``near`` ``(T,)`` changes, unless it would leave a
    segment shorter than ``min_frames``."""
    bounds = np.asarray(bounds, dtype=np.int64)
    changes = np.nonzero(np.diff(near.astype(np.int8)))[0] + 1
    out = list(bounds)
    for c in changes:
        if min(abs(c - b) for b in out) >= min_frames:
            out.append(int(c))
    return np.array(sorted(out), dtype=np.int64)


@dataclass(eq=False)
class InteractionTerms:
    """Synthesis hooks for one hand, all at the database's frame rate.

    Parameters
    ----------
    clip : Clip
        The input, resampled to the database's rate.
    hand : HandSide
    rig : object
        The hand's :class:`~usdhands.algorithms.synthesis.finger_transfer.HandRig`.
    to_local, to_curves : callable
        ``to_local(curves (K, 60)) -> (K, S, 4)``: local rotations of the rig's slot joints
        ``rig.slot_joint[rig.present]`` from synthesis's canonical finger curves, and
        ``to_curves`` the inverse (passed in so this room does not import synthesis).
    fingers : callable
        ``fingers(segment) -> (n, 60)`` canonical finger curves of a database segment.
    colliders : Colliders
        One transform per frame of ``clip``.
    weight : float
        ``wc``.
    reach : float
        Wrist distance under which a frame is near a collider, clip units.
    min_frames : int
        Shortest segment a proximity cut may leave.
    margin_mm : float
    config : InteractionConfig, optional
    stride, samples : int
        The term is a mean over the segment's frames: frames about ``stride`` apart are
        corrected, evenly from the first to the last, at least ``samples`` of them (all of a
        shorter segment).
    world : (T, J, 4, 4) float, optional
        ``clip.world_xforms()``, when the caller has it (both hands share it).

    Notes
    -----
    The collision term needs only the size of each candidate's correction, so the
    candidates are corrected chain by chain on arrays: the input's hand (every chain's
    parent transform at each input frame) is posed once, each candidate frame's finger
    curves become the chain's Euler angles, and only the candidate frames whose chain can
    reach a collider's box (the parent joint plus the chain's length and radius) are
    searched, with a 2 mm clearance and 5 bisection steps (the result is corrected again
    with the full guarantee). No clip is built per candidate.
    """

    clip: Clip
    hand: HandSide
    rig: object
    to_local: object
    to_curves: object
    fingers: object
    colliders: object
    weight: float = 1.0
    reach: float = 0.0
    min_frames: int = 10
    margin_mm: float = 0.0
    config: InteractionConfig | None = None
    stride: int = 6
    samples: int = 4
    world: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.near = wrist_near(self.clip, self.hand, self.colliders, self.reach, self.world)
        self._posers = None

    def cuts(self, bounds: np.ndarray) -> np.ndarray:
        """Segment boundaries with the proximity cuts added."""
        return proximity_cuts(bounds, self.near, self.min_frames)

    def _chains(self) -> list[tuple[ChainPoser, np.ndarray, float]]:
        """Each finger chain's poser on the input, its joints' columns among the slot joints and its reach."""
        if self._posers is None:
            cfg = replace(self.config or InteractionConfig(), tolerance_mm=2.0)
            slot_joints = list(np.asarray(self.rig.slot_joint)[np.asarray(self.rig.present)])
            self._posers = []
            for poser in chain_posers(self.clip, HandMap(**{self.hand.side: self.hand}), cfg, self.world):
                if not all(j in slot_joints for j in poser.chain.joints):
                    continue
                cols = np.array([slot_joints.index(j) for j in poser.chain.joints])
                bones = np.linalg.norm(self.clip.skeleton.rest_translations[list(poser.chain.joints)], axis=1)
                length = float(bones.sum() + np.linalg.norm(poser.chain.tip_offset))
                self._posers.append((poser, cols, length + float(poser.chain.radii.max())))
        return self._posers

    def penalty(self, bounds: np.ndarray, candidates: np.ndarray) -> np.ndarray:
        """Collision term ``(N, k)`` for the candidates of each segment (0 for segments far from colliders)."""
        N, k = candidates.shape
        out = np.zeros((N, k))
        rows, frames, fragments = [], [], []
        curves, picks = {}, {}  # each candidate segment's curves, each (length, span)'s sampled rows: once
        for i in range(N):
            q0, q1 = int(bounds[i]), int(bounds[i + 1])
            if not self.near[q0:q1].any():
                continue
            n = q1 - q0  # the frames sampled, evenly from the first to the last
            at = np.unique(np.round(np.linspace(0, n - 1, min(n, max(self.samples, -(-n // self.stride))))))
            at = at.astype(np.int64)
            for j in range(k):
                c = int(candidates[i, j])
                if c < 0:
                    continue
                seg = curves.get(c)
                if seg is None:
                    seg = curves[c] = self.fingers(c)
                pick = picks.get((len(seg), n))
                if pick is None:
                    pick = picks[len(seg), n] = np.round(np.linspace(0, len(seg) - 1, n)).astype(np.int64)[at]
                rows.append((i, j))
                frames.append(q0 + at)
                fragments.append(seg[pick])
        if not rows:
            return out
        frames_all = np.concatenate(frames)
        D = np.concatenate(fragments)
        D_star = self.corrected(frames_all, D)
        m = max(int(np.count_nonzero(np.any(D != 0, axis=0))), 1)
        diff = (D - D_star + 180.0) % 360.0 - 180.0
        pos = 0
        for (i, j), f in zip(rows, frames):
            n = len(f)
            out[i, j] = self.weight * float((diff[pos:pos + n] ** 2).sum()) / (n * m)
            pos += n
        return out

    def corrected(self, frames: np.ndarray, curves: np.ndarray) -> np.ndarray:
        """Canonical curves ``(K, 60)`` placed on the input's hand at ``frames`` ``(K,)``, corrected
        against the colliders per frame (the least opening, coarse search, no smoothing): D*."""
        mm = 0.001 / self.clip.skeleton.meters_per_unit
        margin = self.margin_mm * mm
        resolution = 2.0 * mm
        local = np.array(self.to_local(curves))
        fixed = np.zeros(len(frames), dtype=bool)
        parent_distance = {}  # per parent joint: its distance to the colliders at each input frame
        todo = []  # (poser, cols, near, base) of each chain some candidate frame may touch
        for poser, cols, reach in self._chains():
            centre = poser.parent_world[frames, :3, 3]
            r = reach + margin
            near = np.nonzero(self.colliders.bbox_gap(frames, centre - r, centre + r) <= 0)[0]
            if len(near):
                # every point of the chain's capsules lies within `reach` of its parent joint, which
                # the candidates do not move: where that joint is farther than `reach` plus the margin
                # from every collider, no candidate can touch
                parent = int(self.clip.skeleton.parents[poser.chain.joints[0]])
                if parent not in parent_distance:
                    parent_distance[parent] = np.full(self.clip.num_frames, np.nan)
                known = parent_distance[parent]
                unknown = np.unique(frames[near][np.isnan(known[frames[near]])])
                if len(unknown):
                    known[unknown] = self.colliders.signed_distance(unknown, poser.parent_world[unknown, :3, 3], r)
                near = near[known[frames[near]] < r]
            if len(near) == 0:
                continue
            rel = quat_multiply(quat_conjugate(poser.rest_rotations)[None], local[near][:, cols])
            todo.append((poser, cols, near, rest_branch(quat_to_euler_deg(rel, poser.order))))
        # the chains' bisections in step: one collider query per step for all of them
        found = least_openings([t[0] for t in todo], self.colliders, [frames[t[2]] for t in todo],
                               [t[3] for t in todo], margin, resolution, iterations=5)
        for (poser, cols, near, base), (u, _) in zip(todo, found):
            moved = u > 0
            if not moved.any():
                continue
            rows = near[moved]
            q = poser.local_rotations(poser.angles(base[moved], u[moved]))
            local[rows[:, None], cols[None, :]] = q
            fixed[rows] = True
        out = np.array(curves, dtype=np.float64)
        if fixed.any():
            out[fixed] = self.to_curves(local[fixed])
        return out

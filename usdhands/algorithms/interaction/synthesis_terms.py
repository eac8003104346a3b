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

from usdhands.algorithms.interaction.correction import correct_clip
from usdhands.algorithms.interaction.finger_geometry import InteractionConfig
from usdhands.model.clip import Clip
from usdhands.model.handmap import HandMap, HandSide

__all__ = ["InteractionTerms", "wrist_proximity", "proximity_cuts"]


def wrist_proximity(clip: Clip, hand: HandSide, colliders) -> np.ndarray:
    """Signed distance from the wrist to the nearest collider per frame, ``(T,)`` clip units."""
    j = clip.skeleton.index(hand.wrist)
    pos = clip.world_positions()[:, j]
    return colliders.signed_distance(np.arange(clip.num_frames), pos)


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
    apply_curves, read_curves : callable
        ``apply_curves(clip, rig, curves (T, 60)) -> Clip`` and ``read_curves(clip, rig) -> (T, 60)``
        (synthesis's canonical finger curves; passed in so this room does not import synthesis).
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
    """

    clip: Clip
    hand: HandSide
    rig: object
    apply_curves: object
    read_curves: object
    fingers: object
    colliders: object
    weight: float = 1.0
    reach: float = 0.0
    min_frames: int = 10
    margin_mm: float = 0.0
    config: InteractionConfig | None = None

    def __post_init__(self) -> None:
        self.near = wrist_proximity(self.clip, self.hand, self.colliders) < self.reach

    def cuts(self, bounds: np.ndarray) -> np.ndarray:
        """Segment boundaries with the proximity cuts added."""
        return proximity_cuts(bounds, self.near, self.min_frames)

    def penalty(self, bounds: np.ndarray, candidates: np.ndarray) -> np.ndarray:
        """Collision term ``(N, k)`` for the candidates of each segment (0 for segments far from colliders)."""
        N, k = candidates.shape
        out = np.zeros((N, k))
        rows, frames, fragments = [], [], []
        for i in range(N):
            q0, q1 = int(bounds[i]), int(bounds[i + 1])
            if not self.near[q0:q1].any():
                continue
            for j in range(k):
                if candidates[i, j] < 0:
                    continue
                seg = self.fingers(int(candidates[i, j]))
                pick = np.round(np.linspace(0, len(seg) - 1, q1 - q0)).astype(np.int64)
                rows.append((i, j))
                frames.append(np.arange(q0, q1))
                fragments.append(seg[pick])
        if not rows:
            return out
        frames_all = np.concatenate(frames)
        D = np.concatenate(fragments)
        base = self.clip.replace(rotations=self.clip.rotations[frames_all],
                                 translations=self.clip.translations[frames_all],
                                 scales=self.clip.scales[frames_all], start_time=0.0)
        stacked = self.apply_curves(base, self.rig, D)
        handmap = HandMap(**{self.hand.side: self.hand})
        # an estimate for ranking candidates: a 2 mm clearance search and 5 bisection steps
        # (the result is corrected again with the full guarantee)
        coarse = replace(self.config or InteractionConfig(), tolerance_mm=2.0)
        corrected, _ = correct_clip(stacked, handmap, self.colliders.take(frames_all), margin_mm=self.margin_mm,
                                    config=coarse, smooth=False, measure=False, iterations=5)
        D_star = self.read_curves(corrected, self.rig)
        m = max(int(np.count_nonzero(np.any(D != 0, axis=0))), 1)
        pos = 0
        for (i, j), f in zip(rows, frames):
            n = len(f)
            diff = (D[pos:pos + n] - D_star[pos:pos + n] + 180.0) % 360.0 - 180.0
            out[i, j] = self.weight * float((diff ** 2).sum()) / (n * m)
            pos += n
        return out

"""The palm as capsules from the wrist to the base of each long finger: measured, never moved.

A hand pressed into a table with its fingers curled up off it, or laid on the chest with
``--self``, can have its palm inside a collider while every finger is clear. The
correction cannot push it out (the palm's joints are body joints, which it never
changes), but it is a penetration all the same: the correction's report and ``check``
measure it with these capsules, one per long finger (index, middle, ring, little) from the
wrist joint to the finger's first joint, of the configuration's ``palm_radius_mm``, or half the
palm's thickness where the file has a mesh skinned to the hand (measured as the fingers' radii
are: :func:`~usdhands.algorithms.interaction.finger_geometry.mesh_radii`), or the radius
``joint_radii_mm`` gives the wrist joint.

With ``--self`` a palm is measured against the body but its own upper arm: the elbow joins
the two, and with the elbow folded (a hand at the shoulder or the head) the wrist end of the
palm passes within the upper arm's capsule, which stands for the whole arm's flesh
(the ``scratch_head`` sample: 27.6 mm at three frames).
"""

from __future__ import annotations

import numpy as np

from usdhands.algorithms.interaction.clearance import axis_clearance
from usdhands.algorithms.interaction.finger_geometry import FingerChain, InteractionConfig
from usdhands.model.handmap import HandSide
from usdhands.model.skeleton import Skeleton

__all__ = ["palm_axes", "palm_depth_mm"]


def palm_axes(world: np.ndarray, skeleton: Skeleton, hand: HandSide, chains: list[FingerChain]) -> np.ndarray:
    """End points of the palm's capsule axes ``(T, m, 2, 3)``: the wrist and each long finger's first
    joint, clip units (``m == 0`` for a hand with no long finger).

    Parameters
    ----------
    world : (T, J, 4, 4) float or FingersPosed
        The clip's world transforms (or :class:`~usdhands.algorithms.interaction.posing.FingersPosed`,
        which poses the joints needed).
    chains : list of FingerChain
        The hand's finger chains (:func:`~usdhands.algorithms.interaction.finger_geometry.finger_chains`).
    """
    wrist = skeleton.index(hand.wrist)
    bases = [c.joints[0] for c in chains if c.finger != "thumb" and c.side == hand.side]
    if hasattr(world, "at"):  # a FingersPosed: the joints posed where needed
        ws = world.at([wrist] + bases)
        T = len(ws[0])
        b = np.stack([w[:, :3, 3] for w in ws[1:]], axis=1) if bases else np.zeros((T, 0, 3))
        wrist_at = ws[0][:, :3, 3]
    else:
        T = len(world)
        b = world[:, bases][..., :3, 3]
        wrist_at = world[:, wrist, :3, 3]
    a = np.broadcast_to(wrist_at[:, None], (T, len(bases), 3))
    return np.stack([a, b], axis=2)


def palm_depth_mm(world: np.ndarray, skeleton: Skeleton, hand: HandSide, chains: list[FingerChain], colliders,
                  config: InteractionConfig | None = None, resolution_mm: float = 0.05) -> np.ndarray:
    """Deepest penetration of the palm into any collider per frame, ``(T,)`` mm (0 where clear).

    An upper bound within ``resolution_mm`` of the exact depth, measured as the fingers' (the
    clearance search along each axis); frames whose palm box is farther from every collider's box
    than the radius cost nothing.
    """
    mm = 0.001 / skeleton.meters_per_unit
    cfg = config or InteractionConfig()
    axes = palm_axes(world, skeleton, hand, chains)
    T, m = axes.shape[:2]
    depth = np.zeros(T)
    if m == 0:
        return depth
    radius = cfg.joint_radius_mm(skeleton.joint_names[skeleton.index(hand.wrist)], cfg.palm_radius_mm) * mm
    colliders = colliders.without_parts({f"{hand.side} upper arm"})
    pts = axes.reshape(T, -1, 3)
    frames = np.arange(T)
    frames = frames[colliders.bbox_gap(frames, pts.min(axis=1) - radius, pts.max(axis=1) + radius) <= 0]
    if len(frames) == 0:
        return depth
    K = len(frames)
    a, b = axes[frames, :, 0], axes[frames, :, 1]
    need = np.full((K, m), radius)
    reach = need + np.linalg.norm(b - a, axis=2)
    # the wrist is measured once for the m axes it starts (exact within the longest axis's reach)
    d_wrist = colliders.signed_distance(frames, a[:, 0], reach.max(axis=1))
    d_base = colliders.signed_distance(np.repeat(frames, m), b.reshape(-1, 3), reach.reshape(-1))
    lower, _ = axis_clearance(colliders, np.repeat(frames, m), a.reshape(-1, 3), b.reshape(-1, 3), need.reshape(-1),
                              resolution_mm * mm, find_depth=True, end_distances=(np.repeat(d_wrist, m), d_base))
    depth[frames] = np.maximum(radius - lower, 0.0).reshape(K, m).max(axis=1) / mm
    return depth

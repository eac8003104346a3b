"""World transforms of a clip's finger joints, posed only where asked for, and a chain's reach.

The correction and its report need a finger chain's joint positions only at the frames where
the chain can come near a collider, and the synthesized clip they correct differs from its
input only in the fingers. :class:`FingersPosed` takes every other joint's world transform
from the input's forward kinematics and poses a finger joint (with the joints between it and
the body) from the clip's own local transforms at the frames asked for, with the very
operations of a full forward-kinematics pass (each row's product is its own: the same bits).

:func:`chain_reach` bounds how far any point of a chain (joints, tip) can be from its parent
joint in any pose, from the translations and scales alone, so frames where a ball of that
radius (plus the capsule radius and a margin) around the parent joint misses every collider's
box are clear in every pose: the broad phase, before any finger is posed.
"""

from __future__ import annotations

import numpy as np

from usdhands.model.clip import Clip
from usdhands.model.handmap import HandMap
from usdhands.model.rotations import trs_to_xform

__all__ = ["FingersPosed", "chain_path", "chain_reach", "reachable_frames"]


class FingersPosed:
    """World transforms ``(K, 4, 4)`` of the joints of ``clip`` at any frames.

    Parameters
    ----------
    clip : Clip
    handmap : HandMap or None
        The hands whose finger joints (and the joints below them) are posed from ``clip``; None: ``world``
        is ``clip``'s own.
    world : (T, J, 4, 4) float, optional
        World transforms of a clip that differs from ``clip`` at most in those joints (the input a
        synthesized clip was made from). None: ``clip``'s own forward kinematics, every joint.
    """

    def __init__(self, clip: Clip, handmap: HandMap | None, world: np.ndarray | None):
        self.clip = clip
        parents = clip.skeleton.parents
        self.dirty = np.zeros(clip.num_joints, dtype=bool)
        if world is None:
            world = clip.world_xforms()
        elif handmap is not None:
            fingers = {clip.skeleton.index(j) for hand in handmap.sides for j in hand.finger_joints}
            for j in range(clip.num_joints):  # parents come before children
                self.dirty[j] = j in fingers or (parents[j] >= 0 and self.dirty[parents[j]])
        self.world = world

    def at(self, joints, frames: np.ndarray | None = None) -> list[np.ndarray]:
        """World transforms of ``joints`` (skeleton indices) at ``frames`` ``(K,)`` (all frames by
        default): a list of ``(K, 4, 4)`` arrays, one per joint."""
        parents = self.clip.skeleton.parents
        rows = slice(None) if frames is None else np.asarray(frames, dtype=np.int64)
        done: dict[int, np.ndarray] = {}

        def get(j: int) -> np.ndarray:
            if j in done:
                return done[j]
            if not self.dirty[j]:
                out = self.world[rows, j]
            else:
                c = self.clip
                local = trs_to_xform(c.translations[rows, j], c.rotations[rows, j], c.scales[rows, j])
                p = int(parents[j])
                out = local if p < 0 else get(p) @ local
            done[j] = out
            return out

        return [get(int(j)) for j in joints]


def chain_path(parents: np.ndarray, joints) -> list[int]:
    """Every joint from the chain's first joint to its last, each below the one before (roll or twist
    joints between two chain joints included), root side first."""
    path = []
    j = int(joints[-1])
    first = int(joints[0])
    while j != first and j >= 0:
        path.append(j)
        j = int(parents[j])
    path.append(first)
    return path[::-1]


def chain_reach(clip: Clip, joints, tip_offset: np.ndarray, parent_world: np.ndarray) -> np.ndarray:
    """How far any joint or the tip of a chain can be from its parent joint, in any rotations, ``(T,)``
    clip units: each offset's length times the largest scale of the transforms above it (the parent's
    linear part by its Frobenius norm, each joint's by its largest absolute scale), summed.

    Parameters
    ----------
    joints : sequence of int
        The chain's joints, proximal to distal (each below the one before).
    tip_offset : (3,) float
        The tip in the last joint's frame.
    parent_world : (T, 4, 4) float
        The chain's parent joint's world transforms.
    """
    gain = np.sqrt(np.einsum("tij,tij->t", parent_world[:, :3, :3], parent_world[:, :3, :3]))
    reach = np.zeros(len(parent_world))
    for j in chain_path(clip.skeleton.parents, joints):
        reach += gain * np.linalg.norm(clip.translations[:, j], axis=1)
        gain = gain * np.abs(clip.scales[:, j]).max(axis=1)
    return reach + gain * float(np.linalg.norm(tip_offset))


def reachable_frames(colliders, centre: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Frames ``(K,)`` where the ball of ``radius`` ``(T,)`` around ``centre`` ``(T, 3)`` comes within
    a hair (a relative 1e-6 of the radius) of some collider's box; every point farther than that from
    all of them is farther than ``radius`` from every collider at the other frames."""
    frames = np.arange(len(centre))
    r = (np.asarray(radius, dtype=np.float64) * (1.0 + 1e-6))[:, None]
    return frames[colliders.bbox_gap(frames, centre - r, centre + r) <= 0]

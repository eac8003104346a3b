"""The character's own body as colliders (``--self``): capsules around the torso, head, upper
arms and thighs, following the skeleton.

Joints are found from the hand map (hips, shoulders, elbows) and by name (neck, head,
thighs, knees); a part whose joints cannot be found is left out. Radii are fractions of
the character's height (its rest pose's extent along the up axis), for an average adult:
torso 7.5%, head 5.5%, upper arm 2.5%, thigh 3.5%.
"""

from __future__ import annotations

import re

import numpy as np

from usdhands.algorithms.interaction.colliders import CapsuleCollider
from usdhands.model.clip import Clip
from usdhands.model.handmap import HandMap

__all__ = ["body_collider", "RADIUS_OF_HEIGHT"]

#: Capsule radius of each body part as a fraction of the character's height.
RADIUS_OF_HEIGHT = {"torso": 0.075, "head": 0.055, "upper arm": 0.025, "thigh": 0.035}

_NAMES = {
    "neck": re.compile(r"neck", re.I),
    "head": re.compile(r"^(?!.*(end|top|nub|tip)).*head", re.I),
    "left thigh": re.compile(r"(left.*(upleg|thigh|upperleg))|((upleg|thigh|upperleg).*(_l|\.l|left)$)|^l_?(thigh|upleg)", re.I),
    "right thigh": re.compile(r"(right.*(upleg|thigh|upperleg))|((upleg|thigh|upperleg).*(_r|\.r|right)$)|^r_?(thigh|upleg)", re.I),
}


def _find(skeleton, pattern) -> int | None:
    for i, n in enumerate(skeleton.short_names):
        if pattern.search(n):
            return i
    return None


def _first_child(skeleton, j: int) -> int | None:
    kids = skeleton.children(j)
    return kids[0] if kids else None


def body_collider(clip: Clip, handmap: HandMap) -> CapsuleCollider | None:
    """Capsules for the body parts that can be found, at every frame of ``clip`` (None when none can)."""
    sk = clip.skeleton
    world = clip.world_positions()
    rest = sk.rest_world_positions()
    up = 1 if sk.up_axis == "Y" else 2
    height = float(np.ptp(rest[:, up])) or 1.0
    parts: list[tuple[int, int | np.ndarray, float]] = []  # joint a, joint b (or offset), radius
    names: list[str] = []

    def add(a, b, part, name=None):
        if a is not None and b is not None and a != b:
            parts.append((a, b, RADIUS_OF_HEIGHT[part] * height))
            names.append(name or part)

    hips = next((sk.index(h.root) for h in handmap.sides if h.root), None)
    neck = _find(sk, _NAMES["neck"])
    head = _find(sk, _NAMES["head"])
    add(hips, neck, "torso")
    if head is not None:
        top = _first_child(sk, head)
        parts.append((head, top if top is not None else -1, RADIUS_OF_HEIGHT["head"] * height))
        names.append("head")
    for hand in handmap.sides:
        if hand.shoulder and hand.forearm:
            add(sk.index(hand.shoulder), sk.index(hand.forearm), "upper arm", f"{hand.side} upper arm")
    for side in ("left", "right"):
        thigh = _find(sk, _NAMES[f"{side} thigh"])
        if thigh is not None:
            add(thigh, _first_child(sk, thigh), "thigh", f"{side} thigh")
    if not parts:
        return None
    T = clip.num_frames
    a = np.empty((T, len(parts), 3))
    b = np.empty((T, len(parts), 3))
    radii = np.empty(len(parts))
    upv = np.zeros(3)
    upv[up] = 1.0
    for k, (ja, jb, r) in enumerate(parts):
        a[:, k] = world[:, ja]
        if jb == -1:  # a head without a top joint: up from the head joint by twice its radius
            b[:, k] = world[:, ja] + clip.world_xforms()[:, ja, :3, :3] @ (upv * 2 * r)
        else:
            b[:, k] = world[:, jb]
        radii[k] = r
    return CapsuleCollider("body", a, b, radii, tuple(names))

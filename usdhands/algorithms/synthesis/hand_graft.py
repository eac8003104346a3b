"""Adding finger joints to a skeleton that has none, copied from a database's hand.

A database records, per side, the rest geometry of the hand it was built from
(:func:`hand_template`): each finger joint's offset from its parent and its rest
orientation, both in a hand frame (forward along the forearm, side towards the
character's front, normal), in centimetres.
:func:`graft_hands` rebuilds that hand on a character's wrist joint, in the
character's hand frame and scaled by the ratio of the characters' reach.

A skeleton without fingers has no finger offsets to build its hand frame from, so
it is guessed from the rest pose: forward along the forearm (elbow to wrist), side
towards the character's front (+Z, Y up: the thumb of a T-pose with palms down, as
in the generated humanoid and Mixamo rigs), or, where the forearm points forwards,
upwards.
"""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from usdhands.algorithms.synthesis.finger_transfer import SLOTS_PER_FINGER
from usdhands.algorithms.synthesis.wrist_features import guess_hand_frame, reach_cm, world_rotations
from usdhands.model.clip import Clip
from usdhands.model.handmap import FINGERS, HandMap, HandSide
from usdhands.model.skeleton import Skeleton, short_joint_name

__all__ = ["hand_template", "mirror_template", "find_wrists", "guess_hand_frame", "graft_hands"]

_FINGER_WORDS = ("thumb", "index", "middle", "ring", "pinky", "pinkie", "little", "finger", "palm", "metacarpal")


def hand_template(skeleton: Skeleton, hand: HandSide) -> dict:
    """The rest geometry of a hand, for :func:`graft_hands` (JSON-ready).

    Returns
    -------
    dict
        ``{"reach_cm": float, "joints": [{"name", "parent", "slot", "offset_cm",
        "rotation"}]}``: ``parent`` is an index into ``joints`` or -1 for the wrist,
        ``slot`` the canonical slot (``"index.d2"``) or None for end joints,
        ``offset_cm`` the rest offset from the parent and ``rotation`` (xyzw) the rest
        orientation, both in the hand frame.
    """
    rest = skeleton.rest_world_xforms()
    cm = skeleton.meters_per_unit * 100.0
    w = skeleton.index(hand.wrist)
    # the frame a fingerless skeleton can rebuild, so grafting onto this very rig is exact
    Hw = guess_hand_frame(skeleton, w, skeleton.index(hand.forearm) if hand.forearm else None)
    joints, index = [], {}
    for f in FINGERS:
        chain = [skeleton.index(j) for j in hand.fingers[f]]
        ends = skeleton.children(chain[-1]) if chain else []
        ends = [e for e in ends if not skeleton.children(e)][:1]
        n = len(chain)
        for k, j in enumerate(chain + ends):
            p = int(skeleton.parents[j])
            slot = None
            if k < n and n - 1 - k < SLOTS_PER_FINGER:
                slot = f"{f}.d{n - 1 - k}"
            off = Hw.T @ (rest[j, :3, 3] - rest[p, :3, 3]) * cm
            rot = Hw.T @ world_rotations(rest[j])
            index[j] = len(joints)
            joints.append({"name": short_joint_name(skeleton.joint_names[j]),
                           "parent": index.get(p, -1) if p != w else -1,
                           "slot": slot, "offset_cm": [float(x) for x in off],
                           "rotation": [float(x) for x in Rotation.from_matrix(rot).as_quat()]})
    return {"reach_cm": float(reach_cm(skeleton, hand)), "joints": joints}


def find_wrists(skeleton: Skeleton) -> dict:
    """Wrist joints by name on a skeleton without fingers: ``{"left": index, "right": index}``.

    A wrist is a joint whose short name holds "hand" or "wrist" and a side mark
    (Left/Right, L/R, .L, _l, ...) and no finger word; the one nearest the root wins.
    """
    found: dict = {}
    for j, name in enumerate(skeleton.short_names):
        s = name.split(":")[-1]
        low = s.lower()
        if not ("hand" in low or "wrist" in low) or any(w in low for w in _FINGER_WORDS):
            continue
        words = re.sub(r"([a-z])([A-Z])", r"\1 \2", s).lower()
        tokens = re.split(r"[^a-z]+", words)
        for side, marks in (("left", ("left", "l")), ("right", ("right", "r"))):
            if any(t in marks for t in tokens) or low.startswith(side) or low.endswith(side):
                depth = len(skeleton.chain_to_root(j))
                if side not in found or depth < found[side][0]:
                    found[side] = (depth, j)
    return {side: j for side, (_, j) in found.items()}


def mirror_template(template: dict) -> dict:
    """The template of the other hand (the hand frame's normal flips under the mirror)."""
    S = np.diag([1.0, 1.0, -1.0])
    joints = []
    for spec in template["joints"]:
        R = Rotation.from_quat(spec["rotation"]).as_matrix()
        name = spec["name"]
        for a, b in (("Left", "Right"), ("left", "right"), (".L", ".R"), ("_l", "_r"), ("_L", "_R")):
            if a in name:
                name = name.replace(a, b)
                break
            if b in name:
                name = name.replace(b, a)
                break
        joints.append({**spec, "name": name, "offset_cm": [float(x) for x in S @ np.asarray(spec["offset_cm"])],
                       "rotation": [float(x) for x in Rotation.from_matrix(S @ R @ S).as_quat()]})
    return {"reach_cm": template["reach_cm"], "joints": joints}


def graft_hands(clip: Clip, wrists: dict, templates: dict, names_from: str = "template") -> tuple[Clip, HandMap, list]:
    """Add finger joints from hand templates under the given wrists.

    Parameters
    ----------
    clip : Clip
        The animation; its skeleton gets the new joints (appended, held at rest).
    wrists : dict of side to HandSide
        For each side to graft, a hand map entry naming at least the wrist (and the
        forearm and root where known); its ``fingers`` are ignored.
    templates : dict of side to dict
        :func:`hand_template` results.

    Returns
    -------
    clip : Clip
        On the new skeleton (old joints keep their indices and animation).
    handmap : HandMap
        The grafted hands.
    added : list of str
        Names of the joints added.
    """
    sk = clip.skeleton
    rest = sk.rest_world_xforms()
    cm = sk.meters_per_unit * 100.0
    names = list(sk.joint_names)
    parents = list(int(p) for p in sk.parents)
    rest_t = list(sk.rest_translations)
    rest_q = list(sk.rest_rotations)
    rest_s = list(sk.rest_scales)
    bind = None if sk.bind_xforms is None else list(sk.bind_xforms)
    sides, added = {}, []
    for side, hand in wrists.items():
        tpl = templates.get(side)
        if tpl is None:
            raise ValueError(f"No hand template for the {side} side")
        w = sk.index(hand.wrist)
        forearm = sk.index(hand.forearm) if hand.forearm else None
        Hw = guess_hand_frame(sk, w, forearm)
        probe = HandSide(side, hand.wrist, hand.forearm, hand.shoulder, hand.root)
        scale = reach_cm(sk, probe) / float(tpl["reach_cm"])
        new_index, world = [], []
        chains = {f: [] for f in FINGERS}
        for spec in tpl["joints"]:
            p_new = spec["parent"]
            p = w if p_new < 0 else new_index[p_new]
            pw = rest[w] if p_new < 0 else world[p_new]
            pos = pw[:3, 3] + Hw @ np.asarray(spec["offset_cm"]) * scale / cm
            rot = Hw @ Rotation.from_quat(spec["rotation"]).as_matrix()
            W = np.eye(4)
            W[:3, :3] = rot
            W[:3, 3] = pos
            local = np.linalg.inv(pw) @ W
            lr = local[:3, :3] / np.linalg.norm(local[:3, :3], axis=0, keepdims=True)
            base = spec["name"]
            name = base if not any(short_joint_name(n) == base for n in names) else f"{short_joint_name(hand.wrist)}_{base}"
            if "/" in names[p]:
                name = f"{names[p]}/{name}"
            names.append(name)
            parents.append(p)
            rest_t.append(local[:3, 3])
            rest_q.append(Rotation.from_matrix(lr).as_quat())
            rest_s.append(np.ones(3))
            if bind is not None:
                bind.append(W)
            new_index.append(len(names) - 1)
            world.append(W)
            added.append(name)
            if spec["slot"]:
                chains[spec["slot"].split(".")[0]].append(name)
        sides[side] = HandSide(side, hand.wrist, hand.forearm, hand.shoulder, hand.root, fingers=chains)
    new_sk = Skeleton(names, np.array(parents), np.array(rest_t), np.array(rest_q), np.array(rest_s),
                      None if bind is None else np.array(bind), sk.meters_per_unit, sk.up_axis, sk.name)
    T, J, n = clip.num_frames, sk.num_joints, new_sk.num_joints - sk.num_joints
    rot = np.concatenate([clip.rotations, np.broadcast_to(new_sk.rest_rotations[J:], (T, n, 4))], axis=1)
    tr = np.concatenate([clip.translations, np.broadcast_to(new_sk.rest_translations[J:], (T, n, 3))], axis=1)
    sc = np.concatenate([clip.scales, np.ones((T, n, 3))], axis=1)
    return clip.replace(skeleton=new_sk, rotations=rot, translations=tr, scales=sc), HandMap(**sides), added

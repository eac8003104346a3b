"""Finding the hands of a skeleton from its joint names and hierarchy.

:func:`detect_hands` reads every joint name as a list of lower-case *tokens*
(``"mixamorig:LeftHandIndex1"`` → ``left hand index 1``, ``"index_01_l"`` →
``index 01 l``, ``"thumb-phalanx-proximal"`` → ``thumb phalanx proximal``) after
dropping USD path prefixes, namespaces (``ns:``) and Maya DAG prefixes (``a|b``), and
classifies each joint:

- **side**: a token ``left``/``l``/``lf``/``lft`` or ``right``/``r``/``rt``/``rgt``
  anywhere in the name (``LeftHand``, ``L_Index1``, ``index1.L``, ``hand_l``,
  ``rHand``, ``Bip01 L Hand``); a joint without one takes the side of its nearest
  sided ancestor; a hand whose joints carry no side at all (WebXR) takes the
  ``side_hint``, or the side named in the skeleton's name.
- **finger**: ``thumb``; ``index``/``pointer``/``forefinger``; ``middle``/``mid``;
  ``ring``; ``pinky``/``pinkie``/``little``; a number after ``finger``: Rokoko's
  ``Finger1Proximal`` and MakeHuman's ``finger1-2.L`` count from 1 (thumb … pinky),
  3ds Max Biped's ``Finger0``, ``Finger01``, ``Finger1`` … from 0 (the skeleton is read
  as Biped when it has a ``Finger0``). Names with ``foot``/``toe`` (HumanIK's foot
  fingers), and joints in a head, leg or tail branch (``EarRing.L`` under ``Head``),
  are no fingers.
- **end joints**, which carry no DOF and are left out of the chains: names with a
  token ``end``, ``nub``, ``tip``, ``leaf``, ``site`` (``*_end``, ``*Nub``,
  ``*-tip``, BVH End Sites read as ``<parent>_end``), and leaf joints numbered 4 or
  more (Mixamo/HumanIK ``LeftHandIndex4``).
- **wrist** candidates: ``hand`` or ``wrist`` without a finger word (``LeftHand``,
  ``hand_l``, ``left_wrist``, ``rHand``, ``wrist``).

Per side, the finger chains are the finger joints ordered from the wrist outwards
(by depth in the hierarchy, then by the segment the name gives: metacarpal,
proximal, intermediate/medial, distal, or the joint's number, which orders flat
hierarchies such as the WebXR hand, where every joint is a sibling; helper joints
inside a finger are skipped). The wrist is the named wrist candidate that the most
chains hang below (the deepest on a tie); chains that do not hang below it are
dropped. In a flat hierarchy the wrist-named joint is taken as it is. A rig without a wrist joint takes as
wrist the lowest common ancestor of its finger chains: on RobotExpressive
(``LowerArm.L`` → ``Palm1.L`` → ``Index.L`` → ``Index2.L``, thumb directly under
``LowerArm.L``) that is ``LowerArm.L``. Unnamed joints between the wrist and one
finger chain only (``Palm1.L``) are that finger's metacarpal and are put at the start
of its chain; joints shared by several fingers (a common palm) are not.

Above the wrist: the **forearm** is the nearest ancestor named ``forearm``,
``lowerarm`` or ``elbow`` (twist and roll joints skipped), else the wrist's parent;
the **shoulder** (upper arm) is the nearest ancestor of the forearm named
``upperarm``, ``arm``, ``shoulder``, ``shldr`` (Daz) or ``humerus``, else the
forearm's parent; the **root** is the nearest ancestor named ``hips``/``hip``/``pelvis``, else the topmost
ancestor of the wrist (None when that is the wrist itself). On RobotExpressive, whose
wrist is ``LowerArm.L``, the forearm is therefore ``UpperArm.L`` and the shoulder
``Shoulder.L``: the joints above the wrist shift by one, the nearest stand-ins the rig
has.

:func:`load_handmap` reads a JSON override (``schemas/handmap.schema.json``) instead;
:func:`resolve_handmap` picks one or the other.
"""

from __future__ import annotations

import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path

from usdhands.errors import ConfigError, NoHandsError
from usdhands.input_files import read_json
from usdhands.json_schemas import first_schema_error, load_schema
from usdhands.model.handmap import FINGERS, SIDES, HandMap, HandSide
from usdhands.model.skeleton import Skeleton

_log = logging.getLogger(__name__)

__all__ = ["detect_hands", "load_handmap", "resolve_handmap", "NoHandsError", "joint_tokens",
           "handmap_schema", "side_from_name"]

_LEFT = {"left", "l", "lf", "lft"}
_RIGHT = {"right", "r", "rt", "rgt"}
_FINGER_WORDS = {
    "thumb": "thumb", "pollex": "thumb",
    "index": "index", "pointer": "index", "forefinger": "index",
    "middle": "middle", "mid": "middle",
    "ring": "ring",
    "pinky": "pinky", "pinkie": "pinky", "little": "pinky",
}
_END_WORDS = {"end", "nub", "tip", "leaf", "site", "effector"}
_NOT_FINGER_WORDS = {"foot", "toe", "toes", "leg", "twist", "roll", "ik", "pole", "target"}
_SEGMENT_RANK = {"metacarpal": 0, "meta": 0, "carpal": 0, "proximal": 1, "prox": 1,
                 "intermediate": 2, "inter": 2, "medial": 2, "distal": 3, "dist": 3}
_OFF_ARM_WORDS = {"head", "jaw", "eye", "ear", "leg", "upleg", "thigh", "knee", "calf", "shin", "foot",
                  "toe", "toes", "tail"}
_HELPER_WORDS = {"twist", "roll", "share", "helper", "ik", "pole", "target"}

_MAX_LISTED = 40


def joint_tokens(name: str) -> list[str]:
    """Lower-case words of a joint name, without path, namespace or DAG prefixes.

    ``"mixamorig:LeftHandIndex1"`` → ``["left", "hand", "index", "1"]``;
    ``"index_metacarpal_l"`` → ``["index", "metacarpal", "l"]``.
    """
    base = re.split(r"[/:|]", name)[-1]
    out = []
    for piece in re.split(r"[^A-Za-z0-9]+", base):
        out.extend(t.lower() for t in re.findall(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|\d+", piece))
    return out


@dataclass
class _Joint:
    index: int
    tokens: list
    side: str | None  # own side token
    finger: str | None
    rank: float  # segment order inside the finger
    number: int | None
    is_end: bool
    is_wrist_name: bool
    core: str  # name without side tokens and digits, lower case, concatenated


def _classify(skeleton: Skeleton) -> list[_Joint]:
    J = skeleton.num_joints
    has_child = [False] * J
    for p in skeleton.parents:
        if p >= 0:
            has_child[p] = True
    all_tokens = [joint_tokens(n) for n in skeleton.short_names]
    biped = any(a == "finger" and b == "0" for toks in all_tokens for a, b in zip(toks, toks[1:]))
    # joints in a head, leg or tail branch are never fingers ("EarRing.L" under "Head"); not "neck":
    # some rigs hang the shoulders from the neck
    off_arm = [False] * J
    for j, toks in enumerate(all_tokens):
        p = int(skeleton.parents[j])
        off_arm[j] = bool(set(toks) & _OFF_ARM_WORDS) or (p >= 0 and off_arm[p])
    out = []
    for j, toks in enumerate(all_tokens):
        tokset = set(toks)
        side = None
        if tokset & _LEFT and not tokset & _RIGHT:
            side = "left"
        elif tokset & _RIGHT and not tokset & _LEFT:
            side = "right"
        finger = None
        number = None
        for t in toks:
            if t in _FINGER_WORDS:
                finger = _FINGER_WORDS[t]
                break
        digits = [int(t) for t in toks if t.isdigit()]
        if finger is None:
            for k in range(len(toks) - 1):
                a, b = toks[k], toks[k + 1]
                if a != "finger" or not b.isdigit():
                    continue
                if biped:  # 3ds Max Biped: Finger0 (thumb) ... Finger4; Finger01, Finger02 the next segments
                    if int(b[0]) <= 4:
                        finger, digits = FINGERS[int(b[0])], [len(b) - 1]
                elif len(b) == 1 and 1 <= int(b) <= 5:  # Rokoko Finger2Proximal, MakeHuman finger2-1
                    finger = FINGERS[int(b) - 1]
                    rest = toks[k + 2:]
                    digits = [int(rest[0])] if rest and rest[0].isdigit() else []
                break
        if tokset & _NOT_FINGER_WORDS or off_arm[j]:
            finger = None
        if digits:
            number = digits[-1]
        rank = 1.5
        for t in toks:
            if t in _SEGMENT_RANK:
                rank = _SEGMENT_RANK[t]
                break
        else:
            if "in" in tokset and "hand" in tokset:  # HumanIK LeftInHandIndex
                rank = 0
            elif number is not None:
                rank = number
        is_end = bool(tokset & _END_WORDS) or (not has_child[j] and finger is not None
                                                and number is not None and number >= 4)
        is_wrist_name = finger is None and bool(tokset & {"hand", "wrist"}) and not is_end \
            and not tokset & (_HELPER_WORDS | _NOT_FINGER_WORDS)
        core = "".join(t for t in toks if t not in _LEFT and t not in _RIGHT and not t.isdigit())
        out.append(_Joint(j, toks, side, finger, rank, number, is_end, is_wrist_name, core))
    return out


def _ancestors(skeleton: Skeleton, j: int) -> list[int]:
    """Strict ancestors of ``j``, nearest first."""
    return skeleton.chain_to_root(j)[1:]


def _depth(skeleton: Skeleton, j: int) -> int:
    return len(skeleton.chain_to_root(j)) - 1


def _lca(skeleton: Skeleton, joints: list[int]) -> int | None:
    common = None
    for j in joints:
        chain = skeleton.chain_to_root(j)
        if common is None:
            common = chain
        else:
            s = set(chain)
            common = [c for c in common if c in s]
    return common[0] if common else None


def _order_chain(skeleton: Skeleton, joints: list[_Joint]) -> list[int]:
    """One proximal→distal chain out of a finger's joints."""
    js = sorted(joints, key=lambda c: (_depth(skeleton, c.index), c.rank, c.index))
    depths = {_depth(skeleton, c.index) for c in js}
    if len(depths) == 1:  # flat hierarchy: the names give the order
        return [c.index for c in js]
    rank = {c.index: c.rank for c in js}
    chain = [js[0].index]
    while True:  # the nearest member below the last one (helper joints in between are skipped)
        below = [k for k in rank if k not in chain and chain[-1] in _ancestors(skeleton, k)]
        if not below:
            break
        chain.append(min(below, key=lambda k: (_depth(skeleton, k), rank[k], k)))
    return chain


def side_from_name(text: str) -> str | None:
    """The side a name or path says, e.g. ``"webxr/left.glb"`` → ``"left"``; None if none or both.

    Every path element counts; file extensions are ignored. For commands to pass a
    ``side_hint`` from a file name.
    """
    toks = set()
    for part in re.split(r"[/\\]", str(text)):
        part = re.sub(r"\.[A-Za-z0-9]+$", "", part)
        toks.update(joint_tokens(part.replace(":", "_").replace("|", "_")))
    if toks & _LEFT and not toks & _RIGHT:
        return "left"
    if toks & _RIGHT and not toks & _LEFT:
        return "right"
    return None


def _side_of_skeleton_name(skeleton: Skeleton) -> str | None:
    return side_from_name(skeleton.name)


def _looked_for() -> str:
    return ("looked for finger joints named thumb, index (pointer), middle (mid), ring, pinky (little) "
            "or Finger1..5, with a side (Left/Right, L/R, l/r, .L, _l, left_ ...), below a wrist "
            "(hand, wrist)")


def _seen(skeleton: Skeleton) -> str:
    names = skeleton.short_names
    shown = ", ".join(names[:_MAX_LISTED])
    more = len(names) - _MAX_LISTED
    return f"saw {len(names)} joints: {shown}" + (f" (and {more} more)" if more > 0 else "")


def detect_hands(skeleton: Skeleton, side_hint: str | None = None) -> HandMap:
    """Find the wrists, arms, root and finger chains of both hands.

    Parameters
    ----------
    skeleton : Skeleton
    side_hint : {"left", "right"}, optional
        The side of a hand whose joint names carry no side (WebXR single-hand
        skeletons); when omitted, the side named in ``skeleton.name`` is used.

    Returns
    -------
    HandMap
        Joint names as they stand in ``skeleton.joint_names``; a side with no hand
        found is None.

    Raises
    ------
    NoHandsError
        No hand at all; the message lists the joints seen and what was looked for.
    ValueError
        ``side_hint`` is not ``"left"``, ``"right"`` or None.
    """
    if side_hint is not None and side_hint not in SIDES:
        raise ValueError(f"Expected side_hint 'left', 'right' or None, got {side_hint!r}")
    joints = _classify(skeleton)
    # inherited side: own token, else the nearest sided ancestor
    side = [None] * skeleton.num_joints
    for jt in joints:
        p = int(skeleton.parents[jt.index])
        side[jt.index] = jt.side or (side[p] if p >= 0 else None)
    sideless_hint = side_hint or _side_of_skeleton_name(skeleton)
    sideless_fingers = False
    for jt in joints:
        if side[jt.index] is None and (jt.finger or jt.is_wrist_name):
            if sideless_hint is None:
                sideless_fingers = sideless_fingers or jt.finger is not None
            else:
                side[jt.index] = sideless_hint
    hands = {s: _detect_side(skeleton, joints, side, s) for s in SIDES}
    if hands["left"] is None and hands["right"] is None:
        extra = ""
        if sideless_fingers:
            extra = ("; finger joints were found but their names give no side: pass side_hint "
                     "'left' or 'right' (usdhands handmap --side)")
        raise NoHandsError(f"no hand found in skeleton {skeleton.name!r}{extra}; {_looked_for()}; "
                           f"{_seen(skeleton)}")
    for s in SIDES:
        h = hands[s]
        if h is None:
            _log.info("skeleton %r: no %s hand found", skeleton.name, s)
        else:
            _log.info("skeleton %r: %s hand at %r, fingers %s", skeleton.name, s, h.wrist,
                      ", ".join(f"{f} {len(h.fingers.get(f, ()))}" for f in FINGERS))
    return HandMap(left=hands["left"], right=hands["right"])


def _detect_side(skeleton: Skeleton, joints: list[_Joint], side: list, s: str) -> HandSide | None:
    names = skeleton.joint_names
    fingers: dict[str, list[_Joint]] = {f: [] for f in FINGERS}
    for jt in joints:
        if side[jt.index] == s and jt.finger and not jt.is_end:
            fingers[jt.finger].append(jt)
    chains = {f: _order_chain(skeleton, js) for f, js in fingers.items() if js}
    if not chains:
        return None
    starts = {f: c[0] for f, c in chains.items()}
    wrist_cands = [jt.index for jt in joints if side[jt.index] == s and jt.is_wrist_name]
    wrist = None
    if wrist_cands:
        scored = []
        for w in wrist_cands:
            n = sum(w in _ancestors(skeleton, st) for st in starts.values())
            scored.append((n, _depth(skeleton, w), -w, w))
        n, _, _, best = max(scored)
        flat = all(len({_depth(skeleton, j) for j in c}) == 1 for c in chains.values())
        if n > 0:
            wrist = best
            chains = {f: c for f, c in chains.items() if wrist in _ancestors(skeleton, c[0])}
        elif flat:  # flat hierarchy (WebXR's glTF): the shallowest wrist-named joint
            wrist = min(wrist_cands, key=lambda w: (_depth(skeleton, w), w))
    if wrist is None:
        lca = _lca(skeleton, list(starts.values()))
        if lca is None:
            return None
        if lca in starts.values():  # a single chain: the wrist is its parent
            lca = int(skeleton.parents[lca])
            if lca < 0:
                return None
        wrist = lca
    # metacarpals: unnamed joints between the wrist and one chain only
    paths = {}
    for f, c in chains.items():
        anc = _ancestors(skeleton, c[0])
        if wrist in anc:
            paths[f] = anc[:anc.index(wrist)]
        else:
            paths[f] = []
    by_finger_name = {jt.index for jt in joints if jt.finger}
    for f, path in paths.items():
        extra = [a for a in path if a not in by_finger_name
                 and not any(a in p for g, p in paths.items() if g != f)]
        if extra:
            chains[f] = list(reversed(extra)) + chains[f]
    forearm = _nearest(skeleton, joints, wrist, _is_forearm)
    shoulder = _nearest(skeleton, joints, forearm, _is_upper_arm) if forearm is not None else None
    root = _nearest(skeleton, joints, wrist, _is_hips, fallback=False)
    if root is None:
        top = skeleton.chain_to_root(wrist)[-1]
        root = None if top == wrist else top
    nm = lambda j: None if j is None else names[j]  # noqa: E731
    return HandSide(side=s, wrist=names[wrist], forearm=nm(forearm), shoulder=nm(shoulder), root=nm(root),
                    fingers={f: tuple(names[j] for j in c) for f, c in chains.items()})


def _nearest(skeleton: Skeleton, joints: list[_Joint], j: int, pred, fallback: bool = True) -> int | None:
    anc = _ancestors(skeleton, j)
    for a in anc:
        if pred(joints[a]):
            return a
    if fallback and anc:
        return anc[0]
    return None


def _is_helper(jt: _Joint) -> bool:
    return bool(set(jt.tokens) & _HELPER_WORDS)


def _is_forearm(jt: _Joint) -> bool:
    c = jt.core
    return not _is_helper(jt) and ("forearm" in c or "lowerarm" in c or "elbow" in c)


def _is_upper_arm(jt: _Joint) -> bool:
    c = jt.core
    return not _is_helper(jt) and ("upperarm" in c or c in ("arm", "shoulder") or "humerus" in c
                                   or c.endswith("shoulder") or c == "uparm" or c.startswith("shldr"))


def _is_hips(jt: _Joint) -> bool:
    c = jt.core
    return c in ("hips", "hip", "pelvis") or c.endswith("hips") or c.endswith("pelvis")


# -- JSON override ------------------------------------------------------------------

def handmap_schema() -> dict:
    """The JSON schema of hand map files (``usdhands/schemas/handmap.schema.json``)."""
    return load_schema("handmap")


def load_handmap(path: str | os.PathLike, skeleton: Skeleton) -> HandMap:
    """Read a hand map JSON file and check it against ``skeleton``.

    Parameters
    ----------
    path : path-like
        A file valid under ``schemas/handmap.schema.json``: ``{"left": {...} or null,
        "right": {...} or null}``, each side with ``wrist``, optional ``forearm``,
        ``shoulder``, ``root`` and ``fingers`` (finger name → joint names, proximal
        to distal).
    skeleton : Skeleton
        Joints may be named by full path or by unique short name; the returned map
        uses the skeleton's full names.

    Raises
    ------
    ConfigError
        Unreadable JSON, a schema violation (with its place in the file), or a joint
        the skeleton does not have.
    """

    path = Path(path)
    data = read_json(path, what="hand map file", error=ConfigError)
    error = first_schema_error(data, "handmap")
    if error is not None:
        where, message = error
        raise ConfigError(f"invalid hand map at {where}: {message}", path=path)
    sides = {}
    for s in SIDES:
        d = data.get(s)
        if d is None:
            sides[s] = None
            continue

        def full(name, what, s=s):
            if name is None:
                return None
            if not skeleton.has_joint(name):
                raise ConfigError(f"{s} {what}: joint {name!r} is not in skeleton {skeleton.name!r}", path=path)
            return skeleton.joint_names[skeleton.index(name)]

        fingers = {f: tuple(full(n, f"{f} finger") for n in d.get("fingers", {}).get(f, [])) for f in FINGERS}
        sides[s] = HandSide(side=s, wrist=full(d["wrist"], "wrist"), forearm=full(d.get("forearm"), "forearm"),
                            shoulder=full(d.get("shoulder"), "shoulder"), root=full(d.get("root"), "root"),
                            fingers=fingers)
    _check_structure(sides, skeleton, path)
    return HandMap(**sides)


def _check_structure(sides: dict, skeleton: Skeleton, path: Path) -> None:
    """Refuse a hand map whose joints exist but do not form hands.

    In a joint hierarchy, finger chains must hang below their wrist, proximal to distal,
    and the forearm must be above the wrist; no joint may be used twice (in two fingers
    or by both hands).
    """
    used: dict[str, str] = {}

    def claim(name: str, what: str) -> None:
        if name in used:
            raise ConfigError(f"{what}: joint {name!r} is already the {used[name]}", path=path)
        used[name] = what

    for s, hand in sides.items():
        if hand is None:
            continue
        w = skeleton.index(hand.wrist)
        claim(hand.wrist, f"{s} wrist")
        if hand.forearm is not None and skeleton.index(hand.forearm) not in skeleton.chain_to_root(w)[1:]:
            raise ConfigError(f"{s} forearm: joint {hand.forearm!r} is not above the wrist {hand.wrist!r}", path=path)
        for f in FINGERS:
            above = w
            for name in hand.fingers.get(f, ()):
                claim(name, f"{s} {f} finger")
                chain = skeleton.chain_to_root(skeleton.index(name))
                # flat rigs (WebXR: every joint a root) have no hierarchy to check
                if chain[-1] == skeleton.chain_to_root(above)[-1] and above not in chain[1:]:
                    what = "the wrist" if above == w else "the previous joint"
                    raise ConfigError(f"{s} {f} finger: joint {name!r} does not hang below {what} "
                                      f"{skeleton.joint_names[above]!r} (joints go proximal to distal)", path=path)
                above = skeleton.index(name)


def resolve_handmap(skeleton: Skeleton, override_path: str | os.PathLike | None = None,
                    side_hint: str | None = None) -> HandMap:
    """The hand map from ``override_path`` when given, else :func:`detect_hands`."""
    if override_path is not None:
        return load_handmap(override_path, skeleton)
    return detect_hands(skeleton, side_hint=side_hint)

"""The ``usdhands check`` rules on a USD stage, from the authored data as it is.

The reader (:mod:`usdhands.formats.usd_read`) refuses arrays that do not fit and NaN
rotations; the audit reports them instead, one :class:`~usdhands.model.findings.Finding`
per broken rule, naming the prim (and joint and time).
"""

from __future__ import annotations

import os

import numpy as np
from pxr import Usd, UsdSkel

from usdhands.errors import NoHandsError, UsdHandsError
from usdhands.formats.usd_common import bound_animation_path, open_stage, quiet_diagnostics, skeleton_tokens_and_names
from usdhands.formats.usd_read import read_skeleton, stage_units
from usdhands.formats.usd_schema_data import read_finger_motion, read_hand_map
from usdhands.model.findings import Finding, provenance_problem
from usdhands.model.hand_detection import detect_hands

__all__ = ["audit_usd", "audit_stage", "MAX_TIMES_CHECKED"]

_PREDICATE = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
#: a zero-length quaternion: norm below this
ZERO_NORM = 1e-6
#: time samples of an attribute checked (a finding names the first bad one)
MAX_TIMES_CHECKED = 100_000


def audit_usd(path: str | os.PathLike, *, require_provenance: bool = False) -> list[Finding]:
    """The findings of a USD file; :class:`~usdhands.errors.AssetReadError` when it cannot be opened."""
    stage = open_stage(path)
    stage_units(stage, path)  # units every reader refuses: unreadable here too, not a pass
    return audit_stage(stage, str(path), require_provenance=require_provenance)


def audit_stage(stage: Usd.Stage, name: str | None = None, *, require_provenance: bool = False,
                rules: tuple[str, ...] | None = None) -> list[Finding]:
    """The findings of an open stage as it composes now.

    Parameters
    ----------
    name : str, optional
        How findings name the file (default: the root layer's identifier).
    require_provenance : bool
        Every SkelAnimation that animates finger joints must carry ``UsdHandsFingerMotionAPI``
        (without it, only records that are there are checked).
    rules : tuple of str, optional
        Only these rules (keys of :data:`usdhands.model.findings.RULES`).
    """
    name = name or stage.GetRootLayer().identifier
    out: list[Finding] = []
    with quiet_diagnostics():
        for prim in stage.Traverse(_PREDICATE):
            if prim.IsA(UsdSkel.Skeleton):
                out += _skeleton(stage, prim, name, require_provenance)
            elif prim.IsA(UsdSkel.Animation):
                out += _animation(prim, name)
    if rules is not None:
        out = [f for f in out if f.rule in rules]
    return out


def _skeleton(stage: Usd.Stage, prim: Usd.Prim, name: str, require_provenance: bool) -> list[Finding]:
    where = str(prim.GetPath())
    skel = UsdSkel.Skeleton(prim)
    joints = list(skel.GetJointsAttr().Get() or [])
    out = []
    for attr in (skel.GetRestTransformsAttr(), skel.GetBindTransformsAttr()):
        value = attr.Get() if attr and attr.HasAuthoredValue() else None
        if value is not None and len(value) != len(joints):
            out.append(Finding(name, where, "array-lengths",
                               f"{attr.GetName()} has {len(value)} entries for {len(joints)} joints"))
    if out or not joints:
        return out
    try:
        handmap = read_hand_map(prim, path=name)
    except UsdHandsError as e:
        return [Finding(name, where, "hands", f"the recorded hand map is invalid: {e.message}")]
    if handmap is None:
        try:
            sk, _ = read_skeleton(skel, path=name)
            handmap = detect_hands(sk) if sk is not None else None
        except NoHandsError:
            handmap = None
        except UsdHandsError as e:
            return [Finding(name, where, "array-lengths", e.message)]
        if handmap is None:
            return [Finding(name, where, "hands", "no hand map recorded (UsdHandsHandMapAPI) and no hand detected "
                                                  "by joint names; give one with 'usdhands handmap'")]
    fingers = [j for h in handmap.sides for j in h.finger_joints]
    anim_path = bound_animation_path(prim)
    anim = stage.GetPrimAtPath(anim_path) if anim_path else None
    if not fingers or not anim or not anim.IsA(UsdSkel.Animation):
        return out
    tokens, names = skeleton_tokens_and_names(skel)
    token_of = dict(zip(names, tokens))
    animated = {str(t) for t in (UsdSkel.Animation(anim).GetJointsAttr().Get() or [])}
    missing = [j for j in fingers if token_of.get(j) not in animated]
    anim_where = str(anim.GetPath())
    if missing:
        out.append(Finding(name, anim_where, "finger-coverage",
                           f"animates {len(fingers) - len(missing)} of the {len(fingers)} finger joints of {where}; "
                           f"not: {', '.join(missing[:6])}{', ...' if len(missing) > 6 else ''}"))
    record = read_finger_motion(anim)
    if record is None and require_provenance and len(missing) < len(fingers):
        out.append(Finding(name, anim_where, "provenance",
                           "finger joints are animated but no UsdHandsFingerMotionAPI records how"))
    return out


def _animation(prim: Usd.Prim, name: str) -> list[Finding]:
    where = str(prim.GetPath())
    anim = UsdSkel.Animation(prim)
    joints = [str(t) for t in (anim.GetJointsAttr().Get() or [])]
    out = []
    for attr in (anim.GetRotationsAttr(), anim.GetTranslationsAttr(), anim.GetScalesAttr()):
        if not attr or not attr.HasAuthoredValue():
            continue
        times = attr.GetTimeSamples()[:MAX_TIMES_CHECKED] or [Usd.TimeCode.Default()]
        bad_len = bad_quat = None
        for t in times:
            value = attr.Get(t)
            if value is None:
                continue
            if bad_len is None and len(value) != len(joints):
                bad_len = (t, len(value))
            if bad_quat is None and attr.GetName() == "rotations":
                q = np.asarray(value, dtype=np.float64).reshape(-1, 4)
                norms = np.linalg.norm(q, axis=1)
                wrong = np.flatnonzero(~np.isfinite(norms) | (norms < ZERO_NORM))
                if wrong.size:
                    k = int(wrong[0])
                    what = "NaN or infinite" if not np.isfinite(norms[k]) else "zero-length"
                    joint = joints[k] if k < len(joints) else f"#{k}"
                    bad_quat = (t, joint, what, int(wrong.size))
            if bad_len is not None and (bad_quat is not None or attr.GetName() != "rotations"):
                break
        if bad_len is not None:
            t, n = bad_len
            out.append(Finding(name, where, "array-lengths",
                               f"{attr.GetName()} has {n} values for {len(joints)} joints{_at(t)}"))
        if bad_quat is not None:
            t, joint, what, count = bad_quat
            out.append(Finding(name, where, "quaternions",
                               f"{what} rotation of joint {joint}{_at(t)} ({count} in that sample)"))
    record = read_finger_motion(prim)
    if record is not None:
        problem = provenance_problem(record)
        if problem:
            out.append(Finding(name, where, "provenance", problem))
    return out


def _at(t) -> str:
    return "" if isinstance(t, Usd.TimeCode) else f" at time {float(t):g}"

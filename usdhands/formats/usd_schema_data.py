"""Authoring and reading the data of usdhands' applied API schemas on USD prims.

- ``UsdHandsHandMapAPI:left`` / ``:right`` on a Skeleton prim: which joints are the hand
  (``usdhands:hand:<side>:wrist``, ``forearm``, ``shoulder``, ``root`` tokens,
  ``thumb`` ... ``pinky`` token arrays; values are the Skeleton's joint tokens);
- ``UsdHandsFingerMotionAPI`` on a SkelAnimation (or Skeleton): how the finger motion
  was made (``usdhands:fingerMotion:method``, ``database``, ``parameters`` as JSON,
  ``version``).

Authoring and reading work through the ``apiSchemas`` metadata and typed attributes, so
they need no plugin registration; a process that has registered the plugin
(:mod:`usdhands.pipeline.usd_plugin`) also gets ``prim.HasAPI`` and the schema's
fallback values.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from pxr import Sdf, Usd, UsdSkel

from usdhands.errors import ConfigError
from usdhands.formats.usd_common import open_stage, quiet_diagnostics, skeleton_tokens_and_names
from usdhands.model.handmap import FINGERS, SIDES, HandMap, HandSide
from usdhands.model.provenance import FINGER_MOTION_METHODS

__all__ = [
    "HAND_MAP_API", "FINGER_MOTION_API", "FINGER_MOTION_METHODS", "write_hand_map", "read_hand_map",
    "write_finger_motion", "read_finger_motion", "read_hand_maps",
]

HAND_MAP_API = "UsdHandsHandMapAPI"
FINGER_MOTION_API = "UsdHandsFingerMotionAPI"
_SINGLE = ("wrist", "forearm", "shoulder", "root")


def _applied(prim: Usd.Prim) -> list[str]:
    """The applied schema names the prim's ``apiSchemas`` metadata lists (registered or not)."""
    op = prim.GetMetadata("apiSchemas")
    if op is None:
        return []
    return [str(x) for x in op.ApplyOperations([])]


def _hand_attr(side: str, name: str) -> str:
    return f"usdhands:hand:{side}:{name}"


def write_hand_map(skel_prim: Usd.Prim, hand_map: HandMap) -> None:
    """Apply ``UsdHandsHandMapAPI:<side>`` for each hand of ``hand_map`` and author its joints.

    Parameters
    ----------
    skel_prim : Usd.Prim
        A Skeleton prim; authored in the stage's edit target.
    hand_map : HandMap
        Joint names as the model has them for this skeleton (joint paths, or the
        original names the reader restored); written as the Skeleton's joint tokens.

    Raises
    ------
    ValueError
        ``skel_prim`` is not a Skeleton, or the map names joints the Skeleton lacks.
    """
    if not skel_prim.IsA(UsdSkel.Skeleton):
        raise ValueError(f"Expected a Skeleton prim, got {skel_prim.GetPath()} of type {skel_prim.GetTypeName()!r}")
    tokens, names = skeleton_tokens_and_names(UsdSkel.Skeleton(skel_prim))
    to_token = dict(zip(names, tokens))
    to_token.update({t: t for t in tokens})
    shorts: dict[str, str | None] = {}
    for n, t in zip(names, tokens):
        s = n.rsplit("/", 1)[-1]
        shorts[s] = t if s not in shorts else None

    def token(name: str | None) -> str:
        if name is None:
            return ""
        t = to_token.get(name) or shorts.get(name)
        if t is None:
            raise ValueError(f"Expected joints of skeleton {skel_prim.GetPath()}, got {name!r}")
        return t

    for hand in hand_map.sides:
        skel_prim.AddAppliedSchema(f"{HAND_MAP_API}:{hand.side}")
        for key in _SINGLE:
            attr = skel_prim.CreateAttribute(_hand_attr(hand.side, key), Sdf.ValueTypeNames.Token, False,
                                             Sdf.VariabilityUniform)
            attr.Set(token(getattr(hand, key)))
        for finger in FINGERS:
            attr = skel_prim.CreateAttribute(_hand_attr(hand.side, finger), Sdf.ValueTypeNames.TokenArray, False,
                                             Sdf.VariabilityUniform)
            attr.Set([token(j) for j in hand.fingers[finger]])


def read_hand_map(skel_prim: Usd.Prim, *, path: str | os.PathLike | None = None) -> HandMap | None:
    """The hand map a Skeleton prim carries through ``UsdHandsHandMapAPI``, or None.

    Joint names are given as the reader names them (joint paths, or restored originals).

    Raises
    ------
    ConfigError
        A side without a wrist, or naming joints the Skeleton lacks.
    """
    applied = _applied(skel_prim)
    sides = [s for s in SIDES if f"{HAND_MAP_API}:{s}" in applied]
    if not sides:
        return None
    tokens, names = skeleton_tokens_and_names(UsdSkel.Skeleton(skel_prim))
    to_name = dict(zip(tokens, names))
    where = str(skel_prim.GetPath())

    def name(t) -> str | None:
        t = str(t) if t is not None else ""
        if not t:
            return None
        if t not in to_name:
            raise ConfigError(f"{HAND_MAP_API} names joint {t!r}, which the skeleton does not have",
                              path=path, location=where)
        return to_name[t]

    out = {}
    for s in sides:
        values = {k: name(skel_prim.GetAttribute(_hand_attr(s, k)).Get()) for k in _SINGLE}
        if values["wrist"] is None:
            raise ConfigError(f"{HAND_MAP_API}:{s} has no wrist joint", path=path, location=where)
        fingers = {}
        for f in FINGERS:
            v = skel_prim.GetAttribute(_hand_attr(s, f)).Get()
            fingers[f] = tuple(name(t) for t in (v or []))
        out[s] = HandSide(side=s, fingers=fingers, **values)
    return HandMap(**out)


def write_finger_motion(prim: Usd.Prim, method: str, *, database: str | os.PathLike | None = None,
                        parameters: dict | None = None, version: str | None = None) -> None:
    """Apply ``UsdHandsFingerMotionAPI`` to a SkelAnimation (or Skeleton) and record how.

    Parameters
    ----------
    method : {"none", "synthesis", "interaction", "splicing", "reduction", "keyed"}
    database : path-like, optional
        The database or hand capture the motion came from (stored as a string, not an
        asset path, so packaging tools leave it alone).
    parameters : dict, optional
        JSON-serialisable parameters of the method.
    version : str, optional
        The usdhands version; the installed one when omitted.
    """
    if method not in FINGER_MOTION_METHODS:
        raise ValueError(f"Expected method in {FINGER_MOTION_METHODS}, got {method!r}")
    if not (prim.IsA(UsdSkel.Animation) or prim.IsA(UsdSkel.Skeleton)):
        raise ValueError(f"Expected a SkelAnimation or Skeleton prim, got {prim.GetPath()} "
                         f"of type {prim.GetTypeName()!r}")
    if version is None:
        from usdhands import __version__ as version
    prim.AddAppliedSchema(FINGER_MOTION_API)
    ns = "usdhands:fingerMotion:"
    prim.CreateAttribute(ns + "method", Sdf.ValueTypeNames.Token, False, Sdf.VariabilityUniform).Set(method)
    if database is not None:
        prim.CreateAttribute(ns + "database", Sdf.ValueTypeNames.String, False, Sdf.VariabilityUniform).Set(
            Path(database).as_posix())
    prim.CreateAttribute(ns + "parameters", Sdf.ValueTypeNames.String, False, Sdf.VariabilityUniform).Set(
        json.dumps(parameters or {}, sort_keys=True))
    prim.CreateAttribute(ns + "version", Sdf.ValueTypeNames.String, False, Sdf.VariabilityUniform).Set(str(version))


def read_finger_motion(prim: Usd.Prim) -> dict | None:
    """``{"method", "database", "parameters", "version"}`` of a prim with ``UsdHandsFingerMotionAPI``, or None."""
    if FINGER_MOTION_API not in _applied(prim):
        return None
    ns = "usdhands:fingerMotion:"

    def get(n, default):
        a = prim.GetAttribute(ns + n)
        v = a.Get() if a else None
        return default if v is None else v

    db = str(get("database", "")) or None
    try:
        params = json.loads(get("parameters", "{}") or "{}")
    except json.JSONDecodeError:
        params = {"_unparsed": get("parameters", "")}
    return {"method": str(get("method", "none")), "database": db,
            "parameters": params, "version": str(get("version", ""))}


def read_hand_maps(path: str | os.PathLike) -> dict[str, HandMap]:
    """Every hand map a USD file carries: ``{Skeleton prim path: HandMap}``."""
    stage = open_stage(path)
    out = {}
    with quiet_diagnostics():
        for prim in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)):
            if prim.IsA(UsdSkel.Skeleton):
                hm = read_hand_map(prim, path=path)
                if hm is not None:
                    out[str(prim.GetPath())] = hm
    return out

"""How an animation's finger motion was made: the provenance record usdhands writes.

One record is a dict ``{"method", "database", "parameters", "version"}``; USD files
carry it as ``UsdHandsFingerMotionAPI`` on the SkelAnimation, glTF files in the
animation's ``extras.usdhands.provenance`` (docs/usd-schema.md, docs/format-gltf.md).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

__all__ = ["FINGER_MOTION_METHODS", "provenance_record"]

FINGER_MOTION_METHODS = ("none", "synthesis", "interaction", "splicing", "reduction", "keyed")
_KEYS = ("method", "database", "parameters", "version")


def provenance_record(method: str | dict, *, database: str | os.PathLike | None = None,
                      parameters: dict | None = None, version: str | None = None) -> dict:
    """A complete, checked provenance record.

    Parameters
    ----------
    method : {"none", "synthesis", "interaction", "splicing", "reduction", "keyed"}, or dict
        The method; or a whole record (its keys are checked and missing ones filled).
    database : path-like, optional
        The database, hand capture or model the motion came from (a POSIX-style string).
    parameters : dict, optional
        JSON-serialisable parameters of the method (stored as their JSON round trip).
    version : str, optional
        The usdhands version; the installed one when omitted.

    Returns
    -------
    dict
        ``{"method": str, "database": str | None, "parameters": dict, "version": str}``

    Raises
    ------
    ValueError
        Unknown method or keys, parameters that are not a JSON object.
    """
    if isinstance(method, dict):
        unknown = set(method) - set(_KEYS)
        if unknown or "method" not in method:
            raise ValueError(f"Expected provenance keys {', '.join(_KEYS)} (method required), got {sorted(method)}")
        return provenance_record(method["method"], database=method.get("database"),
                                 parameters=method.get("parameters"), version=method.get("version"))
    if method not in FINGER_MOTION_METHODS:
        raise ValueError(f"Expected method in {FINGER_MOTION_METHODS}, got {method!r}")
    params = json.loads(json.dumps(parameters or {}, sort_keys=True, default=_jsonable))
    if not isinstance(params, dict):
        raise ValueError(f"Expected parameters as a dict, got {type(parameters).__name__}")
    if version is None:
        from usdhands import __version__ as version
    return {"method": method, "database": None if database is None else Path(database).as_posix(),
            "parameters": params, "version": str(version)}


def _jsonable(value):
    """Paths as strings, numpy scalars and arrays as numbers and lists."""
    if isinstance(value, os.PathLike):
        return Path(value).as_posix()
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"parameter value {value!r} of type {type(value).__name__} is not JSON")

"""A finding of ``usdhands check``: a rule a file breaks, and where."""

from __future__ import annotations

import json
from dataclasses import dataclass

from usdhands.model.provenance import FINGER_MOTION_METHODS

#: the rules, in the order ``usdhands check`` reports them, with what each asks of a file
RULES = {
    "hands": "every skeleton has its hands mapped (a recorded hand map) or detectable",
    "finger-coverage": "every animation of a skeleton with hands animates its finger joints",
    "quaternions": "no NaN, infinite or zero-length rotation quaternion",
    "array-lengths": "joint counts and the lengths of the arrays that go with them agree",
    "provenance": "finger motion usdhands made carries a well-formed provenance record",
    "props": "fingers do not penetrate the props named with --props",
}


@dataclass(frozen=True)
class Finding:
    """One broken rule.

    Attributes
    ----------
    file : str
        The file checked.
    where : str
        The prim path (USD), node or animation (glTF, ``animations[2]``), joint (BVH).
    rule : str
        A key of :data:`RULES`.
    message : str
        What is wrong, in one line.
    """

    file: str
    where: str
    rule: str
    message: str

    def __post_init__(self) -> None:
        if self.rule not in RULES:
            raise ValueError(f"Expected a rule in {sorted(RULES)}, got {self.rule!r}")

    def __str__(self) -> str:
        return f"{self.file}: {self.where}: {self.rule}: {self.message}"

    def to_json(self) -> dict:
        return {"file": self.file, "where": self.where, "rule": self.rule, "message": self.message}


def provenance_problem(record) -> str | None:
    """What is wrong with a finger-motion record ``{"method", "database", "parameters", "version"}``, or None."""
    if not isinstance(record, dict):
        return f"the provenance record is not an object: {json.dumps(record)[:60]}"
    if record.get("method") not in FINGER_MOTION_METHODS:
        return f"method {record.get('method')!r} is none of {', '.join(FINGER_MOTION_METHODS)}"
    params = record.get("parameters", {})
    if not isinstance(params, dict) or "_unparsed" in params:
        return f"parameters are not a JSON object: {json.dumps(params)[:60]}"
    if not record.get("version"):
        return "no usdhands version recorded"
    return None

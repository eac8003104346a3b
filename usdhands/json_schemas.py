"""The project's JSON schemas (shipped in ``usdhands/schemas/``) and checking data against them.

Each file format the project reads as JSON (hand maps, finger databases, synthesis
configurations, reduction models) has a schema; its module turns the first violation
found here into a :class:`~usdhands.errors.ConfigError` worded for that file.
"""

from __future__ import annotations

import functools
import json
from importlib import resources

__all__ = ["load_schema", "first_schema_error"]


@functools.lru_cache(maxsize=None)
def _schema_text(name: str) -> str:
    return resources.files("usdhands").joinpath(f"schemas/{name}.schema.json").read_text(encoding="utf-8")


def load_schema(name: str) -> dict:
    """The schema ``usdhands/schemas/<name>.schema.json`` as a fresh dict.

    Parameters
    ----------
    name : str
        ``"handmap"``, ``"database"``, ``"synthesis_config"`` or ``"reduction_model"``.
    """
    return json.loads(_schema_text(name))


def first_schema_error(data, name: str) -> tuple[str, str] | None:
    """Where and what the first violation of schema ``name`` in ``data`` is, or None.

    Returns
    -------
    (str, str) or None
        The JSON path of the offending value (``"left/fingers/index/0"``, or
        ``"(top level)"``) and the validator's message. Of several violations,
        jsonschema's ``best_match`` picks the most specific (inside ``oneOf`` branches
        too, where the first by path would only say "not valid under any of the given
        schemas").
    """
    import jsonschema

    validator = jsonschema.Draft202012Validator(load_schema(name))
    e = jsonschema.exceptions.best_match(validator.iter_errors(data))
    if e is None:
        return None
    return "/".join(str(p) for p in e.absolute_path) or "(top level)", e.message

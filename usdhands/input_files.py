"""Opening the user's files safely: regular files only, text that must be UTF-8, strict JSON.

Every reader of a user's file (assets, hand maps, configurations, models, databases,
label tables) goes through these, so hostile input fails in one line
(:class:`~usdhands.errors.UsdHandsError` naming the file) instead of hanging or
raising a traceback:

- a named pipe, a device (``/dev/zero``, or a symlink to it) or a socket is refused
  before it is opened (reading one blocks forever or never ends);
- text that is not UTF-8 is named as such;
- JSON nested deeper than :data:`MAX_JSON_DEPTH`, integers longer than Python converts
  (4300 digits), and the non-standard ``NaN``/``Infinity`` literals are refused.
"""

from __future__ import annotations

import json
import os
import re
import stat
from pathlib import Path

from usdhands.errors import AssetReadError, UsdHandsError

__all__ = ["MAX_JSON_DEPTH", "check_regular_file", "read_bytes", "read_text", "parse_json", "read_json", "check_json_depth",
           "refuse_json_constant"]

#: Deepest nesting of arrays and objects accepted in a JSON file (the schemas need < 10;
#: Python's parser recurses and raised RecursionError at about 1000).
MAX_JSON_DEPTH = 200


def check_regular_file(path: str | os.PathLike, *, what: str = "file", error: type[UsdHandsError] = AssetReadError
                       ) -> Path:
    """``path`` if it names a regular file (after symlinks), else ``error`` in one line.

    Raises
    ------
    UsdHandsError (``error``)
        Missing, a folder, a named pipe, a device or a socket, or not accessible.
    """
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise error(f"no such {what}", path=path) from None
    except OSError as e:
        raise error(f"cannot read {what} ({e.strerror or e})", path=path) from None
    if stat.S_ISDIR(mode):
        raise error("is a folder, not a file", path=path)
    if not stat.S_ISREG(mode):  # a named pipe, a device, a socket: the words of the CLI's check_paths
        raise error("not a regular file", path=path)
    return path


def read_bytes(path: str | os.PathLike, *, what: str = "file", error: type[UsdHandsError] = AssetReadError) -> bytes:
    """The bytes of a regular file; one-line ``error`` otherwise."""
    path = check_regular_file(path, what=what, error=error)
    try:
        return path.read_bytes()
    except MemoryError:
        raise error(f"{what} too large to read into memory", path=path) from None
    except OSError as e:
        raise error(f"cannot read {what} ({e.strerror or e})", path=path) from None


def read_text(path: str | os.PathLike, *, what: str = "file", error: type[UsdHandsError] = AssetReadError) -> str:
    """The UTF-8 text of a regular file; one-line ``error`` otherwise (naming the first bad byte)."""
    raw = read_bytes(path, what=what, error=error)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise error(f"{what} is not UTF-8 text ({e.reason} at byte {e.start})", path=path) from None


def refuse_json_constant(name: str):
    """``parse_constant`` for :func:`json.loads`: NaN, Infinity and -Infinity are not JSON."""
    raise ValueError(f"{name} is not a JSON number")


_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"')


def _depth(text: str | bytes) -> int:
    """Deepest bracket nesting of JSON text, brackets inside strings not counted (linear, vectorised)."""
    import numpy as np

    raw = text.encode("utf-8", errors="replace") if isinstance(text, str) else bytes(text)
    codes = np.frombuffer(_STRING.sub(b'""', raw), dtype=np.uint8)
    step = np.zeros(256, dtype=np.int32)
    step[[ord("["), ord("{")]] = 1
    step[[ord("]"), ord("}")]] = -1
    return int(np.cumsum(step[codes]).max()) if len(codes) else 0


def parse_json(text: str | bytes, path: str | os.PathLike | None = None, *, what: str = "JSON",
               error: type[UsdHandsError] = AssetReadError):
    """Parse JSON text strictly; one-line ``error`` naming ``path`` on anything wrong.

    Refuses invalid JSON (with line and column), nesting deeper than
    :data:`MAX_JSON_DEPTH`, ``NaN``/``Infinity``, and integers too long to convert.
    """
    try:
        data = json.loads(text, parse_constant=refuse_json_constant)
        check_json_depth(text, path, what=what, error=error)  # what a schema check or pygltflib recurses into
        return data
    except json.JSONDecodeError as e:
        raise error(f"{what} is not valid JSON: {e.msg} at line {e.lineno} column {e.colno}", path=path) from None
    except UnicodeDecodeError as e:
        raise error(f"{what} is not UTF-8 ({e.reason} at byte {e.start})", path=path) from None
    except RecursionError:
        pass  # reported below, with the depth
    except ValueError as e:  # NaN/Infinity, or an integer of more than 4300 digits
        raise error(f"{what} is not valid JSON: {str(e).split(';')[0]}", path=path) from None
    raise error(f"{what} is nested {_depth(text)} deep (more than {MAX_JSON_DEPTH} is refused)", path=path)


def check_json_depth(text: str | bytes, path: str | os.PathLike | None = None, *, what: str = "JSON",
                     error: type[UsdHandsError] = AssetReadError) -> None:
    """Refuse JSON text nested deeper than :data:`MAX_JSON_DEPTH` (before a parser recurses into it)."""
    depth = _depth(text)
    if depth > MAX_JSON_DEPTH:
        raise error(f"{what} is nested {depth} deep (more than {MAX_JSON_DEPTH} is refused)", path=path)


def read_json(path: str | os.PathLike, *, what: str = "file", error: type[UsdHandsError] = AssetReadError):
    """Read and strictly parse a JSON file (see :func:`parse_json`)."""
    return parse_json(read_text(path, what=what, error=error), path, what=what, error=error)

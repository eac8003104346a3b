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
import stat
from pathlib import Path

from usdhands.errors import AssetReadError, UsdHandsError

__all__ = ["MAX_JSON_DEPTH", "MAX_JSON_VALUES", "check_regular_file", "read_bytes", "read_text", "parse_json", "read_json", "check_json_depth",
           "refuse_json_constant"]

#: Deepest nesting of arrays and objects accepted in a JSON file (the schemas need < 10;
#: Python's parser recurses and raised RecursionError at about 1000).
MAX_JSON_DEPTH = 200
#: Most values (array elements and object members, counted by their commas) in a JSON file: a glTF
#: of 100,000 objects (its limit) holds about 2 million; a 208 MB glTF whose extras held 10^7 keys
#: took 66 s and ran out of memory under 3 GB. Parsed, a value takes ~100 bytes of Python objects.
MAX_JSON_VALUES = 5_000_000


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




#: Bytes of JSON text looked at at once by :func:`_structure` (its arrays stay a few times this size).
_CHUNK = 1 << 22
_QUOTE, _BACKSLASH, _COMMA = ord('"'), ord("\\"), ord(",")


def _structure(text: str | bytes) -> tuple[int, int]:
    """``(deepest bracket nesting, commas)`` of JSON text, what is inside strings not counted.

    Linear and vectorised, a chunk of :data:`_CHUNK` bytes at a time, carrying from one chunk to
    the next whether a string is open and how many backslashes end the chunk. (Replacing each
    string by a regular expression built one object per string: a 208 MB glTF of 10^7 keys took
    2.5 GB and 24 s before it was parsed.) :func:`_structure_naive` is its twin; they agree on
    JSON, where a backslash stands only inside strings.
    """
    import numpy as np

    raw = text.encode("utf-8", errors="replace") if isinstance(text, str) else text
    codes = np.frombuffer(raw, dtype=np.uint8)
    step = np.zeros(256, dtype=np.int8)
    step[[ord("["), ord("{")]] = 1
    step[[ord("]"), ord("}")]] = -1
    level = deepest = commas = 0
    inside = 0  # 1 while a string is open at the chunk's start
    trailing = 0  # backslashes that end the text before the chunk
    for start in range(0, len(codes), _CHUNK):
        part = codes[start:start + _CHUNK]
        n = len(part)
        quote = part == _QUOTE
        slash = part == _BACKSLASH
        if (trailing and quote[0]) or np.any(slash[:-1] & quote[1:]):  # a quote may be escaped
            at = np.arange(n)
            last_other = np.maximum.accumulate(np.where(slash, -1, at))  # last non-backslash at or before
            before = np.empty(n, dtype=np.int64)  # backslashes just before each position
            before[0] = trailing
            run = at[:-1] - last_other[:-1]
            before[1:] = np.where(last_other[:-1] < 0, run + trailing, run)
            quote &= before % 2 == 0
        opened = np.bitwise_xor.accumulate(quote.view(np.uint8)) ^ inside  # 1 inside a string, its opening quote too
        outside = opened == 0
        moves = step[part]
        where = np.flatnonzero(moves & outside.view(np.int8))  # brackets outside strings
        if where.size:
            running = np.cumsum(moves[where], dtype=np.int64) + level
            deepest = max(deepest, int(running.max()))
            level = int(running[-1])
        commas += int(np.count_nonzero((part == _COMMA) & outside))
        inside = int(opened[-1])
        if slash[-1]:
            others = np.flatnonzero(~slash)
            trailing = n - 1 - int(others[-1]) if others.size else trailing + n
        else:
            trailing = 0
    return deepest, commas


def _structure_naive(text: str | bytes) -> tuple[int, int]:
    """:func:`_structure` byte by byte (the twin its test compares against)."""
    raw = text.encode("utf-8", errors="replace") if isinstance(text, str) else bytes(text)
    level = deepest = commas = 0
    inside = escaped = False
    for b in raw:
        if inside:
            if escaped:
                escaped = False
            elif b == _BACKSLASH:
                escaped = True
            elif b == _QUOTE:
                inside = False
        elif b == _QUOTE:
            inside = True
        elif b in b"[{":
            level += 1
            deepest = max(deepest, level)
        elif b in b"]}":
            level -= 1
        elif b == _COMMA:
            commas += 1
    return deepest, commas


def _depth(text: str | bytes) -> int:
    """Deepest bracket nesting of JSON text, brackets inside strings not counted."""
    return _structure(text)[0]


def parse_json(text: str | bytes, path: str | os.PathLike | None = None, *, what: str = "JSON",
               error: type[UsdHandsError] = AssetReadError):
    """Parse JSON text strictly; one-line ``error`` naming ``path`` on anything wrong.

    Refuses invalid JSON (with line and column), nesting deeper than
    :data:`MAX_JSON_DEPTH`, ``NaN``/``Infinity``, and integers too long to convert.
    """
    try:
        check_json_depth(text, path, what=what, error=error)  # what a schema check recurses into; its size
        return json.loads(text, parse_constant=refuse_json_constant)
    except MemoryError:
        raise error(f"{what} too large to parse in the memory there is", path=path) from None
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
    """Refuse JSON text nested deeper than :data:`MAX_JSON_DEPTH` (before a parser recurses into it)
    or holding more than :data:`MAX_JSON_VALUES` values (before a parser builds them)."""
    depth, commas = _structure(text)
    if depth > MAX_JSON_DEPTH:
        raise error(f"{what} is nested {depth} deep (more than {MAX_JSON_DEPTH} is refused)", path=path)
    if commas >= MAX_JSON_VALUES:
        raise error(f"{what} holds more than {MAX_JSON_VALUES:,} values (array elements and object members)",
                    path=path)


def read_json(path: str | os.PathLike, *, what: str = "file", error: type[UsdHandsError] = AssetReadError):
    """Read and strictly parse a JSON file (see :func:`parse_json`)."""
    return parse_json(read_text(path, what=what, error=error), path, what=what, error=error)

"""BVH (Biovision hierarchy): reading and writing skeletons with motion.

Reading
-------
- Every ``ROOT`` and ``JOINT`` becomes a joint named as in the file (the rest of the
  line, so ``JOINT Bip01 L Hand`` is ``"Bip01 L Hand"``; the writer puts ``_`` for
  whitespace). An ``End Site``
  becomes a leaf joint named ``<parent>_end`` (``rThumb3_end``), with its offset as rest
  translation and no DOF, so the skeleton keeps the shape of the file (finger tips
  included) and writing gives the End Sites back.
- ``OFFSET`` is the rest translation; rest rotations are identity (BVH has none).
- Rotation channels in any order and number: the local rotation is the product of
  the axis rotations in channel order, ``R = R_c1 @ R_c2 @ R_c3``, i.e. intrinsic
  Euler angles in channel order (``Zrotation Yrotation Xrotation`` is scipy's
  ``from_euler("ZYX", [z, y, x], degrees=True)``). A joint without rotation channels
  keeps its rest rotation.
- Position channels (on the root and on any other joint) *replace* the matching
  component of ``OFFSET`` as the joint's local translation, as three.js, MotionBuilder
  and Blender (for the root) read them.
- ``Frame Time`` gives ``fps = 1 / frame_time``, snapped to the nearest integer when
  within 0.001 of it (``0.0333333`` → 30).
- Units: centimetres by default (``meters_per_unit = 0.01``); the ``units`` option of
  :meth:`BvhHandler.read` names others (``"m"``, ``"mm"``, ``"in"``, ``"ft"`` or metres
  per unit as a number). +Y up.
- One tolerance: a file with exactly one motion line more than ``Frames:`` says, the
  first of them all zeros, has that line skipped (the Leap Motion BVH exporter writes
  such a rest line before the frames; the three Leap files of the test assets do).
- Bad numbers: a motion line with too few or too many values, a ``Frames:`` count
  that disagrees with the lines, a value that is not a number, or a malformed
  hierarchy raise :class:`~usdhands.errors.AssetReadError` naming the line
  (``line 312: expected 171 values, found 168``).

Speed
-----
A well-formed file (one statement a line in the hierarchy, as exporters write it) is read
from its bytes: the hierarchy line by line, the motion values by the NumPy parser of
:mod:`usdhands.formats._bvh_numpy_motion` (the numbers exporters write, the same values as
``np.loadtxt``, which reads anything else) and the Euler angles converted with NumPy; or,
with the kernels compiled ahead of time (:mod:`usdhands.compiled`; the same numbers,
about 2x faster), or where they were not built (no C compiler at install), in a process
where numba already runs a kernel of the package (or that has read 128 MB of BVH motion,
:data:`COMPILED_AFTER_BYTES`), with their numba twins in :mod:`usdhands.formats._bvh_kernel`.
Anything unusual is read by the token-by-token parser, which names the line of
a problem. A fresh process reading a file imports no numba.

Writing
-------
- :meth:`BvhHandler.write` writes a new file from a skeleton and its first clip (or
  the rest pose as one frame when there is none): roots get 6 channels, other joints
  3 rotation channels, plus position channels where the clip moves their translation
  away from the rest; rotation order ``order`` (default ``"ZXY"``:
  ``Zrotation Xrotation Yrotation``). A leaf joint named ``<parent>_end`` is written as
  an End Site; other leaves as joints with no End Site. BVH has no rest rotation and no
  scale: the clip's local rotations are written as they are, and each joint's scale is
  baked into the offsets and translations below it (exact for uniform scales, the mean
  of the components otherwise), so world positions are kept.
  Skeletons in other units or Z-up are converted to the ``units`` (default
  centimetres) and +Y.
- :meth:`BvhHandler.write_clip` writes the source file's hierarchy text unchanged
  (line endings become ``\n``) with the clip's motion, in the source's channel layout (orders kept).
- Numbers are written with 6 decimals (1e-6 degree, 1e-6 unit); Euler angles are
  unwrapped over time so curves have no 360° jumps.
"""

from __future__ import annotations

import io
import logging
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from usdhands.compiled import kernel_module
from usdhands.errors import AssetReadError, JointMismatchError
from usdhands.formats._bvh_numpy_motion import parse_rows as parse_motion_rows
from usdhands.formats.fixed_point_text import format_rows_6f
from usdhands.model.asset import Asset
from usdhands.model.clip import Clip, clip_size_problem, resampled_frames
from usdhands.model.rotations import quat_identity, quat_to_euler_deg, unwrap_deg
from usdhands.model.skeleton import Skeleton

_log = logging.getLogger(__name__)

__all__ = ["HANDLER", "BvhHandler", "UNITS", "units_to_meters", "parse_bvh", "BvhFile", "euler_channels_to_quat"]

UNITS = {"cm": 0.01, "m": 1.0, "mm": 0.001, "dm": 0.1, "in": 0.0254, "inch": 0.0254, "ft": 0.3048}
DEFAULT_ORDER = "ZXY"
END_SUFFIX = "_end"
_FMT = "%.6f"
#: Deepest indentation written (tabs): deeper joints are indented no further, so a long chain
#: does not make the file grow with the square of its depth.
MAX_INDENT = 64

_CHANNELS = {"xposition": ("p", 0), "yposition": ("p", 1), "zposition": ("p", 2),
             "xrotation": ("r", 0), "yrotation": ("r", 1), "zrotation": ("r", 2)}
_AXES = "XYZ"
#: Each channel's name as the reader keeps it (``"Xrotation"``), from its lower-case and its own spelling.
_CHANNEL_NAMES = {k: k[0].upper() + k[1:] for k in _CHANNELS} | {k[0].upper() + k[1:]: k[0].upper() + k[1:]
                                                                  for k in _CHANNELS}


def units_to_meters(units: str | float | None) -> float:
    """Metres per unit for a unit name (``"cm"``, ``"m"``, ...) or a positive number."""
    if units is None:
        return UNITS["cm"]
    if isinstance(units, str):
        key = units.strip().lower()
        if key in UNITS:
            return UNITS[key]
        try:
            units = float(key)
        except ValueError:
            raise ValueError(f"Expected units as one of {sorted(UNITS)} or metres per unit, got {units!r}") from None
    units = float(units)
    if not (np.isfinite(units) and units > 0):
        raise ValueError(f"Expected units > 0 metres per unit, got {units!r}")
    return units


@dataclass
class BvhJoint:
    """One ROOT/JOINT or End Site of a BVH hierarchy."""

    name: str
    parent: int
    offset: np.ndarray
    channels: list = field(default_factory=list)  # e.g. ["Xposition", ..., "Zrotation"]
    end_site: bool = False
    line: int = 0


@dataclass
class BvhFile:
    """A parsed BVH file.

    Attributes
    ----------
    joints : list of BvhJoint
        Depth-first, parents first, End Sites included.
    hierarchy_text : str
        The file's text from ``HIERARCHY`` up to (not including) ``MOTION``.
    frame_time : float
        Seconds per frame.
    values : (T, C) float
        Motion values, C = total channel count, in channel order.
    """

    joints: list
    hierarchy_text: str
    frame_time: float
    values: np.ndarray

    @property
    def num_channels(self) -> int:
        return sum(len(j.channels) for j in self.joints)


class _Tokens:
    def __init__(self, lines: list[str], path):
        self.toks = []
        for i, line in enumerate(lines, start=1):
            for t in re.findall(r"[{}]|[^\s{}]+", line):
                self.toks.append((t, i))
        self.pos = 0
        self.path = path
        self.last_line = len(lines)

    def peek(self):
        return self.toks[self.pos] if self.pos < len(self.toks) else (None, self.last_line)

    def next(self, what: str):
        if self.pos >= len(self.toks):
            self.error(self.last_line, f"unexpected end of file, expected {what}")
        t = self.toks[self.pos]
        self.pos += 1
        return t

    def expect(self, word: str):
        t, line = self.next(repr(word))
        if t.lower() != word.lower():
            self.error(line, f"expected {word!r}, found {t!r}")
        return line

    def number(self, what: str) -> float:
        t, line = self.next(what)
        try:
            return float(t)
        except ValueError:
            self.error(line, f"expected a number for {what}, found {t!r}")

    def error(self, line: int, msg: str):
        raise AssetReadError(msg, path=self.path, location=f"line {line}")


def parse_bvh(path: str | os.PathLike) -> BvhFile:
    """Parse a BVH file into its hierarchy and motion values.

    Raises
    ------
    AssetReadError
        Naming the line of the first problem.
    """
    path = Path(path)
    fast = _parse_bvh_fast(path)
    if fast is not None:
        return fast
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as e:
        raise AssetReadError(f"cannot read: {e.strerror}", path=path) from None
    lines = text.removeprefix("\ufeff").splitlines()
    motion_line = None
    for i, line in enumerate(lines):
        if _is_motion_line(line):
            motion_line = i
            break
    joints = _parse_hierarchy(lines if motion_line is None else lines[:motion_line], path)
    if motion_line is None:
        raise AssetReadError("no MOTION section", path=path, location=f"line {len(lines)}")
    hierarchy_text = "\n".join(lines[:motion_line]) + "\n"
    values, frame_time = _parse_motion(lines, motion_line, sum(len(j.channels) for j in joints), path)
    return BvhFile(joints, hierarchy_text, frame_time, values)


#: Line breaks of ``str.splitlines`` other than ``\n`` and ``\r`` (which an open text file turns into ``\n``).
_OTHER_LINE_BREAKS = re.compile("[\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029]")
_MOTION_WORD = re.compile(rb"(?i)motion")
#: Candidate ``MOTION`` words looked at before the fast path hands over (a hierarchy full of joints
#: named "motion..."; the slow path then finds the line).
_MOTION_CANDIDATES = 8


#: The characters of _OTHER_LINE_BREAKS that are ASCII.
_ASCII_LINE_BREAKS = (b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e")


def _motion_words(data: bytes):
    """The offsets after each ``motion`` of ``data`` (any case), in order: the ends of
    ``_MOTION_WORD.finditer(data)``, the first found with ``bytes.find`` where it is an upper-case
    ``MOTION`` with none before it (as exporters write it: 4x faster than the regular expression)."""
    start = 0
    p = data.find(b"MOTION")
    if p >= 0 and data[:p + 6].lower().find(b"motion") == p:
        start = p + 6
        yield start
    for m in _MOTION_WORD.finditer(data, start):
        yield m.end()


def _is_motion_line(line: str) -> bool:
    s = line.strip().upper()
    return s == "MOTION" or s.startswith("MOTION ")


def _head_of(data: bytes) -> tuple[list[str], int] | None:
    """The lines up to and including the ``MOTION`` line, and the offset of the byte after that line.

    As :func:`parse_bvh` splits the decoded text (UTF-8, bad bytes replaced; ``\n``,
    ``\r\n`` and ``\r`` end lines; a leading byte order mark dropped), or None when the head
    holds other line breaks or the ``MOTION`` line is not found among the first candidates.
    """
    for k, end in enumerate(_motion_words(data)):
        if k == _MOTION_CANDIDATES:
            return None
        nl = data.find(b"\n", end)
        cr = data.find(b"\r", end, len(data) if nl < 0 else nl)
        end = cr if cr >= 0 else nl if nl >= 0 else len(data)
        chunk = data[:end]
        plain = chunk.isascii()
        text = chunk.decode("utf-8", errors="replace")
        if any(b in chunk for b in _ASCII_LINE_BREAKS) if plain else _OTHER_LINE_BREAKS.search(text):
            return None
        lines = text.splitlines()
        if not lines or not _is_motion_line(lines[-1]):
            continue  # "motion" inside another line (a joint's name)
        lines[0] = lines[0].removeprefix("\ufeff")
        if not plain and any(_is_motion_line(line) for line in lines[:-1]):
            return None  # an earlier line the slow path takes ("motıon": non-ASCII letters upper-cased)
        after = end + (2 if data[end:end + 2] == b"\r\n" else 1 if end < len(data) else 0)
        return lines, after
    return None


def _header_lines(data: bytes, pos: int) -> tuple[list[str], int] | None:
    """The two non-blank lines after ``MOTION`` (whitespace runs as one space) and the offset after them.

    None where a line there ends with a lone ``\r`` or holds another line break.
    """
    header = []
    while len(header) < 2:
        if pos >= len(data):
            return None
        nl = data.find(b"\n", pos)
        nl = len(data) if nl < 0 else nl
        raw = data[pos:nl].removesuffix(b"\r")
        pos = nl + 1
        if b"\r" in raw:
            return None
        line = raw.decode("utf-8", errors="replace")
        if _OTHER_LINE_BREAKS.search(line):
            return None
        if line.strip():
            header.append(" ".join(line.split()))
    return header, min(pos, len(data))


#: Bytes read first for the head of a file (doubled while the head is longer).
_HEAD_BYTES = 1 << 16


def _read_head(f) -> tuple[bytes, bool, list[str], list[str], int] | None:
    """The first bytes of the binary file ``f`` up to at least the end of its ``Frame Time`` line.

    Returns those bytes, whether they are the whole file, the head's lines (to the
    ``MOTION`` line, see :func:`_head_of`), the two header lines (see :func:`_header_lines`)
    and the offset of the first motion byte; None where the whole file has no such head.
    """
    want = _HEAD_BYTES
    data = f.read(want)
    while True:
        whole = len(data) < want
        found = _head_of(data)
        if found is not None:
            lines, pos = found
            header = _header_lines(data, pos)
            if header is not None and (whole or data[header[1] - 1:header[1]] == b"\n"):
                return data, whole, lines, header[0], header[1]
        if whole:
            return None
        data += f.read(want)
        want *= 2


def _parse_bvh_fast(path: Path) -> BvhFile | None:
    """:func:`parse_bvh` of a well-formed file.

    The head (hierarchy and motion header) is read as bytes, decoded and split into
    lines; the motion values after the ``Frame Time`` line by the compiled parser from
    the bytes, or by ``np.loadtxt`` from the text (:func:`_motion_from`). None whenever
    anything is unusual (an unreadable file, other line breaks in the head, a header or
    motion line that is not as expected): :func:`parse_bvh` then reads the file its
    slower way and names the problem.
    """
    try:
        f = open(path, "rb")
    except OSError:
        return None
    with f:
        found = _read_head(f)
        if found is None:
            return None
        data, whole, lines, header, pos = found
        if not header[0].lower().startswith("frames:") or not header[1].lower().startswith("frame time:"):
            return None
        try:
            frames = int(header[0][len("Frames:"):].strip())
            frame_time = float(header[1][len("Frame Time:"):].strip())
        except ValueError:
            return None
        if frames < 0 or not (np.isfinite(frame_time) and MIN_FRAME_TIME_S <= frame_time <= MAX_FRAME_TIME_S):
            return None
        head = lines[:-1]
        joints = _parse_hierarchy_fast(head)
        if joints is None:
            return None
        C = sum(len(j.channels) for j in joints)
        if C == 0 or frames == 0:
            return None
        values = _motion_from(f, data, whole, pos, C, frames)
    if values is None:
        return None
    if len(values) == frames + 1 and not values[0].any():
        values = values[1:]  # the Leap Motion rest line (see _parse_motion)
    if len(values) != frames:
        return None
    return BvhFile(joints, "\n".join(head) + "\n", frame_time, values)


#: Motion text (bytes) a process reads with ``np.loadtxt`` before it starts the compiled reader
#: (:mod:`usdhands.formats._bvh_kernel`) on its own. numba's import and first kernel cost about
#: 0.55 s of CPU (measured); the compiled reader saves about 5 ns a byte (parsing and the Euler
#: conversion: 10,000 frames x 65 joints, 42 MB, 0.36 -> 0.21 s): paid back after about 110 MB.
#: Where a kernel of the package already runs in the process (:func:`usdhands.jit.kernels_running`)
#: the reader's own kernels load in a few milliseconds and are used from the first file.
COMPILED_AFTER_BYTES = 128_000_000
#: ``True``: numba's compiled reader always; ``False``: never a compiled one (NumPy alone); ``None``:
#: the reader compiled ahead of time where it was built, else as above (:func:`_kernels`).
USE_COMPILED: bool | None = None
_motion_bytes_read = 0


def _kernels():
    """The module of compiled kernels this process reads BVH motion with, or None for NumPy.

    The kernels compiled ahead of time (:mod:`usdhands.compiled`: nothing to start) wherever
    they were built; else numba's (:mod:`usdhands.formats._bvh_kernel`) once numba runs a kernel
    of the package or past :data:`COMPILED_AFTER_BYTES`. :data:`USE_COMPILED` ``True`` forces
    numba's, ``False`` NumPy. All read the same numbers.
    """
    if USE_COMPILED is False:
        return None
    if USE_COMPILED is None:
        built = kernel_module("formats._bvh_compiled")
        if built is not None:
            return built
        if _motion_bytes_read < COMPILED_AFTER_BYTES:
            from usdhands.jit import kernels_running

            if not kernels_running():
                return None
    from usdhands.formats import _bvh_kernel

    return _bvh_kernel


def _motion_from(f, data: bytes, whole: bool, pos: int, C: int, frames: int) -> np.ndarray | None:
    """The motion values ``(T, C)`` float64 of the binary file ``f`` from byte ``pos``, or None where
    they are not ``C`` finite numbers a line.

    ``data`` holds the file's first bytes (all of them where ``whole``). The compiled
    parser (:mod:`usdhands.formats._bvh_kernel`, the same numbers) reads the bytes when
    the process uses it and it can read them; else ``np.loadtxt`` reads the text from
    ``pos`` (UTF-8, bad bytes replaced, ``\r\n`` and ``\r`` ending lines as ``\n``).
    At most ``frames + 1`` rows (the Leap Motion rest line): more is handed back.
    """
    global _motion_bytes_read
    size = len(data) if whole else os.fstat(f.fileno()).st_size
    _motion_bytes_read += max(0, size - pos)
    kernel = _kernels()
    if kernel is not None:
        if not whole:
            data += f.read()
            whole = True
        # a row of C numbers takes at least 2 C bytes with its line break: at most 4 bytes of floats a byte read
        rows = min(frames + 1, (len(data) - pos + 1) // (2 * C))
        out = np.empty((rows, C))
        got = kernel.parse_rows(np.frombuffer(data, np.uint8), pos, C, out, kernel.POW10)
        if got >= 0:
            return out[:got]
    # the NumPy parser (_bvh_numpy_motion: the numbers exporters write, the same values) reads the bytes
    # from the 8 before the motion
    if whole:
        buf, start = data, pos
    else:
        f.seek(pos - 8)
        buf, start = f.read(), 8
    out = np.empty((min(frames + 1, (len(buf) - start + 1) // (2 * C)), C))
    got = parse_motion_rows(buf, start, C, out)
    if got >= 0:
        return out[:got]
    if whole:  # a small file, in memory: its lines (measured: a little faster than reading the file again)
        text = data[pos:].decode("utf-8", errors="replace")
        if "\r" in text:
            text = text.replace("\r\n", "\n").replace("\r", "\n")  # as an open text file has them
        return _motion_values(text.split("\n"), C)
    f.seek(pos)
    text = io.TextIOWrapper(f, encoding="utf-8", errors="replace")  # newlines as an open text file has them
    try:
        return _motion_values(text, C)
    finally:
        text.detach()  # f is closed by its owner


def _is_count(text: str) -> bool:
    """Whether ``text`` is a channel count: ASCII digits ("²" is a digit to ``str.isdigit``, not to
    ``int``), at most 9 of them after leading zeros (5,000 digits exceed ``int()``'s limit)."""
    return text.isascii() and text.isdigit() and len(text.lstrip("0")) <= 9


def _end_site_name(parent: str, names: set[str]) -> str:
    """``<parent>_end``, or ``<parent>_end1``, ``_end2``... where that name is taken."""
    name = parent + END_SUFFIX
    k = 1
    while name in names:
        name = f"{parent}{END_SUFFIX}{k}"
        k += 1
    return name


def _parse_hierarchy_fast(head: list[str]) -> list[BvhJoint] | None:
    """:func:`_parse_hierarchy` of a hierarchy laid out one statement a line, or None.

    Every ``ROOT``/``JOINT``/``End Site``, ``{``, ``}``, ``OFFSET x y z`` and
    ``CHANNELS n ...`` on a line of its own (braces alone on theirs), as every exporter
    writes them: the same joints as the token-by-token parser, without a method call per
    token. Anything else (a brace beside a word, a statement over two lines, a
    mistake) gives None, and the token parser reads the file and names the problem.
    """
    rows = [line.split() for line in head]
    numbers = None  # the line number of each row where blank lines were left out
    if not all(rows):
        numbers = [i for i, parts in enumerate(rows, 1) if parts]
        rows = [parts for parts in rows if parts]
    if not rows or len(rows[0]) != 1 or rows[0][0].upper() != "HIERARCHY":
        return None
    joints: list[BvhJoint] = []
    offsets: list[str] = []  # x y z of each joint, converted at the end
    names: set[str] = set()
    stack: list[int] = []  # the open joints
    known: dict[tuple, list] = {}  # a CHANNELS line's words -> its channels (a file repeats a few lines)
    k, n = 1, len(rows)
    while k < n:
        parts = rows[k]
        if parts == _CLOSE:
            if not stack:
                return None
            stack.pop()
            k += 1
            continue
        kw = parts[0].upper()
        if not stack:
            if kw != "ROOT":
                return None
        elif kw not in ("JOINT", "END") or joints[stack[-1]].end_site:
            return None
        if kw == "END":
            if len(parts) != 2 or parts[1].lower() != "site":
                return None
            name = _end_site_name(joints[stack[-1]].name, names)
            end = True
        else:
            name = " ".join(parts[1:])
            if not name or "{" in name or "}" in name or name in names:
                return None
            end = False
        if k + 2 >= n or rows[k + 1] != _OPEN:
            return None
        offset = rows[k + 2]
        if len(offset) != 4 or offset[0].lower() != "offset":
            return None
        offsets += offset[1:]
        names.add(name)
        line = k + 1 if numbers is None else numbers[k]
        k += 3
        channels = []
        if not end and k < n and rows[k][0].upper() == "CHANNELS":
            key = tuple(rows[k])
            channels = known.get(key)
            if channels is None:
                channels = known[key] = _channel_names(rows[k])
                if channels is None:
                    return None
            channels = channels.copy()
            k += 1
        stack.append(len(joints))
        joints.append(BvhJoint(name, stack[-2] if len(stack) > 1 else -1, None, channels, end, line))
    if stack or not joints:
        return None
    try:
        xyz = np.array(list(map(float, offsets))).reshape(-1, 3)  # float() as the token parser reads them
    except ValueError:
        return None
    for joint, row in zip(joints, xyz):  # one array, a row each
        joint.offset = row
    return joints


_CLOSE = ["}"]
_OPEN = ["{"]


def _channel_names(words: list[str]) -> list[str] | None:
    """The channels of a ``CHANNELS n name...`` line's words, each as the reader keeps it, or None
    where the count is not a count or not the number of names, or a name is not a channel."""
    count = words[1] if len(words) > 1 else ""
    if not _is_count(count) or len(words) != 2 + int(count):
        return None
    channels = []
    for c in words[2:]:
        c = _CHANNEL_NAMES.get(c) or _CHANNEL_NAMES.get(c.lower())
        if c is None:
            return None
        channels.append(c)
    return channels


def _parse_hierarchy(head: list[str], path: Path) -> list[BvhJoint]:
    """The joints of the lines before ``MOTION`` (raises AssetReadError naming the line)."""
    tok = _Tokens(head, path)
    t, line = tok.peek()
    if t is None or t.upper() != "HIERARCHY":
        tok.error(line if t is not None else 1, f"expected 'HIERARCHY', found {t!r}" if t else
                  "expected 'HIERARCHY', found an empty file")
    tok.next("HIERARCHY")
    joints: list[BvhJoint] = []
    names: set[str] = set()
    while tok.peek()[0] is not None:
        t, line = tok.peek()
        if t.upper() != "ROOT":
            tok.error(line, f"expected 'ROOT' or 'MOTION', found {t!r}")
        _parse_joint(tok, joints, names, -1)
    if not joints:
        tok.error(tok.last_line, "no ROOT in HIERARCHY")
    return joints


def _parse_joint(tok: _Tokens, joints: list, names: set, parent: int) -> None:
    """Parse a ROOT and every joint below it into ``joints``.

    Iterative (a stack of the open joints): a hierarchy 10,000 joints deep raised
    RecursionError when each joint was a recursive call.
    """
    stack = [_parse_joint_head(tok, joints, names, parent)]
    while stack:
        me, name, end = stack[-1]
        t, tline = tok.peek()
        if t is None:
            tok.error(tline, f"unexpected end of hierarchy inside {name!r}: missing '}}'")
        if t == "}":
            tok.next("'}'")
            stack.pop()
            continue
        if end:
            tok.error(tline, f"expected '}}' closing the End Site of {joints[joints[me].parent].name!r}, found {t!r}")
        if t.upper() in ("JOINT", "END"):
            stack.append(_parse_joint_head(tok, joints, names, me))
            continue
        tok.error(tline, f"expected 'JOINT', 'End Site' or '}}' in {name!r}, found {t!r}")


def _parse_joint_head(tok: _Tokens, joints: list, names: set, parent: int) -> tuple[int, str, bool]:
    """Read ``JOINT name { OFFSET ... CHANNELS ...`` (or ``End Site { OFFSET ...``) up to its children.

    Returns the joint's index in ``joints``, its name and whether it is an End Site.
    """
    kw, line = tok.next("'JOINT'")
    kwu = kw.upper()
    if kwu == "END":
        tok.expect("Site")
        name = _end_site_name(joints[parent].name, names)
        end = True
    else:
        name, nline = tok.next("a joint name")
        if name in "{}":
            tok.error(nline, f"expected a joint name after {kw!r}, found {name!r}")
        while tok.peek()[1] == nline and tok.peek()[0] not in (None, "{", "}"):  # "JOINT Bip01 L Hand"
            name += " " + tok.next("a joint name")[0]
        if name in names:
            tok.error(nline, f"joint name {name!r} is used twice")
        end = False
    names.add(name)
    tok.expect("{")
    tok.expect("OFFSET")
    offset = np.array([tok.number("OFFSET x"), tok.number("OFFSET y"), tok.number("OFFSET z")])
    j = BvhJoint(name, parent, offset, [], end, line)
    joints.append(j)
    if not end and tok.peek()[0] is not None and tok.peek()[0].upper() == "CHANNELS":
        tok.next("CHANNELS")
        t, cline = tok.next("a channel count")
        if not _is_count(t):
            tok.error(cline, f"expected a channel count, found {t!r}")
        n = int(t)
        for _ in range(n):
            c, cl = tok.next("a channel name")
            if c.lower() not in _CHANNELS:
                if c in "{}" or c.upper() in ("JOINT", "END"):
                    tok.error(cl, f"CHANNELS {n} lists fewer than {n} channels")
                tok.error(cl, f"unknown channel {c!r} (expected X/Y/Z position or rotation)")
            j.channels.append(c[0].upper() + c[1:].lower())
    return len(joints) - 1, name, end


#: Shortest and longest ``Frame Time`` read (seconds): 10000 fps down to one frame in 1000 s.
MIN_FRAME_TIME_S = 1e-4
MAX_FRAME_TIME_S = 1000.0


def _parse_motion(lines: list[str], motion_line: int, C: int, path) -> tuple[np.ndarray, float]:
    i = motion_line + 1
    n = len(lines)

    def header(label: str) -> tuple[str, int]:
        nonlocal i
        while i < n and not lines[i].strip():
            i += 1
        if i >= n:
            raise AssetReadError(f"expected '{label}', found the end of the file", path=path,
                                 location=f"line {n}")
        s = " ".join(lines[i].split())  # 'Frame\tTime:\t0.033' as 'Frame Time: 0.033'
        if not s.lower().startswith(label.lower()):
            raise AssetReadError(f"expected '{label}', found {lines[i].strip()[:40]!r}", path=path,
                                 location=f"line {i + 1}")
        i += 1
        return s[len(label):].strip(), i

    frames_text, frames_line = header("Frames:")
    try:
        frames = int(frames_text)
        if frames < 0:
            raise ValueError
    except ValueError:
        raise AssetReadError(f"expected a frame count, found {frames_text!r}", path=path,
                             location=f"line {frames_line}") from None
    ft_text, ft_line = header("Frame Time:")
    try:
        frame_time = float(ft_text)
        if not (np.isfinite(frame_time) and frame_time > 0):
            raise ValueError
    except ValueError:
        raise AssetReadError(f"expected a positive frame time, found {ft_text!r}", path=path,
                             location=f"line {ft_line}") from None
    if not MIN_FRAME_TIME_S <= frame_time <= MAX_FRAME_TIME_S:  # 1e-300 gave 1e300 fps: float32 key times collapse
        raise AssetReadError(f"frame time {ft_text} s is outside {MIN_FRAME_TIME_S:g}..{MAX_FRAME_TIME_S:g} s "
                             f"(at most {1 / MIN_FRAME_TIME_S:g} frames per second)", path=path,
                             location=f"line {ft_line}")
    values = _motion_values(lines[i:], C)
    if values is not None and frames <= len(values) <= frames + 1:
        if len(values) == frames + 1 and not values[0].any():
            values = values[1:]  # the Leap Motion rest line (see below)
        if len(values) == frames:
            return values, frame_time
    # something is wrong with the motion lines (or the file has none): find and name the line
    counts = _tokens_per_line(lines[i:])
    filled = np.nonzero(counts)[0]
    bad = filled[counts[filled] != C]
    if len(bad):
        k = int(bad[0])
        raise AssetReadError(f"expected {C} values, found {counts[k]}", path=path, location=f"line {i + k + 1}")
    row_lines = (filled + i + 1).tolist()
    text = "\n".join(lines[k - 1] for k in row_lines)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            flat = np.fromstring(text, dtype=np.float64, sep=" ") if text else np.zeros(0)
    except ValueError:  # numpy >= 2.x raises on a token that is not a number
        flat = np.zeros(0)
    if flat.size != len(row_lines) * C:  # a token that is not a number: find it
        for ln in row_lines:
            for v in lines[ln - 1].split():
                try:
                    float(v)
                except ValueError:
                    raise AssetReadError(f"not a number: {v!r}", path=path, location=f"line {ln}") from None
        raise AssetReadError("unreadable motion values", path=path, location=f"line {row_lines[0]}")
    values = flat.reshape(len(row_lines), C)
    if len(row_lines) == frames + 1 and not values[0].any():
        # the Leap Motion exporter (jaanga) writes an all-zero rest line before the frames
        values, row_lines = values[1:], row_lines[1:]
    if len(row_lines) != frames:
        where = row_lines[frames] if len(row_lines) > frames else n
        raise AssetReadError(f"'Frames: {frames}' (line {frames_line}) but {len(row_lines)} frames of motion follow",
                             path=path, location=f"line {where}")
    if not np.all(np.isfinite(values)):
        r, c = np.argwhere(~np.isfinite(values))[0]
        raise AssetReadError(f"value {c + 1} is not finite: {lines[row_lines[r] - 1].split()[c]!r}", path=path,
                             location=f"line {row_lines[r]}")
    return values, frame_time


def _motion_values(lines, C: int) -> np.ndarray | None:
    """The motion lines (a list of str, or an open text file) as a ``(T, C)`` float64 array, or None
    when they are not ``C`` finite numbers each.

    The fast path of :func:`_parse_motion`: ``np.loadtxt``'s C parser, which skips
    blank lines and refuses a row with another number of values or a token that is
    not a number (including ``#`` comments). None sends the caller to the slow path
    that names the offending line.
    """
    if C == 0 or not lines:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
            values = np.loadtxt(lines, dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        return None
    if values.ndim != 2 or values.shape[1] != C or not np.isfinite(values).all():
        return None
    return values


def _tokens_per_line(lines: list[str]) -> np.ndarray:
    """Number of whitespace-separated tokens on each line, ``(len(lines),)`` int.

    ``str.split`` per line beats byte-level numpy here (measured: 0.4 s against 1.5 s
    for 10,000 lines of 390 values).
    """
    return np.fromiter((len(line.split()) for line in lines), dtype=np.int64, count=len(lines))


def _fps(frame_time: float) -> float:
    fps = 1.0 / frame_time
    r = round(fps)
    return float(r) if r > 0 and abs(fps - r) < 1e-3 else fps


def bvh_to_asset(bvh: BvhFile, path: Path, meters_per_unit: float = 0.01, fps: float | None = None) -> Asset:
    """The skeleton and clip of a parsed BVH file."""
    J = len(bvh.joints)
    names = [j.name for j in bvh.joints]
    parents = np.array([j.parent for j in bvh.joints], dtype=np.int64)
    offsets = np.array([j.offset for j in bvh.joints], dtype=np.float64).reshape(J, 3)
    sk = Skeleton(names, parents, offsets, quat_identity((J,)), meters_per_unit=meters_per_unit,
                  up_axis="Y", name=path.stem)
    values = np.ascontiguousarray(bvh.values, dtype=np.float64)
    T = values.shape[0]
    rate = _fps(bvh.frame_time)
    n = T if fps is None else resampled_frames(T, rate, fps)  # after resampling
    too_big = clip_size_problem(max(T, n), J, lambda: T * sum(1 for j in bvh.joints if j.channels))
    if too_big:  # before the clip's arrays are allocated (a line of text per frame, but joints without channels)
        raise AssetReadError(too_big, path=path)
    rot = np.empty((T, J, 4))  # arrays that own their memory: the clip keeps them (see below)
    trans = np.empty((T, J, 3))
    layout = _ChannelLayout(bvh.joints)
    kernel = _kernels() if T else None
    if kernel is not None:
        ints = [np.array(a, dtype=np.int64) for a in (layout.first, layout.count, layout.axes, layout.cols)
                + layout.moved]
        kernel.clip_arrays(values, offsets, *ints, kernel.PERM, kernel.SIGN, rot, trans)
    else:
        _translations_numpy(values, offsets, layout.moved, trans)
        _rotations_numpy(values, layout.groups, rot)
    scales = np.ones((T, J, 3))  # the rest scales (BVH has none): cheaper made here than broadcast and copied
    for a in (rot, trans, scales):
        a.setflags(write=False)  # made here and handed over: the clip keeps them without a copy
    clip = Clip(sk, rate, rot, trans, scales, name=path.stem)
    if fps is not None and T:
        clip = clip.resample(fps)
    return Asset(str(path), (sk,), (clip,), ())


class _ChannelLayout:
    """Where each joint's channels are among the motion values, as the two conversions want it.

    Attributes
    ----------
    first, count, axes, cols : list of int
        The rotation channels joint after joint (the compiled conversion): joint ``k`` has
        channels ``first[k] .. first[k] + count[k] - 1`` of ``axes`` (0 X, 1 Y, 2 Z) and
        ``cols`` (columns of the values).
    moved : tuple of three lists of int
        The position channels in file order: joint, axis, column.
    groups : dict
        Rotation axes (``(2, 0, 1)`` for ``Zrotation Xrotation Yrotation``) -> (the joints
        with those channels, their columns joint after joint): the NumPy conversion
        converts each group at once.
    """

    def __init__(self, joints: list[BvhJoint]):
        first: list[int] = []
        count: list[int] = []
        axes: list[int] = []
        cols: list[int] = []
        moved: tuple[list, list, list] = ([], [], [])
        groups: dict[tuple, tuple[list, list]] = {}
        kinds: dict[tuple, tuple] = {}  # a joint's channel names -> its rotation and position channels
        col = 0
        for k, j in enumerate(joints):
            channels = tuple(j.channels)
            kind = kinds.get(channels)
            if kind is None:
                pairs = [_CHANNELS[c.lower()] for c in channels]
                kind = kinds[channels] = (tuple(a for what, a in pairs if what == "r"),
                                          [i for i, (what, _) in enumerate(pairs) if what == "r"],
                                          [a for what, a in pairs if what == "p"],
                                          [i for i, (what, _) in enumerate(pairs) if what == "p"])
            raxes, rplaces, paxes, pplaces = kind
            first.append(len(cols))
            count.append(len(raxes))
            if raxes:
                jcols = [col + i for i in rplaces]
                axes += raxes
                cols += jcols
                group = groups.get(raxes)
                if group is None:
                    group = groups[raxes] = ([], [])
                group[0].append(k)
                group[1].extend(jcols)
            if paxes:
                moved[0].extend([k] * len(paxes))
                moved[1].extend(paxes)
                moved[2].extend([col + i for i in pplaces])
            col += len(channels)
        self.first, self.count, self.axes, self.cols, self.moved, self.groups = first, count, axes, cols, moved, groups


#: Rotation channels converted together, a block of frames at a time (their temporaries stay in cache).
_ANGLES_PER_CHUNK = 3 * 8192


def _rotations_numpy(values: np.ndarray, groups: dict, rot: np.ndarray) -> None:
    """Fill ``rot (T, J, 4)`` (xyzw) with the rotations of the rotation channels of ``values (T, C)``.

    ``groups`` maps rotation axes to the joints with those channels and their columns,
    joint after joint (:class:`_ChannelLayout`); joints in no group get the identity.
    Joints whose every rotation channel holds the same number (to the bit) in every
    frame, as real files' unused channels do (51 of the 65 joints of the sample
    conversation's body-only take, 6 of 17 in the Leap files), are converted from the
    first frame and copied to the others: the same numbers. The others are converted
    by :func:`_convert_rotations`.
    """
    T, J = rot.shape[:2]
    posed, moving = {}, groups
    if T > 1 and values.size >= _POSED_AFTER:
        posed, moving = _posed_joints(values, groups)
    if posed:
        one = np.empty((1, J, 4))
        _convert_rotations(values[:1], posed, one)
        ks = [k for ks, _ in posed.values() for k in ks]
        rot[:, ks] = one[:, ks]
    still = set(range(J)).difference(*(ks for ks, _ in groups.values()))
    if still:  # joints without rotation channels
        rot[:, sorted(still)] = quat_identity()
    _convert_rotations(values, moving, rot)


#: Motion values (frames x channels) from which the reader looks for posed joints: in smaller
#: files their conversion is mostly the cost of the calls, which the search and the extra
#: one-frame conversion would double (measured: Leap files, 153-317 frames x 66 values, no gain).
_POSED_AFTER = 20_000


def _posed_joints(values: np.ndarray, groups: dict) -> tuple[dict, dict]:
    """``groups`` split in two: the joints whose rotation columns hold the same bits in every frame, and the others.

    Frames 0 and 1 name the candidates (none in a file whose every channel moves: one
    comparison of two rows), the candidates' columns are then compared over all frames.
    """
    bits = values.view(np.int64)  # -0.0 is not 0.0 here: their sines differ in sign
    cols = np.array([c for _, kcols in groups.values() for c in kcols], dtype=np.int64)
    first = bits[0, cols]
    maybe = cols[bits[1, cols] == first]
    if not len(maybe):
        return {}, groups
    fixed = set(maybe[(bits[:, maybe] == bits[0, maybe]).all(axis=0)].tolist())
    posed: dict = {}
    moving: dict = {}
    for axes, (ks, kcols) in groups.items():
        n = len(axes)
        for m, k in enumerate(ks):
            jcols = kcols[m * n:m * n + n]
            ks_, cols_ = (posed if fixed.issuperset(jcols) else moving).setdefault(axes, ([], []))
            ks_.append(k)
            cols_.extend(jcols)
    return posed, moving


def _convert_rotations(values: np.ndarray, groups: dict, rot: np.ndarray) -> None:
    """Write the rotations of ``groups``' joints (see :func:`_rotations_numpy`) into ``rot (T, J, 4)``.

    For a block of frames at a time, the angles of every rotation channel are gathered
    into one array, a row per channel and joint (a group's first channel of every joint,
    then its second...), their half angles' cosines and sines computed in one call each,
    and each group's axis rotations multiplied (:func:`_axis_product`) on whole rows of
    them, all its joints at once.
    """
    T = len(values)
    order, plan = [], []  # the columns gathered; (axes, joints, rows of the block, the joints in rot)
    for axes, (ks, cols) in groups.items():
        for i in range(len(axes)):
            order.extend(cols[i::len(axes)])
        whole = ks[-1] - ks[0] == len(ks) - 1  # the joints follow each other: a slice of rot
        plan.append((axes, len(ks), slice(len(order) - len(cols), len(order)),
                     slice(ks[0], ks[-1] + 1) if whole else np.array(ks)))
    if not order or not T:
        return
    rcols = np.array(order, dtype=np.int64)
    step = max(1, _ANGLES_PER_CHUNK // len(rcols))
    for t in range(0, T, step):
        half = values[t:t + step].T[rcols]  # (channels, frames): each channel's angles contiguous
        half *= _RADIANS  # np.radians' number (it multiplies by pi / 180), a vectorised multiply
        half *= 0.5
        c = np.cos(half)
        s = np.sin(half, out=half)
        for axes, size, rows, ks in plan:
            q = _axis_product(c[rows].reshape(len(axes), size, -1), s[rows].reshape(len(axes), size, -1), axes)
            # joints scattered among others: the block's rotations side by side, then one indexed write
            out = rot[t:t + step, ks] if isinstance(ks, slice) else np.empty((len(half[0]), size, 4))
            for k in range(4):
                out[:, :, k] = 0.0 if q[k] is None else q[k].T
            if not isinstance(ks, slice):
                rot[t:t + step, ks] = out


#: Radians a degree, the factor ``np.radians`` multiplies by (NumPy's ``NPY_PI / 180.0``).
_RADIANS = np.pi / 180.0


def _translations_numpy(values: np.ndarray, offsets: np.ndarray, moved: tuple, trans: np.ndarray) -> None:
    """Fill ``trans (T, J, 3)``: the ``offsets (J, 3)``, position channels in place of their components.

    ``moved`` lists the position channels (joints, axes, columns of ``values``), in file
    order: a channel given twice, the last one wins.
    """
    T, J = trans.shape[:2]
    flat = trans.reshape(T, 3 * J)  # column 3k + axis: joint k's translation along axis
    dest = [3 * k + a for k, a in zip(moved[0], moved[1])]
    if dest == list(range(3 * J)):  # every joint X, Y, Z: one gather, no offsets under it
        np.take(values, moved[2], axis=1, out=flat)
    else:
        trans[:] = offsets
        if dest:  # one fancy assignment, in file order
            flat[:, dest] = np.take(values, moved[2], axis=1)


def euler_channels_to_quat(angles_deg: np.ndarray, axes: tuple[int, ...]) -> np.ndarray:
    """Rotations of BVH rotation channels: the product of axis rotations in channel order.

    Parameters
    ----------
    angles_deg : (..., n) float
        Degrees, one per channel, in channel order.
    axes : tuple of int, length n
        Axis of each channel (0 = X, 1 = Y, 2 = Z); any number and order (``"ZXY"``
        is ``(2, 0, 1)``), which for three distinct axes is scipy's intrinsic
        ``from_euler("ZXY", ...)``.

    Returns
    -------
    (..., 4) float
        Quaternions xyzw: the numbers the reader makes of the same angles.
    """
    angles = np.asarray(angles_deg, dtype=np.float64)
    if angles.shape[-1:] != (len(axes),):
        raise ValueError(f"Expected {len(axes)} angles per rotation, got shape {angles.shape}")
    flat = angles.reshape(-1, len(axes))
    out = np.empty((len(flat), 4))
    step = max(1, _ANGLES_PER_CHUNK // max(1, len(axes)))
    for start in range(0, len(flat), step):  # temporaries stay in cache
        block = flat[start:start + step]
        half = np.multiply(block.T, _RADIANS, out=np.empty((len(axes), len(block))))  # channel-major
        half *= 0.5
        q = _axis_product(np.cos(half), np.sin(half), axes)
        for k in range(4):
            out[start:start + step, k] = 0.0 if q[k] is None else q[k]
    return out.reshape(angles.shape[:-1] + (4,))


def _axis_product(c, s, axes: tuple[int, ...]) -> list:
    """The product of the axis rotations in channel order, component-major: ``[x, y, z, w]``.

    ``c[i]`` and ``s[i]`` are the cosines and sines of channel ``i``'s half angles (arrays
    of one shape); a component is None where it is zero. The axis rotations are
    multiplied on whole arrays, skipping the components known to be zero: the first
    rotation is ``(s e_a, c)`` as it is, the second takes four products, the third eight
    and four sums (three distinct axes: 12 multiplications instead of 24 from the
    identity). The same numbers as the product from the identity (``+0.0`` where that
    gave ``0 * c + 0``), and as the compiled twin (``_bvh_kernel.clip_arrays``).
    """
    # component-major x, y, z, w; None for a component that is zero
    q: list = [None, None, None, c[0]]
    q[axes[0]] = s[0]
    for i in range(1, len(axes)):
        # q * (s e_a + c) = q c + (q * e_a) s, q * e_a a signed permutation of q's components
        perm, sign = _AXIS_PRODUCT[axes[i]]
        new = []
        for k in range(4):
            kept, moved = q[k], q[perm[k]]
            if moved is None:
                new.append(None if kept is None else kept * c[i])
                continue
            term = moved * s[i]
            if kept is None:
                new.append(np.negative(term, out=term) if sign[k] < 0 else term)
                continue
            out = kept * c[i]
            if sign[k] < 0:
                out -= term
            else:
                out += term
            new.append(out)
        q = new
    return q


# q * e_x = (w, z, -y, -x), q * e_y = (-z, w, x, -y), q * e_z = (y, -x, w, -z)  (xyzw)
_AXIS_PRODUCT = {0: ([3, 2, 1, 0], np.array([1.0, 1.0, -1.0, -1.0])),
                 1: ([2, 3, 0, 1], np.array([-1.0, 1.0, 1.0, -1.0])),
                 2: ([1, 0, 3, 2], np.array([1.0, -1.0, 1.0, -1.0]))}


def _euler(q: np.ndarray, axes: str) -> np.ndarray:
    """Intrinsic Euler angles in degrees, unwrapped along time, for 1 to 3 axes.

    ``q`` is ``(T, ..., 4)`` xyzw (any number of joints after the time axis, converted
    in one call); returns ``(T, ..., len(axes))``.
    """
    full = axes
    if len(set(axes)) < 3 and len(axes) < 3:
        full = axes + "".join(a for a in _AXES if a not in axes)[: 3 - len(axes)]
    q = np.asarray(q)
    e = quat_to_euler_deg(q.reshape(-1, 4), full)  # scipy's as_euler (gimbal lock: third angle 0), without scipy
    if len(axes) == 2 and len(set(axes)) == 2:
        # two channels: keep the solution whose dropped third angle is near 0, not 180; for three
        # distinct axes (t1, t2, t3) and (t1 + 180, 180 - t2, t3 + 180) are the same rotation
        flip = np.abs(e[:, 2]) > 90
        e[flip, 0] = (e[flip, 0] + 360) % 360 - 180
        e[flip, 1] = (360 - e[flip, 1]) % 360 - 180
    e = e[:, : len(axes)].reshape(q.shape[:-1] + (len(axes),))
    return unwrap_deg(e, axis=0) if len(e) > 1 else e


def _format_rows(values: np.ndarray) -> str:
    if values.shape[1] == 0:
        return "\n" * values.shape[0]
    values = np.where(np.abs(values) < 5e-7, 0.0, values)  # no "-0.000000"
    return format_rows_6f(values)


def _motion_text(frames: int, fps: float, values: np.ndarray) -> str:
    return f"MOTION\nFrames: {frames}\nFrame Time: {1.0 / fps:.10g}\n" + _format_rows(values)


def _clip_in(clip: Clip, meters_per_unit: float) -> Clip:
    """``clip`` in ``meters_per_unit`` and +Y up."""
    from usdhands.model.units import clip_to, skeleton_to

    sk = clip.skeleton
    if sk.up_axis == "Y" and abs(sk.meters_per_unit - meters_per_unit) < 1e-15:
        return clip
    return clip_to(clip, skeleton_to(sk, meters_per_unit, "Y"))


def _baked_translations(clip: Clip) -> tuple[np.ndarray, np.ndarray]:
    """Rest offsets ``(J, 3)`` and translations ``(T, J, 3)`` with the scales above each joint baked in.

    BVH has no scale: each joint's translation is multiplied by the accumulated scale
    of its ancestors (exact for uniform scales; a non-uniform scale counts as the mean
    of its components).
    """
    sk = clip.skeleton
    rest_s = np.abs(sk.rest_scales).mean(axis=-1)  # (J,)
    anim_s = np.abs(clip.scales).mean(axis=-1)  # (T, J)
    if np.allclose(rest_s, 1.0, atol=1e-12) and np.allclose(anim_s, 1.0, atol=1e-12):
        return np.asarray(sk.rest_translations), np.asarray(clip.translations)
    J = sk.num_joints
    rest_w = np.ones(J)
    anim_w = np.ones(anim_s.shape)
    rest_par = np.ones(J)
    anim_par = np.ones(anim_s.shape)
    for j, p in enumerate(sk.parents):
        if p >= 0:
            rest_par[j], anim_par[:, j] = rest_w[p], anim_w[:, p]
        rest_w[j] = rest_par[j] * rest_s[j]
        anim_w[:, j] = anim_par[:, j] * anim_s[:, j]
    return sk.rest_translations * rest_par[:, None], clip.translations * anim_par[..., None]


def _bvh_names(sk: Skeleton) -> list[str]:
    shorts = [re.sub(r"\s+", "_", n) for n in sk.short_names]
    if len(set(shorts)) == len(shorts):
        return shorts
    return [re.sub(r"[\s/]+", "_", n) for n in sk.joint_names]


def _check_order(order: str) -> str:
    o = str(order).upper()
    if len(o) != 3 or set(o) != set(_AXES):
        raise ValueError(f"Expected a rotation order of X, Y and Z such as 'ZXY', got {order!r}")
    return o


class BvhHandler:
    """The BVH format handler (see the module documentation)."""

    name = "bvh"
    read_extensions = (".bvh",)
    write_extensions = (".bvh",)

    def read(self, path: str | os.PathLike, *, fps: float | None = None, units: str | float | None = None) -> Asset:
        """Read a BVH file.

        Parameters
        ----------
        path : path-like
        fps : float, optional
            Resample to this rate; the file's ``1 / Frame Time`` otherwise.
        units : str or float, optional
            The unit of the file's numbers: ``"cm"`` (default), ``"m"``, ``"mm"``,
            ``"dm"``, ``"in"``, ``"ft"``, or metres per unit.

        Returns
        -------
        Asset
            One skeleton (named after the file) and one clip.
        """
        path = Path(path)
        return bvh_to_asset(parse_bvh(path), path, units_to_meters(units), fps)

    def write(self, asset: Asset, path: str | os.PathLike, *, order: str = DEFAULT_ORDER,
              units: str | float | None = None, animation: str | int | None = None,
              provenance: dict | None = None, **options) -> None:
        """Write a new BVH file from an asset's first clip (or ``animation``).

        BVH has no place for a provenance record: one given (or the asset's, for the
        clip written) is named in a warning and not kept.

        Parameters
        ----------
        order : str
            Rotation channel order of every joint, e.g. ``"ZXY"`` (default).
        units : str or float, optional
            Unit of the numbers written (default centimetres).
        """
        order = _check_order(order)
        mpu = units_to_meters(units)
        if asset.clips:
            try:
                clip = asset.clip(animation)
            except KeyError as e:
                raise AssetReadError(str(e.args[0]).split(": ", 1)[-1], path=asset.path) from None
        elif asset.skeletons:
            sk = asset.skeletons[0]
            clip = Clip(sk, 30.0, sk.rest_rotations[None], name=sk.name)
        else:
            raise AssetReadError("nothing to write as BVH: no skeleton", path=asset.path)
        _warn_provenance_lost(provenance if provenance is not None else asset.provenance.get(clip.name))
        clip = _clip_in(clip, mpu)
        sk = clip.skeleton
        names = _bvh_names(sk)
        J = sk.num_joints
        kids = [sk.children(j) for j in range(J)]
        is_end = [not kids[j] and sk.parents[j] >= 0 and names[j] == names[sk.parents[j]] + END_SUFFIX
                  for j in range(J)]
        rest_t, anim_t = _baked_translations(clip)
        moved = np.abs(anim_t - rest_t[None]).max(axis=0).max(axis=-1) > 1e-9 \
            if clip.num_frames else np.zeros(J, bool)
        rot_ch = " ".join(f"{a}rotation" for a in order)
        lines = ["HIERARCHY"]
        columns = []  # (joint, "p"/"r")

        def emit(j: int, depth: int) -> list:
            """Lines opening joint ``j``; returns the children to emit before its closing brace."""
            ind = "\t" * min(depth, MAX_INDENT)
            off = rest_t[j]
            if is_end[j]:
                lines.extend([f"{ind}End Site", f"{ind}{{", f"{ind}\tOFFSET {_FMT % off[0]} {_FMT % off[1]} "
                              f"{_FMT % off[2]}", f"{ind}}}"])
                return []
            kw = "ROOT" if sk.parents[j] < 0 else "JOINT"
            lines.extend([f"{ind}{kw} {names[j]}", f"{ind}{{",
                          f"{ind}\tOFFSET {_FMT % off[0]} {_FMT % off[1]} {_FMT % off[2]}"])
            if sk.parents[j] < 0 or moved[j]:
                lines.append(f"{ind}\tCHANNELS 6 Xposition Yposition Zposition {rot_ch}")
                columns.append((j, "p"))
            else:
                lines.append(f"{ind}\tCHANNELS 3 {rot_ch}")
            columns.append((j, "r"))
            return kids[j]

        # depth first with a stack (a chain 10,000 joints deep overflowed the recursion)
        stack = [(r, 0, False) for r in range(J - 1, -1, -1) if sk.parents[r] < 0]
        while stack:
            j, depth, closing = stack.pop()
            if closing:
                lines.append("\t" * min(depth, MAX_INDENT) + "}")
                continue
            children = emit(j, depth)
            if not is_end[j]:
                stack.append((j, depth, True))
                stack.extend((c, depth + 1, False) for c in reversed(children))
        rotated = [j for j, kind in columns if kind == "r"]
        euler = _euler(clip.rotations[:, rotated], order) if clip.num_frames and rotated else None
        parts = []
        r = 0
        for j, kind in columns:
            if kind == "p":
                parts.append(anim_t[:, j])
            else:
                parts.append(euler[:, r] if euler is not None else np.zeros((clip.num_frames, 3)))
                r += 1
        values = np.concatenate(parts, axis=1) if parts else np.zeros((clip.num_frames, 0))
        Path(path).write_text("\n".join(lines) + "\n" + _motion_text(clip.num_frames, clip.fps, values),
                              encoding="utf-8")

    def write_clip(self, source: str | os.PathLike, clip: Clip, path: str | os.PathLike, *,
                   units: str | float | None = None, provenance: dict | None = None, **options) -> None:
        """Write ``source``'s hierarchy (text unchanged) with ``clip``'s motion.

        A ``provenance`` record is not kept (BVH has no place for it); logged at INFO.

        Every ROOT/JOINT of the source must be in the clip's skeleton (matched by
        short name); channel orders are the source's.

        Parameters
        ----------
        source : path-like
            The BVH file whose hierarchy is kept.
        clip : Clip
            Converted to ``units`` and +Y up first when it is in other units or Z-up.
        path : path-like
            The file to write.
        units : str or float, optional
            The unit of the source's numbers (default centimetres): pass the
            ``units`` the source was read with.

        Raises
        ------
        JointMismatchError
            Naming the source joints the clip lacks.
        """
        source = Path(source)
        bvh = parse_bvh(source)
        _warn_provenance_lost(provenance, logging.INFO)  # the command chose BVH: -v says so
        clip = _clip_in(clip, units_to_meters(units))
        sk = clip.skeleton
        lookup = {}
        for i, n in enumerate(sk.short_names):
            lookup.setdefault(n, i)
        for i, n in enumerate(sk.joint_names):
            lookup.setdefault(n, i)
        missing = [j.name for j in bvh.joints if not j.end_site and j.name not in lookup]
        if missing:
            raise JointMismatchError(f"the clip has no joint(s) {', '.join(missing[:10])}"
                                     f"{' ...' if len(missing) > 10 else ''} of the source hierarchy",
                                     path=source)
        T = clip.num_frames
        _, anim_t = _baked_translations(clip)
        channelled = []  # (clip joint, [(kind, axis)], rotation axes, place in its rotation-order group)
        groups: dict[str, list] = {}  # rotation axes ("ZXY") -> clip joints, converted in one call
        for bj in bvh.joints:
            if bj.channels:
                k = lookup[bj.name]
                kinds = [_CHANNELS[c.lower()] for c in bj.channels]
                raxes = "".join(_AXES[a] for kind, a in kinds if kind == "r")
                group = groups.setdefault(raxes, [])
                channelled.append((k, kinds, raxes, len(group)))
                group.append(k)
        euler = {raxes: _euler(clip.rotations[:, ks], raxes) for raxes, ks in groups.items() if raxes and T}
        parts = []
        for k, kinds, raxes, g in channelled:
            e = euler[raxes][:, g] if raxes and T else np.zeros((T, len(raxes)))
            ri = 0
            for kind, a in kinds:
                if kind == "p":
                    parts.append(anim_t[:, k, a][:, None])
                else:
                    parts.append(e[:, ri:ri + 1])
                    ri += 1
        values = np.concatenate(parts, axis=1) if parts else np.zeros((T, 0))
        Path(path).write_text(bvh.hierarchy_text + _motion_text(T, clip.fps, values), encoding="utf-8")


def _warn_provenance_lost(record: dict | None, level: int = logging.WARNING) -> None:
    if record:
        _log.log(level, "BVH cannot record how the finger motion was made (method %r): provenance not kept",
                 record.get("method"))


HANDLER = BvhHandler()

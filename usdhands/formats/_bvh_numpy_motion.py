"""The ``MOTION`` block of a BVH file parsed with NumPy: the values of a fresh process's read.

:func:`parse_rows` is a twin of ``np.loadtxt`` on the motion lines, for the numbers BVH
exporters write (``-12.345678``, ``0``, ``49.97``), in whole-array operations on the bytes
(2-3x faster than ``np.loadtxt``, measured on the sample and shared BVH files). It reads
only what it can read exactly as ``float()`` does (and ``np.loadtxt``, which gives
``float()``'s numbers) and hands everything else back to the caller, which then reads the
block with ``np.loadtxt`` (and names a bad line):

- a number is ``[+-]digits[.digits]`` (either side of the point may be empty, not both),
  at most 8 digits before the point and at most 7 after it (the point among its last 8
  bytes); no exponent;
- its value is the digits as an integer ``w`` (below ``10**15``: exact in a double) over
  ``10**k`` for ``k`` digits after the point (exact too): one correctly rounded division,
  the correctly rounded value of the decimal, which is ``float()``'s; signed as written
  (``-0.000000`` is ``-0.0``);
- numbers are separated by spaces and tabs; lines end with ``\\n``, ``\\r\\n`` or ``\\r``
  (as the text file ``np.loadtxt`` reads has them); lines holding only spaces and tabs are
  skipped, as ``np.loadtxt`` skips them; every other line must hold exactly ``C`` numbers;
  any other byte hands the block back.

How: a block of lines (about 64 KB) at a time, the numbers are found as the runs of bytes
above ``" "``; for each, the 8 bytes that end it are read as one little-endian 64-bit word,
its point found by a zero-byte test on the word, and the digits on either side turned
into integers eight at a time (the usual SWAR steps: pairs, quads, eights by three
multiplications). Tests hold it to ``float()`` on random decimal strings and to
``np.loadtxt`` on every real BVH file, its variants and mutated files.
"""

from __future__ import annotations

import numpy as np

__all__ = ["parse_rows"]

#: Bytes of motion text parsed together (whole lines): their temporaries stay in cache and below
#: the size malloc maps fresh pages for (blocks of 256 KB were 1.3-2x slower in a fresh process:
#: page faults on every temporary; 16 KB ones paid their ~60 NumPy calls too often).
_BLOCK_BYTES = 1 << 16

_U = np.uint64
#: For n = 0..8: a word's last n bytes (the high ones: the word is little-endian) kept ...
_KEEP_LAST = np.array([((1 << 64) - 1) ^ ((1 << (8 * (8 - n))) - 1) for n in range(9)], dtype=_U)
#: ... and the others made the digit 0.
_ZEROS_BEFORE = ~_KEEP_LAST & _U(0x3030303030303030)
_POINTS = _U(0x2E2E2E2E2E2E2E2E)
_ONES = _U(0x0101010101010101)
_HIGH_BITS = _U(0x8080808080808080)
#: Byte j holds j, and j + 1: the product of ``1 << 8 b`` and these has ``7 - b``, and ``8 - b``, in its top byte.
_AFTER = _U(0x0706050403020100)
_BACK = _U(0x0807060504030201)
_LOW_NIBBLES = _U(0x0F0F0F0F0F0F0F0F)
#: 10**0 .. 10**22: the powers of ten a double holds exactly.
_POW10 = np.array([10.0 ** k for k in range(23)])
#: Those and their negatives (from 23 on).
_SIGNED_POW10 = np.concatenate([_POW10, -_POW10])
#: For a number's first byte: 1 for a sign (int64) ...
_SIGNED = np.zeros(256, dtype=np.int64)
_SIGNED[[ord("-"), ord("+")]] = 1
#: ... and 23 for a minus (the index of the negative powers).
_MINUS = np.zeros(256, dtype=np.int64)
_MINUS[ord("-")] = len(_POW10)


def _eight_digits(w: np.ndarray) -> np.ndarray:
    """``(n,)`` uint64 words of 8 ASCII digits each (the first digit in the low byte) -> their
    integers ``(n,)`` uint64 (0 .. 99,999,999); ``w`` is overwritten."""
    w &= _LOW_NIBBLES
    w *= _U(10 * 256 + 1)  # each pair of digits: 10 a + b in its high byte
    w >>= _U(8)
    w &= _U(0x00FF00FF00FF00FF)
    w *= _U(100 * 65536 + 1)  # each quad
    w >>= _U(16)
    w &= _U(0x0000FFFF0000FFFF)
    w *= _U(10000 * (1 << 32) + 1)  # the eight
    w >>= _U(32)
    return w


def parse_rows(buf: bytes, start: int, columns: int, out: np.ndarray) -> int:
    """Parse ``buf[start:]`` (the motion lines) into ``out (rows, columns)`` float64.

    ``start`` is at least 8 (the 8 bytes before a number are read with it, and ignored).
    Returns the number of rows read (``<= out.shape[0]``), or ``-1`` when the text holds
    anything outside the forms above, a row of another length, or more rows than ``out``.
    """
    if start < 8:
        raise ValueError(f"Expected start >= 8, got {start}")
    a = np.frombuffer(buf, np.uint8)
    words = np.ndarray((len(buf) - 7,), dtype="<u8", buffer=buf, strides=(1,))  # the word at every byte
    flat = out.reshape(-1)
    done = 0  # values written
    lo, n = start, len(buf)
    while lo < n:
        hi = buf.find(b"\n", lo + _BLOCK_BYTES) + 1 or n
        got = _parse_block(a, words, lo, hi, columns, flat[done:])
        if got < 0:
            return -1
        done += got
        lo = hi
    return done // columns


def _parse_block(a: np.ndarray, words: np.ndarray, lo: int, hi: int, columns: int, out: np.ndarray) -> int:
    """The numbers of the whole lines ``a[lo:hi]`` (uint8) into ``out`` (flat float64): how many, or -1.

    ``words`` is ``a`` as a little-endian uint64 word at every byte.
    """
    seg = a[lo:hi]
    inside = np.zeros(len(seg) + 2, dtype=bool)
    np.greater(seg, 32, out=inside[1:-1])  # bytes of numbers
    edges = np.flatnonzero(inside[1:] != inside[:-1])
    edges += lo
    starts, ends = edges[0::2], edges[1::2]  # each number's first byte, and the byte after it
    count = len(starts)
    if count == 0:
        return 0
    if count > len(out):
        return -1
    # every byte a separator (space, tab, \n, \r) or part of a number (digit, point, sign)
    in_numbers = int(ends.sum()) - int(starts.sum())
    signs = np.count_nonzero(seg == 45) + np.count_nonzero(seg == 43)
    points = np.count_nonzero(seg == 46)
    if np.count_nonzero((seg - 48) < 10) + points + signs != in_numbers:
        return -1
    crs = np.count_nonzero(seg == 13)
    if np.count_nonzero(seg == 32) + np.count_nonzero(seg == 9) + np.count_nonzero(seg == 10) + crs != \
            len(seg) - in_numbers:
        return -1
    # rows: each line ends with \n or \r (\r\n makes one more line, empty) and holds 0 or `columns` numbers
    breaks = np.flatnonzero(seg == 10) if not crs else np.flatnonzero((seg == 10) | (seg == 13))
    before = np.searchsorted(starts, breaks + lo)  # numbers before each line break
    per_line = np.diff(before, prepend=0, append=count)
    if ((per_line != 0) & (per_line != columns)).any():
        return -1
    first = a[starts]
    signed = _SIGNED[first]  # 1 where a number starts with a sign
    if int(signed.sum()) != signs:  # a sign elsewhere than first
        return -1
    # the last 8 bytes of each number (the bytes before it made zeros), its point found among them
    length = ends - starts
    np.minimum(length, 8, out=length)
    w = words[ends - 8]
    w &= _KEEP_LAST[length]
    w |= _ZEROS_BEFORE[length]
    x = w ^ _POINTS  # a zero byte where the point is
    m = x - _ONES
    m &= ~x
    m &= _HIGH_BITS  # 0x80 in the point's byte b (no other byte: digits and signs are not 0x2F)
    if np.count_nonzero(m) != points:  # two points in a number, or a point further left
        return -1
    m >>= _U(7)  # 1 << 8 b, or 0 without a point
    after = (m * _AFTER).view(np.int64)
    after >>= 56  # 7 - b: the digits after the point (0 without one)
    m *= _BACK
    m >>= _U(56)  # 8 - b: the point's place back from the end (0 without one)
    point = ends - m.view(np.int64)  # the point's byte, or the end of a number without one
    before_point = point - starts
    before_point -= signed  # the digits before it
    if before_point.max() > 8:
        return -1
    if (before_point + after).min() < 1:  # a sign or a point alone
        return -1
    w &= _KEEP_LAST[after]
    w |= _ZEROS_BEFORE[after]
    fraction = _eight_digits(w).view(np.int64).astype(np.float64)
    point -= 8
    w = words[point]
    w &= _KEEP_LAST[before_point]
    w |= _ZEROS_BEFORE[before_point]
    value = out[:count]
    np.copyto(value, _eight_digits(w).view(np.int64))  # below 10**8: exact
    value *= _POW10[after]  # the digits as one integer, below 10**15: exact
    value += fraction
    after += _MINUS[first]
    value /= _SIGNED_POW10[after]  # the one rounding, and the sign (-0.0 where written so)
    return count

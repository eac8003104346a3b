"""The BVH reader's NumPy motion parser (usdhands.formats._bvh_numpy_motion) against float() and
np.loadtxt: random decimal strings, lines and separators, blocks cut anywhere, real files, and
mutated motion text (whatever it reads, np.loadtxt reads to the same bits)."""

from __future__ import annotations

import random
import re
import sys
from pathlib import Path

import numpy as np
import pytest

import usdhands.formats.bvh as bvh_module
from usdhands.formats import _bvh_numpy_motion as numpy_motion

sys.path.insert(0, str(Path(__file__).resolve().parent / "fuzz"))

from test_bvh_compiled_reader import NOT_READ, SPECIAL, _bvh_sources, _random_token, assert_reads_as_float  # noqa: E402,E501


def _read(text: bytes, columns: int, rows: int = 1):
    """parse_rows of ``text``: the array read, or None where it hands the text back."""
    out = np.empty((rows, columns))
    got = numpy_motion.parse_rows(b"HEAD....." + text, 9, columns, out)
    return None if got < 0 else out[:got]


def _loadtxt(text: bytes, columns: int):
    """What the reader's np.loadtxt path makes of ``text`` (decoded, line breaks as a text file has them)."""
    lines = text.decode("utf-8", errors="replace").replace("\r\n", "\n").replace("\r", "\n").split("\n")
    return bvh_module._motion_values(lines, columns)


def _reads(token: str) -> bool:
    """Whether parse_rows should read ``token`` (the rules of its docstring, written out in Python)."""
    m = re.fullmatch(r"[+-]?([0-9]*)(?:\.([0-9]*))?", token)
    if m is None or not (m.group(1) or m.group(2)):
        return False
    before, after = len(m.group(1)), len(m.group(2) or "")
    return before <= 8 and after <= 7 and before + after <= 15


def test_parse_rows_reads_exactly_what_float_reads():
    """Random decimal strings (exponents, long mantissas, negative zero, leading zeros, either side
    of the point empty): read exactly where the rules say, and then to float()'s bit."""
    rng = random.Random(8)
    tokens = SPECIAL + [_random_token(rng) for _ in range(30_000)]
    tokens += ["%.*f" % (rng.randint(0, 7), rng.uniform(-1e8, 1e8) * 10.0 ** -rng.randint(0, 8)) for _ in range(20_000)]
    tokens += ["12345678.1234567", "123456789", "12345678", "1234567.12345678", "0.1234567", "-99999999.9999999",
               "00000000.0000000", "-.0000001", "+12345678.", "1.", "-0", "+0.0"]
    assert assert_reads_as_float(_read, _reads, tokens) > 0.5 * len(tokens)
    assert _read(b"-0.000000\n", 1)[0, 0].tobytes() == np.float64(-0.0).tobytes()
    assert _read(b"-99999999.9999999\n", 1)[0, 0] == float("-99999999.9999999")
    for t in NOT_READ + ["1-", "1+2", "-", "+.", "1..", ".1.", "1/2", "1,2", "1:2", "1 .", "-1.2-"]:
        got = _read((t + "\n").encode("utf-8"), 1 + t.count(" "))
        assert got is None or _loadtxt((t + "\n").encode(), 1 + t.count(" ")) is not None, t


def test_parse_rows_lines_like_loadtxt():
    """Blank lines and lines of spaces and tabs skipped, CRLF, a lone CR (a line break, as the text
    np.loadtxt reads has it), no final line break; a row of another length, more rows than
    room, other whitespace and control bytes: handed back."""
    text = b"1 2 3\r\n\n \t \n4\t5  6\r7 8 9\n\n10 11 12"
    assert np.array_equal(_read(text, 3, 4), [[1, 2, 3], [4, 5, 6], [7, 8, 9], [10, 11, 12]])
    assert _read(text, 3, 4).tobytes() == _loadtxt(text, 3).tobytes()
    assert _read(b"", 3, 3).shape == (0, 3)
    assert _read(b"\n \n\t\n", 3, 3).shape == (0, 3)
    for bad in (b"1 2 3\n4 5\n", b"1 2 3 4\n", b"1 2\x0c3\n", b"1 2 3\n\x0b\n", b"1 2 3\n" * 4, b"1 2 3\x00\n",
                b"1 2 3\n4 5 6 7", b"1 2 3\x1c\n", b"1 2 3\xc2\x85\n", b"1 2 3\n4 5 6\n\x85"):
        assert _read(bad, 3, 3) is None, bad


@pytest.mark.parametrize("block_bytes", [1, 9, 64, 1000, 1 << 16])
def test_blocks_cut_anywhere_read_alike(sample_assets, monkeypatch, block_bytes):
    """The motion of every real file read in blocks of lines of any size: np.loadtxt's numbers to the bit
    (the files' own numbers, and the NumPy parser reads them all, not handing them back)."""
    monkeypatch.setattr(numpy_motion, "_BLOCK_BYTES", block_bytes)
    for src in _bvh_sources(sample_assets):
        data = src.read_bytes()
        start = data.index(b"\n", data.index(b"Frame Time")) + 1
        columns = len(data[start:].split(b"\n", 1)[0].split())
        expected = _loadtxt(data[start:], columns)
        out = np.empty((len(expected) + 1, columns))
        got = numpy_motion.parse_rows(data, start, columns, out)
        assert got == len(expected), src.name
        assert out[:got].tobytes() == expected.tobytes(), src.name


def test_what_it_reads_loadtxt_reads_alike_on_mutated_motion(sample_assets):
    """Random edits of real motion text (bytes flipped, numbers replaced by odd tokens, cuts, copies,
    separators changed) and random rows of random tokens: where parse_rows reads the text,
    np.loadtxt reads the same numbers to the bit; where np.loadtxt refuses it, parse_rows does too
    (text without numbers: no rows, as np.loadtxt finds none)."""
    from fuzz_target import mutate

    rng = random.Random(3)
    blocks = []
    for src in _bvh_sources(sample_assets):
        data = src.read_bytes()
        start = data.index(b"\n", data.index(b"Frame Time")) + 1
        rows = data[start:].split(b"\n")
        blocks.append((b"\n".join(rows[:6]) + b"\n", len(rows[0].split())))
    tokens = SPECIAL + NOT_READ + ["", "-", ".", "1-", "1.2.3", "\t", "\r", "\r\n", "  "]
    read = refused = 0
    for n in range(3000):
        if n % 4 == 3:  # rows of random tokens
            columns = rng.randint(1, 5)
            text = "".join(" ".join(rng.choice([_random_token(rng), rng.choice(tokens), "%.6f" % rng.uniform(-9, 9)])
                                    for _ in range(columns)) + rng.choice(["\n", "\r\n", "\r", "\n\n", " \n"])
                           for _ in range(rng.randint(0, 4))).encode()
        else:
            text, columns = rng.choice(blocks)
            if n % 4 == 0:
                text = mutate(text, rng)
            elif n % 4 == 1:  # numbers replaced by other tokens
                spans = [m.span() for m in re.finditer(rb"\S+", text)]
                for _ in range(rng.randint(1, 3)):
                    i, j = rng.choice(spans)
                    token = rng.choice(["%.*f" % (rng.randint(0, 9), rng.uniform(-1e3, 1e3)), _random_token(rng),
                                        rng.choice(tokens)])
                    text = text[:i] + token.encode().ljust(j - i) + text[j:] if len(token) <= j - i else text
            else:  # separators changed
                spans = [m.span() for m in re.finditer(rb"[ \t]+|\n", text)]
                for _ in range(rng.randint(1, 3)):
                    i, j = rng.choice(spans)
                    sep = rng.choice([b" ", b"\t", b"  ", b" \t "] * 3 + [b"\r\n", b"\r", b"\n\n", b"\n", b" \n"])
                    text = text[:i] + (sep.ljust(j - i) if len(sep) < j - i else sep) + text[j:]
                    spans = [m.span() for m in re.finditer(rb"[ \t]+|\n", text)]
        ours, theirs = _read(text, columns, 10), _loadtxt(text, columns)
        if ours is None:
            refused += 1
            continue
        if not len(ours):  # no numbers at all: np.loadtxt's None (both leave the frames to the caller's count)
            assert theirs is None or not len(theirs), text[:200]
            continue
        read += 1
        assert theirs is not None and ours.tobytes() == theirs.tobytes(), text[:200]
    assert read > 800 and refused > 800, (read, refused)  # both kinds were tried


def test_the_reader_uses_it_where_numba_does_not_run(sample_assets, tmp_path, monkeypatch):
    """A NumPy read of a real file goes through parse_rows (not np.loadtxt), from a file read whole and from
    one whose motion is read after the head; a file it hands back is read by np.loadtxt alike."""
    monkeypatch.setattr(bvh_module, "USE_COMPILED", False)
    calls = []
    real = numpy_motion.parse_rows

    def counted(*args):
        calls.append(real(*args))
        return calls[-1]

    monkeypatch.setattr(bvh_module, "parse_motion_rows", counted)
    src = sample_assets / "humanoid.bvh"
    expected = bvh_module.parse_bvh(src).values
    for head_bytes in (1 << 16, 256):
        monkeypatch.setattr(bvh_module, "_HEAD_BYTES", head_bytes)
        calls.clear()
        assert bvh_module.parse_bvh(src).values.tobytes() == expected.tobytes()
        assert calls == [len(expected)]
    data = src.read_text()
    p = tmp_path / "e.bvh"
    head, motion = data.split("Frame Time", 1)
    p.write_text(head + "Frame Time" + motion.replace(" 0.4", " 4e-1", 3))  # exponents: handed back, np.loadtxt reads them
    calls.clear()
    values = bvh_module.parse_bvh(p).values
    assert calls == [-1]
    monkeypatch.setattr(bvh_module, "parse_motion_rows", lambda *args: -1)
    assert values.tobytes() == bvh_module.parse_bvh(p).values.tobytes()

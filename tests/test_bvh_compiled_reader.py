"""The BVH reader's compiled twins: the motion parser against float() and np.loadtxt, the clip's
arrays against the NumPy conversion, whole reads against the NumPy reader and the
token-by-token reader (real files, variants, mutated bytes; the reader compiled at install
against numba's), and when the process uses them."""

from __future__ import annotations

import math
import os
import random
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import usdhands.formats.bvh as bvh_module
from usdhands.compiled import kernel_module
from usdhands.errors import AssetReadError
from usdhands.formats import _bvh_kernel as kernel
from usdhands.formats.bvh import HANDLER, parse_bvh

ROOT = Path(__file__).resolve().parent.parent
#: The reader compiled at install (the reader of USE_COMPILED None), or None where it was not built
AHEAD_OF_TIME = kernel_module("formats._bvh_compiled")
sys.path.insert(0, str(Path(__file__).resolve().parent / "fuzz"))


def _kernel_read(text: bytes, columns: int, rows: int = 1):
    """parse_rows of ``text``: the array read, or None where the kernel hands the text back."""
    out = np.empty((rows, columns))
    got = kernel.parse_rows(np.frombuffer(text, np.uint8), 0, columns, out, kernel.POW10)
    return None if got < 0 else out[:got]


def _fast_path_reads(token: str) -> bool:
    """Whether the kernel should read ``token`` (the rules of its docstring, written out in Python)."""
    m = re.fullmatch(r"[+-]?([0-9]*)(?:\.([0-9]*))?(?:[eE]([+-]?[0-9]{1,6}))?", token)
    if m is None or not (m.group(1) or m.group(2)):
        return False
    digits = (m.group(1) + (m.group(2) or "")).lstrip("0")
    if len(digits) > 19:
        return False
    w = int(digits or "0")
    e = int(m.group(3) or 0) - len(m.group(2) or "")
    return w == 0 or (w <= 2 ** 53 and -22 <= e <= 22)


def _random_token(rng: random.Random) -> str:
    k = rng.random()
    if k < 0.25:
        return "%.6f" % rng.uniform(-400, 400)
    if k < 0.35:
        return repr(rng.uniform(-1e3, 1e3))
    if k < 0.45:
        return "%.*e" % (rng.randint(0, 20), rng.uniform(-1, 1) * 10.0 ** rng.randint(-30, 30))
    if k < 0.55:
        return str(rng.randint(-10 ** rng.randint(1, 21), 10 ** rng.randint(1, 21)))
    digits = "".join(rng.choice("0123456789") for _ in range(rng.randint(1, 25)))
    p = rng.randint(0, len(digits))
    s = rng.choice(["", "-", "+"]) + digits[:p] + "." + digits[p:]
    if rng.random() < 0.4:
        s += rng.choice("eE") + rng.choice(["", "-", "+"]) + str(rng.randint(0, 40))
    return s


SPECIAL = ["-0", "-0.0", "-0.000000", "+0", "0e5", "-0e-5", "0e999999", ".5", "5.", "+.5", "-5.", "00001.5000",
           "1E5", "1e+05", "1e-05", "9007199254740992", "9007199254740993", "123456789012345678",
           "1234567890123456789", "12345678901234567890", "0.1", "0.30000000000000004", "1e22", "1e23", "1e-22",
           "1e-23", "4.35679e-310", "2.2250738585072014e-308", "179769313486231570000", "0.000000000000000000001",
           "1.7976931348623157e308", "5e-324"]
NOT_READ = ["nan", "inf", "-inf", "Infinity", "1e", "1e+", ".", "-", "+", "1.2.3", "1e5.0", "#1", "1,5", "1_000",
            "0x10", "\u0661", "1e1234567", "--1", "+-1", "e5", "1.5f", "1d5"]


def assert_reads_as_float(read, rules, tokens: list[str]) -> int:
    """Each token on a line of its own: ``read(text, 1)`` reads it exactly where ``rules(token)`` says,
    and then as the one value float() makes of it, to the bit. Returns how many it read."""
    count = 0
    for t in tokens:
        got = read((t + "\n").encode(), 1)
        assert (got is not None) == rules(t), t
        if got is not None:
            count += 1
            assert got.shape == (1, 1) and got[0, 0].tobytes() == np.float64(float(t)).tobytes(), t
    return count


def test_parse_rows_reads_exactly_what_float_reads():
    """Random decimal strings (long mantissas, exponents, negative zero, leading zeros, both sides
    of the point empty in turn): read exactly where the rules say, and then to float()'s bit."""
    rng = random.Random(7)
    tokens = SPECIAL + [_random_token(rng) for _ in range(30_000)]
    assert assert_reads_as_float(_kernel_read, _fast_path_reads, tokens) > 0.6 * len(tokens)
    assert _kernel_read(b"-0.000000\n", 1)[0, 0].tobytes() == np.float64(-0.0).tobytes()
    for t in NOT_READ:
        assert _kernel_read((t + "\n").encode("utf-8"), 1) is None, t


def test_parse_rows_lines_like_loadtxt():
    """Blank lines and lines of spaces and tabs skipped, CRLF, no final line break; a row of
    another length, a lone CR, more rows than room, other whitespace: handed back."""
    text = b"1 2 3\r\n\n \t \n4\t5  6\n\n7 8 9"
    assert np.array_equal(_kernel_read(text, 3, 3), [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    assert np.array_equal(_kernel_read(text, 3, 3), np.loadtxt(text.decode().splitlines(), ndmin=2))
    assert _kernel_read(b"", 3, 3).shape == (0, 3)
    for bad in (b"1 2 3\n4 5\n", b"1 2 3 4\n", b"1 2 3\r4 5 6\n", b"1 2\x0c3\n", b"1 2 3\n\x0b\n", b"1 2 3\n" * 4,
                b"1 2 3\x00\n", b"1 2 3\n4 5 6 7"):
        assert _kernel_read(bad, 3, 3) is None, bad


def _libm_trig(half: np.ndarray) -> bool:
    """Whether NumPy's float64 cos and sin of ``half`` are the C library's (math.cos, math.sin), as on
    x86-64 with NumPy 2: the compiled conversion's numbers are then NumPy's to the bit."""
    flat = half.ravel()
    return np.cos(flat).tobytes() == np.array([math.cos(x) for x in flat]).tobytes() and \
        np.sin(flat).tobytes() == np.array([math.sin(x) for x in flat]).tobytes()


def assert_same_rotations(ours: np.ndarray, twin: np.ndarray, angles_deg: np.ndarray) -> None:
    """Equal to the bit where NumPy's trigonometry is the C library's; else within 1e-15 (an ulp or two)."""
    if _libm_trig(np.radians(angles_deg) * 0.5):
        assert ours.tobytes() == twin.tobytes()
    else:
        assert np.abs(ours - twin).max() <= 1e-15


def test_compiled_clip_arrays_equal_the_numpy_conversion(monkeypatch):
    """Random hierarchies of random channels (0 to 6 a joint, any order, repeats: rotation axes
    given twice, a position channel given twice), angles with exact zeros (signed), half and
    whole turns, tiny ones: the compiled clip's rotations are the NumPy reader's (to the bit
    here), its translations the same numbers."""
    from usdhands.formats.bvh import BvhFile, BvhJoint, bvh_to_asset

    rng = np.random.default_rng(4)
    names = ["Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"]
    special = np.array([0.0, 90.0, -90.0, 180.0, -180.0, 360.0, -360.0, 720.5, 1e-300, -1e-7, -0.0])
    for trial in range(40):
        J = int(rng.integers(1, 9))
        joints = [BvhJoint(f"j{k}", int(rng.integers(-1, k)) if k else -1, rng.normal(size=3),
                           [names[c] for c in rng.integers(0, 6, int(rng.integers(0, 7)))]) for k in range(J)]
        C = sum(len(j.channels) for j in joints)
        T = int(rng.integers(1, 300)) if trial else 9000  # once more frames than a NumPy chunk
        values = np.where(rng.random((T, C)) < 0.3, rng.choice(special, (T, C)), rng.uniform(-400, 400, (T, C)))
        bvh = BvhFile(joints, "", 1 / 30, values)
        clips = {}
        for compiled in (True, False):
            monkeypatch.setattr(bvh_module, "USE_COMPILED", compiled)
            clips[compiled] = bvh_to_asset(bvh, Path("random.bvh")).clip()
        assert clips[True].translations.tobytes() == clips[False].translations.tobytes()
        assert_same_rotations(clips[True].rotations, clips[False].rotations, values)


def _bvh_sources(sample_assets):
    from conftest import SHARED_ASSETS

    return [sample_assets / "conversation_bodyonly.bvh", sample_assets / "humanoid.bvh"] + \
        sorted((SHARED_ASSETS / "leap_hands").glob("*.bvh"))


def _outcome(path: Path, compiled: bool | None, monkeypatch, fast: bool = True):
    """parse_bvh and the clip of ``path`` read with the compiled reader, the NumPy one, or the token reader."""
    with monkeypatch.context() as m:
        m.setattr(bvh_module, "USE_COMPILED", compiled)
        if not fast:
            m.setattr(bvh_module, "_parse_bvh_fast", lambda path: None)
        try:
            parsed = parse_bvh(path)
            clip = HANDLER.read(path).clip()
        except AssetReadError as e:
            return str(e)
    return ([(j.name, j.parent, j.offset.tobytes(), j.channels, j.end_site, j.line) for j in parsed.joints],
            parsed.hierarchy_text, parsed.frame_time, parsed.values.shape, parsed.values.tobytes(),
            clip.fps, clip.translations.tobytes(), clip.skeleton.joint_names), (parsed.values, clip.rotations)


def assert_same_outcome(a, b, what, exact: bool = False) -> None:
    """Two _outcome: the same error, or the same file read (rotations to the bit where ``exact``,
    else as assert_same_rotations says)."""
    if isinstance(a, str) or isinstance(b, str):
        assert a == b, what
        return
    assert a[0] == b[0], what
    (values, ours), (_, twin) = a[1], b[1]
    assert ours.shape == twin.shape, what
    if exact:
        assert ours.tobytes() == twin.tobytes(), what
    elif ours.size:
        assert_same_rotations(ours, twin, values)


def test_compiled_reader_equals_the_numpy_reader_on_real_files_and_variants(sample_assets, tmp_path, monkeypatch):
    """Every real BVH file and its variants (CRLF, CR, BOM, blank lines, tabs, the Leap rest line,
    broken ones): the compiled reader, the NumPy reader and the token reader give the same
    hierarchy, numbers to the bit and clip, or the same error."""
    from test_format_bvh import _bvh_variants

    checked, sources = 0, _bvh_sources(sample_assets)
    for src in sources:
        for name, text in _bvh_variants(src.read_text()):
            p = tmp_path / f"{src.stem}-{name.replace(' ', '_')}.bvh"
            p.write_bytes(text.encode("utf-8"))
            compiled = _outcome(p, True, monkeypatch)
            assert_same_outcome(compiled, _outcome(p, False, monkeypatch), (src.name, name))
            if AHEAD_OF_TIME is not None:  # the kernels compiled at install: numba's numbers to the bit
                assert_same_outcome(_outcome(p, None, monkeypatch), compiled, (src.name, name), exact=True)
            assert_same_outcome(_outcome(p, False, monkeypatch), _outcome(p, False, monkeypatch, fast=False),
                                (src.name, name), exact=True)
            checked += not isinstance(compiled, str)
    assert checked >= len(sources) * 7  # 7 variants of each file read (the others are refused alike)


def test_fast_paths_equal_the_token_reader_on_mutated_files(sample_assets, tmp_path, monkeypatch):
    """Random byte edits of real files (the fuzz harness's mutator): the line-by-line hierarchy,
    the compiled motion parser and the NumPy one read what the token reader reads, or the same error."""
    from fuzz_target import mutate

    rng = random.Random(12)
    sources = [src.read_bytes() for src in _bvh_sources(sample_assets)]
    head, motion = sources[0].split(b"MOTION\n")
    rows = motion.split(b"\n")[2:52]  # the long take: its hierarchy and 50 frames
    sources[0] = head + b"MOTION\nFrames: 50\nFrame Time: 0.0333333\n" + b"\n".join(rows) + b"\n"
    readable = 0
    for n in range(240):
        p = tmp_path / f"m{n}.bvh"
        data = rng.choice(sources)
        if n % 3 == 0:
            data = mutate(data, rng)
        else:  # a number of the motion replaced by another token: mostly readable
            numbers = [m.span() for m in re.compile(rb"\S+").finditer(data, data.index(b"Frame Time"))][3:]
            for _ in range(rng.randint(1, 3)):
                i, j = rng.choice(numbers)
                token = rng.choice([_random_token(rng)] * 6 + SPECIAL + NOT_READ).encode()
                data = data[:i] + token.ljust(j - i) + data[j:] if len(token) <= j - i else data
        p.write_bytes(data)
        slow = _outcome(p, False, monkeypatch, fast=False)
        assert_same_outcome(_outcome(p, True, monkeypatch), slow, p.read_bytes()[:300])
        if AHEAD_OF_TIME is not None:
            assert_same_outcome(_outcome(p, None, monkeypatch), _outcome(p, True, monkeypatch), p.read_bytes()[:300],
                                exact=True)
        assert_same_outcome(_outcome(p, False, monkeypatch), slow, p.read_bytes()[:300], exact=True)
        readable += not isinstance(slow, str)
    assert 50 < readable < 200  # both readable and broken files were tried


def test_hierarchy_one_statement_a_line_equals_the_token_parser(sample_assets):
    from conftest import SHARED_ASSETS  # noqa: F401  (the sources need it)

    for src in _bvh_sources(sample_assets):
        head = src.read_text().split("MOTION")[0].splitlines()
        fast = bvh_module._parse_hierarchy_fast(head)
        slow = bvh_module._parse_hierarchy(head, src)
        assert fast is not None
        assert [(j.name, j.parent, j.offset.tobytes(), j.channels, j.end_site, j.line) for j in fast] == \
               [(j.name, j.parent, j.offset.tobytes(), j.channels, j.end_site, j.line) for j in slow]
    # written otherwise: handed to the token parser
    for head in (["HIERARCHY", "ROOT A {", "OFFSET 0 0 0", "}"], ["HIERARCHY", "ROOT A", "{", "OFFSET 0 0", "0", "}"],
                 ["HIERARCHY", "ROOT A", "{", "OFFSET 0 0 0", "CHANNELS 2 Xrotation", "Yrotation", "}"],
                 ["HIERARCHY ROOT A", "{", "OFFSET 0 0 0", "}"], ["HIERARCHY", "ROOT A", "{", "OFFSET 0 0 0"],
                 ["HIERARCHY", "ROOT A", "{", "OFFSET 0 0 0", "}", "}"], ["HIERARCHY"]):
        assert bvh_module._parse_hierarchy_fast(head) is None, head


def test_when_the_process_reads_with_the_kernels(monkeypatch):
    """The kernels compiled ahead of time wherever they were built; without them, numba's not before
    numba runs a kernel of the package or enough motion text was read, then always; USE_COMPILED forces
    numba's or NumPy."""
    import usdhands.compiled
    import usdhands.jit

    built = usdhands.compiled.kernel_module("formats._bvh_compiled")
    if built is not None:
        assert bvh_module._kernels() is built
    monkeypatch.setattr(usdhands.compiled, "ENABLED", False)
    monkeypatch.setattr(usdhands.jit, "kernels_running", lambda: False)
    monkeypatch.setattr(bvh_module, "_motion_bytes_read", 0)
    assert bvh_module._kernels() is None
    monkeypatch.setattr(bvh_module, "_motion_bytes_read", bvh_module.COMPILED_AFTER_BYTES)
    assert bvh_module._kernels() is kernel
    monkeypatch.setattr(bvh_module, "_motion_bytes_read", 0)
    monkeypatch.setattr(usdhands.jit, "kernels_running", lambda: True)
    assert bvh_module._kernels() is kernel
    monkeypatch.setattr(bvh_module, "USE_COMPILED", False)
    assert bvh_module._kernels() is None
    monkeypatch.setattr(usdhands.jit, "kernels_running", lambda: False)
    monkeypatch.setattr(bvh_module, "USE_COMPILED", True)
    assert bvh_module._kernels() is kernel


@pytest.mark.parametrize("compiled", ["1", "0"])
def test_a_fresh_process_reads_a_bvh_file_without_numba(sample_assets, tmp_path, compiled):
    """Reading a file (start-up of every BVH command) imports no numba, with the kernels compiled ahead
    of time (which it reads with) or without them (NumPy); once a kernel of the package has run,
    jit.kernels_running() says so and, without the kernels compiled ahead of time, the reader uses numba's."""
    script = (
        "import sys\n"
        "from usdhands import jit\n"
        "import usdhands.formats.bvh as bvh\n"
        f"bvh.HANDLER.read({str(sample_assets / 'conversation_bodyonly.bvh')!r})\n"
        "from usdhands.compiled import kernel_module\n"
        "built = kernel_module('formats._bvh_compiled')\n"
        "print('numba' in sys.modules, jit.kernels_running(), bvh._kernels() is built)\n"
        "from usdhands.formats import _bvh_kernel as k\n"
        "import numpy as np\n"
        "k.parse_rows(np.frombuffer(b'1', np.uint8), 0, 1, np.empty((1, 1)), k.POW10)\n"
        "print(jit.kernels_running(), bvh._kernels() is (built or k), built is None)\n")
    env = dict(os.environ, USDHANDS_COMPILED_KERNELS=compiled)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[:5] == ["False", "False", "True", "True", "True"]
    if compiled == "0":
        assert out.stdout.split()[5] == "True"


@pytest.mark.parametrize("frames", ["1000000000000", "3"])
def test_frame_count_far_beyond_the_lines_allocates_nothing_big(tmp_path, monkeypatch, frames):
    """'Frames:' sizes nothing: the rows made room for are bounded by the bytes of the motion text."""
    monkeypatch.setattr(bvh_module, "USE_COMPILED", True)
    p = tmp_path / "f.bvh"
    p.write_text("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n}\n"
                 f"MOTION\nFrames: {frames}\nFrame Time: 0.04\n1 2 3\n4 5 6\n7 8 9\n")
    if frames == "3":
        assert parse_bvh(p).values.tolist() == [[1, 2, 3], [4, 5, 6], [7, 8, 9]]
    else:
        with pytest.raises(AssetReadError, match="'Frames: 1000000000000' .* but 3 frames of motion follow"):
            parse_bvh(p)


@pytest.mark.parametrize("first_bytes", [1, 13, 700, 4096])
def test_a_head_longer_than_the_first_read_is_read_whole(sample_assets, tmp_path, monkeypatch, first_bytes):
    """The head is read in growing pieces: cut anywhere (inside a UTF-8 character, a CRLF, the
    MOTION word, a header line) the file reads as when its head came in one piece."""
    from test_format_bvh import _bvh_variants

    src = sample_assets / "humanoid.bvh"
    text = src.read_text().replace("JOINT Spine", "JOINT Spiné", 1)
    for name, variant in _bvh_variants(text):
        p = tmp_path / f"{name.replace(' ', '_')}.bvh"
        p.write_bytes(variant.encode("utf-8"))
        for compiled in (True, False):
            whole = _outcome(p, compiled, monkeypatch)
            with monkeypatch.context() as m:
                m.setattr(bvh_module, "_HEAD_BYTES", first_bytes)
                assert_same_outcome(_outcome(p, compiled, monkeypatch), whole, (name, compiled), exact=True)
                if name in ("as is", "crlf", "bom"):
                    assert bvh_module._parse_bvh_fast(p) is not None, name  # read in pieces, not handed over

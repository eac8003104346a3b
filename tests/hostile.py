"""Building hostile inputs and checking the error promise on them.

The promise (issue 8): a bad input gives exactly one stderr line
``usdhands: error: FILE: ...``, exit status 2, no output and no temporary file left,
every input unchanged (sha256), and the run stays within a time and memory bound.

:func:`run_bounded` runs ``python -m usdhands ARGV`` in a subprocess under
``resource`` limits (address space, CPU seconds) and a wall-clock timeout, so a hang,
a runaway allocation or a crash of the interpreter (segfault) shows up as a failed
promise instead of taking the test run down. :func:`check_promise` runs it and
asserts everything the promise says.
"""

from __future__ import annotations

import hashlib
import json
import os
import resource
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: Bounds of one hostile run: address space (bytes), CPU seconds, wall-clock seconds.
MEMORY_LIMIT = 3 * 1024 ** 3
CPU_LIMIT = 60
WALL_LIMIT = 120


def sha(path: Path) -> str:
    """sha256 of a file's bytes (a symlink's target; a FIFO or device is named, not read)."""
    path = Path(path)
    if not path.is_file():
        return f"not a regular file: {path}"
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _limits(memory: int, cpu: int):
    def apply():
        resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    return apply


@dataclass
class Run:
    code: int
    stdout: str
    stderr: str

    @property
    def lines(self) -> list[str]:
        return self.stderr.rstrip("\n").split("\n") if self.stderr.strip() else []


def run_bounded(argv, *, cwd: Path | None = None, memory: int = MEMORY_LIMIT, cpu: int = CPU_LIMIT,
                wall: float = WALL_LIMIT, env: dict | None = None) -> Run:
    """Run ``python -m usdhands ARGV`` under resource limits; a timeout is exit code -9."""
    full_env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    full_env.update(env or {})
    proc = subprocess.Popen([sys.executable, "-m", "usdhands", *map(str, argv)], cwd=cwd, env=full_env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=_limits(memory, cpu), start_new_session=True)
    try:
        out, err = proc.communicate(timeout=wall)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        return Run(-9, out.decode(errors="replace"), "TIMEOUT\n" + err.decode(errors="replace"))
    return Run(proc.returncode, out.decode(errors="replace"), err.decode(errors="replace"))


def listing(folder: Path) -> list[str]:
    """Every entry under ``folder`` (recursive, relative, sorted)."""
    return sorted(str(p.relative_to(folder)) for p in Path(folder).rglob("*"))


def check_promise(argv, *, folder: Path, inputs, names: str | Path, message: str = "", **bounds) -> Run:
    """Run ``argv`` bounded and assert the one-line error promise.

    Parameters
    ----------
    folder : Path
        Where the inputs and outputs live: its listing must not change.
    inputs : iterable of Path
        Files whose bytes must not change.
    names : str or Path
        The file the error line must name (``usdhands: error: NAMES: ...``).
    message : str
        A piece of the error line (after the file name).
    """
    inputs = list(inputs)
    before = {p: sha(p) for p in inputs}
    listed = listing(folder)
    run = run_bounded(argv, **bounds)
    assert run.code == 2, (run.code, run.stderr[-3000:])
    assert len(run.lines) == 1, run.stderr[-3000:]
    line = run.lines[0]
    assert line.startswith(f"usdhands: error: {names}"), line
    assert message in line, line
    assert "Traceback" not in run.stderr
    assert listing(folder) == listed, "output or temporary file left behind"
    assert {p: sha(p) for p in inputs} == before, "an input changed"
    return run


def deep_json(depth: int, inner: str = "0") -> str:
    """``[[[...0...]]]`` nested ``depth`` deep."""
    return "[" * depth + inner + "]" * depth


def gltf_json(path: Path) -> dict:
    """The JSON of a .gltf, or of a .glb's JSON chunk."""
    raw = Path(path).read_bytes()
    if raw[:4] == b"glTF":
        n = int.from_bytes(raw[12:16], "little")
        return json.loads(raw[20:20 + n])
    return json.loads(raw)


def run_batch(cases: list[list], *, memory: int = MEMORY_LIMIT, cpu: int = 300, wall: float = 900) -> list[dict]:
    """Run many command lines in one bounded subprocess (tests/hostile_worker.py); one result dict each.

    A crash or a hang of the whole batch fails here, naming the batch's output.
    """
    full_env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    worker = Path(__file__).resolve().parent / "hostile_worker.py"
    proc = subprocess.Popen([sys.executable, str(worker)], env=full_env, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=_limits(memory, cpu),
                            start_new_session=True)
    try:
        out, err = proc.communicate(json.dumps([[str(a) for a in argv] for argv in cases]).encode(), timeout=wall)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise AssertionError(f"hostile batch did not finish in {wall} s") from None
    assert proc.returncode == 0, (proc.returncode, err.decode(errors="replace")[-3000:])
    return json.loads(out)


def glb_bytes(doc: dict | str, binary: bytes = b"") -> bytes:
    """A GLB file from a JSON document (or its text) and an optional binary chunk."""
    import struct

    j = (doc if isinstance(doc, str) else json.dumps(doc)).encode()
    j += b" " * (-len(j) % 4)
    chunks = struct.pack("<II", len(j), 0x4E4F534A) + j
    if binary:
        binary += b"\0" * (-len(binary) % 4)
        chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


def crate_seed(samples: Path, folder: Path) -> bytes:
    """The sample humanoid (skeleton, animation, skinned mesh) as .usdc, with a custom-data dictionary."""
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(str(samples / "humanoid.usda"))
    copy = Sdf.Layer.CreateAnonymous(".usda")
    copy.TransferContent(layer)
    copy.customLayerData = {"pipeline": {"step": "mocap", "take": 3}}
    path = Path(folder) / "crate_seed.usdc"
    copy.Export(str(path))
    data = path.read_bytes()
    path.unlink()
    return data


def crate_lies(good: bytes) -> dict[str, tuple[bytes, str]]:
    """Crafted .usdc files from a good one (:func:`crate_seed`), each lying about one count or index USD trusts.

    Returns class -> (bytes, piece of the expected error line). Each class is one the
    usdc fuzzer found (or its sibling): without the check in usdhands/formats/usdc_crate.py
    USD allocated gigabytes, printed ``posix_madvise`` lines on stderr, or crashed.
    """
    import struct

    import numpy as np

    from usdhands.formats.usdc_crate import _Crate

    crate = _Crate(good)
    crate.table_of_contents()
    reps = np.frombuffer(crate.structural(), dtype="<u8").tolist()
    toc = struct.unpack_from("<q", good, 16)[0]
    out: dict[str, tuple[bytes, str]] = {}

    def edit(fmt: str, at: int, value) -> bytes:
        data = bytearray(good)
        struct.pack_into(fmt, data, at, value)
        return bytes(data)

    def first(kind: int, *, array: bool = False) -> int:
        """Payload offset of the first out-of-line value of ``kind``."""
        return next(r & ((1 << 48) - 1) for r in reps
                    if (r >> 48) & 0xFF == kind and not r & (1 << 62) and bool(r & (1 << 63)) == array
                    and r & ((1 << 48) - 1))

    # 117,178,119 sections in a 20 KB file: USD reserved 3.7 GB for the table of contents
    out["toc_sections"] = (edit("<Q", toc, 117_178_119), "table of contents claims 117178119 entries")
    # a section past the end: USD printed 'failed call to posix_madvise' (prefetch), then read on
    names = [good[toc + 8 + 32 * k:toc + 24 + 32 * k].split(b"\0")[0] for k in range(6)]
    specs = names.index(b"SPECS")
    out["section_past_end"] = (edit("<q", toc + 8 + 32 * specs + 24, 10 ** 9), "section 'SPECS' claims bytes")
    # a token vector (apiSchemas and the like) of 513 entries: indices past the token table, a segfault
    out["token_index"] = (edit("<Q", first(41), 513), "names token")
    # a small array claiming 2^40 entries: USD resizes before it reads
    out["array_count"] = (edit("<Q", first(11, array=True), 1 << 40), "an array claims 1099511627776 entries")
    # the token count: USD sizes the token table from it
    tokens = names.index(b"TOKENS")
    start = struct.unpack_from("<q", good, toc + 8 + 32 * tokens + 16)[0]
    out["token_count"] = (edit("<Q", start, 1 << 40), "TOKENS claims 1099511627776 tokens")
    # the root's primChildren naming a prim it does not have: USD aborted ('Dereferenced an invalid SdfPrimSpec')
    start, end = crate.sections["TOKENS"]
    raw, packed = struct.unpack_from("<QQ", good, start + 8)
    tokens = crate.decompress(start + 24, packed, raw, "TOKENS", end).split(b"\0")
    out["child_without_spec"] = (edit("<I", first(41) + 8, tokens.index(b"Humanoid")),
                                 "primChildren of </> lists </Humanoid>, which has no spec")
    # a prim spec retyped as a Mapper: USD aborted the interpreter ('Dereferenced an invalid SdfPrimSpec')
    out["spec_type"] = (respec(good, crate, toc, names), "SPECS: a spec of type 4 on a prim path")
    # a dictionary value whose offset points backwards: USD prefetched (posix_madvise) a negative length
    dictionary = first(31)
    out["value_offset"] = (edit("<q", dictionary + 12, -(10 ** 6)), "value offset -1000000 points backwards")
    return out


def _lz4_literals(data: bytes) -> bytes:
    """One LZ4 block holding ``data`` as literals (valid, uncompressed), framed as USD's TfFastCompression."""
    n = len(data)
    head = bytes([0xF0]) + b"\xff" * ((n - 15) // 255) + bytes([(n - 15) % 255]) if n >= 15 else bytes([n << 4])
    return b"\0" + head + data


def _encode_ints(values) -> bytes:
    """Sdf's integer coding with every delta stored in 32 bits (common delta 0), LZ4-framed, size first."""
    import struct

    import numpy as np

    deltas = np.diff(np.asarray(values, dtype=np.int64), prepend=0).astype("<i4")
    codes = bytes([0xFF]) * ((2 * len(deltas) + 7) // 8)
    body = _lz4_literals(struct.pack("<i", 0) + codes + deltas.tobytes())
    return struct.pack("<Q", len(body)) + body


def respec(good: bytes, crate, toc: int, names: list, retype: bool = True) -> bytes:
    """``good`` with its SPECS section rewritten (appended, the table of contents pointed at it):
    the first prim spec (type 6) made a Mapper (type 4), or (``retype=False``) left as it was."""
    import struct

    from usdhands.formats.usdc_crate import decode_ints

    k = names.index(b"SPECS")
    start, end = crate.sections["SPECS"]
    n = struct.unpack_from("<Q", good, start)[0]
    arrays, at = [], start + 8
    for _ in range(3):
        size = struct.unpack_from("<Q", good, at)[0]
        raw = crate.decompress(at + 8, size, 4 + (2 * n + 7) // 8 + 4 * n, "SPECS", end)
        arrays.append(decode_ints(raw, n).tolist())
        at += 8 + size
    if retype:
        arrays[2][arrays[2].index(6)] = 4
    section = struct.pack("<Q", n) + b"".join(_encode_ints(a) for a in arrays)
    data = bytearray(good)
    struct.pack_into("<qq", data, toc + 8 + 32 * k + 16, len(good), len(section))
    return bytes(data) + section

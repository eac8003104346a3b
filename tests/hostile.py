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

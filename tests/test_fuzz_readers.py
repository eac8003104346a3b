"""A short fuzz run of every reader (tests/fuzz/run.py, seeded random engine, a few seconds each).

The long runs (``python tests/fuzz/run.py READER --seconds 600``, atheris when installed)
go the same way; every finding of theirs became a case in tests/test_hostile_findings.py.
Each reader runs in a subprocess under resource limits, so a crash of the interpreter or
a runaway allocation fails the test instead of the test run.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

from hostile import ROOT, _limits  # noqa: E402  (tests/ is on sys.path)

RUNNER = Path(__file__).resolve().parent / "fuzz" / "run.py"
sys.path.insert(0, str(RUNNER.parent))
from fuzz_target import READERS  # noqa: E402
SECONDS = 4


@pytest.mark.parametrize("reader", sorted(READERS))
def test_short_fuzz_run_finds_nothing(reader, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, str(RUNNER), reader, "--seconds", str(SECONDS), "--engine", "random",
                          "--seed", "1", "--crashes", str(tmp_path / "crashes")], env=env, capture_output=True,
                         text=True, timeout=300, preexec_fn=_limits(3 * 1024 ** 3, 240))
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    report = ast.literal_eval(out.stdout.strip().splitlines()[-1])
    assert report["runs"] > 0
    assert report["findings"] == []
    assert not (tmp_path / "crashes").exists()


def test_the_target_reports_what_breaks_the_promise():
    """The check itself: a traceback-raising reader is a finding, a UsdHandsError is not."""
    from fuzz_target import Target

    target = Target("bvh")
    assert target.check(b"HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\n}\n") is None  # no MOTION: a one-line error
    target._read = lambda path: (_ for _ in ()).throw(RecursionError())
    assert target.check(b"x") == "RecursionError"

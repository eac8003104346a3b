"""A ``usdhands`` process runs OpenBLAS on one thread unless its caller chose a thread count
(cli.one_blas_thread_by_default): the extra threads spun on usdhands' small products, a quarter to
a third of a fresh command's CPU, for the same output."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

PROBE = """
import os, sys
from usdhands import cli
numpy_before = "numpy" in sys.modules
set_here = cli.one_blas_thread_by_default()
import numpy as np
a = np.ones((600, 600))
a @ a  # large enough for OpenBLAS to use every thread it has
tasks = len(os.listdir("/proc/self/task")) if os.path.isdir("/proc/self/task") else -1
print(numpy_before, set_here, os.environ.get("OPENBLAS_NUM_THREADS"), tasks)
"""


def _probe(**env_changes) -> list[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS",
                                                             "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    env.update(env_changes)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True)
    return out.stdout.split()


def test_one_thread_when_the_caller_chose_none():
    numpy_before, set_here, value, tasks = _probe()
    assert (numpy_before, set_here, value) == ("False", "True", "1")
    if tasks != "-1":
        assert tasks == "1"  # no OpenBLAS thread beside the main one


@pytest.mark.skipif((os.cpu_count() or 1) < 2 or not os.path.isdir("/proc/self/task"), reason="needs 2 cores and /proc")
def test_the_callers_thread_count_is_kept():
    numpy_before, set_here, value, tasks = _probe(OMP_NUM_THREADS="2")
    assert (set_here, value) == ("False", "None")
    assert int(tasks) >= 2  # OpenBLAS's threads as the caller asked
    _, set_here, value, _ = _probe(OPENBLAS_NUM_THREADS="2")
    assert (set_here, value) == ("False", "2")


def test_the_command_sets_it_before_numpy_loads(tmp_path):
    code = ("import os, sys; sys.argv = ['usdhands', '--version']\n"
            "from usdhands import cli\n"
            "try:\n    cli.entry_point()\n"
            "finally:\n    import numpy as np\n    a = np.ones((600, 600))\n    a @ a\n"
            "    tasks = len(os.listdir('/proc/self/task')) if os.path.isdir('/proc/self/task') else 1\n"
            "    print(os.environ.get('OPENBLAS_NUM_THREADS'), tasks)\n")
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[-2:] == ["1", "1"]  # set, and OpenBLAS (loaded by the command) has no thread of its own

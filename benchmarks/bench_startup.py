"""Fresh-process start-up: what a user waits for before any work is done.

Run: ``python benchmarks/bench_startup.py [--repeat N]``

Each row is the median wall time of ``N`` fresh Python processes, measured in the same
run as the baseline ``python -c "import numpy"`` (these machines are shared and noisy:
read the ratios):

- ``usdhands --help``;
- ``import usdhands``;
- ``usdhands synthesize`` of the bundled body-only conversation in each format (BVH,
  glTF, USD), with the bundled database, into a temporary folder;
- ``usdhands correct`` of the ``cup_grasp`` sample against its cup and table, and
  ``usdhands synthesize --props`` of its body-only version (what a fresh process pays for
  the props: trimesh, libigl, the correction).

Each row gives the median wall time and the median CPU time (user + system of the
child process) with their ratios to the baseline's: on a machine other processes keep
busy the wall times stretch, the CPU times much less.

Every row is run once before timing (not timed): the bytecode is cached (the runs
write it even where ``PYTHONDONTWRITEBYTECODE`` is set, as an installed package has
it) and so are the kernels, so these are the times of every run after the first. The processes run with the checkout this
file belongs to first on ``PYTHONPATH``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "sample_assets" / "conversation_bodyonly"


def run_times(cmd: list[str], repeat: int, env: dict) -> list[tuple[float, float]]:
    """Wall seconds and CPU seconds (user + system, of the child) of ``repeat`` fresh runs of ``cmd``.

    Raises if one fails.
    """
    times = []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        done = subprocess.run(cmd, env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        times.append((wall, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime))
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}): {done.stderr.decode()[-500:]}")
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=7, help="fresh processes per row (median reported)")
    args = ap.parse_args()

    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # an installed package has its bytecode cached: so do these runs
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    py = sys.executable
    usdhands = [py, "-m", "usdhands"]
    with tempfile.TemporaryDirectory() as tmp:
        rows = {
            "python -c 'import numpy'": [py, "-c", "import numpy"],
            "usdhands --help": usdhands + ["--help"],
            "python -c 'import usdhands'": [py, "-c", "import usdhands"],
        }
        for ext in ("bvh", "glb", "usdc"):
            rows[f"usdhands synthesize conversation .{ext}"] = usdhands + [
                "synthesize", str(SAMPLE.with_suffix(f".{ext}")), "-o", str(Path(tmp) / f"out.{ext}")]
        inter = ROOT / "sample_assets" / "interaction"
        props = ROOT / "sample_assets" / "props"
        rows["usdhands correct cup_grasp .glb"] = usdhands + [
            "correct", str(inter / "cup_grasp.glb"), "--props", str(props / "cup_on_table.obj"), str(props / "table.obj"),
            "--attach", "cup_on_table=RightHand:48-102", "-o", str(Path(tmp) / "cup_fixed.glb")]
        rows["usdhands synthesize --props cup_grasp .glb"] = usdhands + [
            "synthesize", str(inter / "cup_grasp_bodyonly.glb"), "--props", str(props / "cup_on_table.obj"),
            str(props / "table.obj"), "--attach", "cup_on_table=RightHand:48-102", "-o", str(Path(tmp) / "cup_synth.glb")]
        # warm the bytecode and the kernel cache (a first run compiles), not timed
        for cmd in rows.values():
            run_times(cmd, 1, env)
        # interleave the rows so a slow spell of the machine hits every row alike
        samples: dict[str, list[tuple[float, float]]] = {k: [] for k in rows}
        for _ in range(args.repeat):
            for name, cmd in rows.items():
                samples[name] += run_times(cmd, 1, env)

    base = samples["python -c 'import numpy'"]
    base_wall = statistics.median(w for w, _ in base)
    base_cpu = statistics.median(c for _, c in base)
    print(f"fresh processes, median of {args.repeat} (python {sys.version.split()[0]}, {os.cpu_count()} cpus, "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())})")
    print(f"{'command':<44} {'wall s':>7} {'min s':>7} {'x numpy':>8} {'CPU s':>7} {'x numpy':>8}")
    for name, ts in samples.items():
        wall = statistics.median(w for w, _ in ts)
        cpu = statistics.median(c for _, c in ts)
        print(f"{name:<44} {wall:7.3f} {min(w for w, _ in ts):7.3f} {wall / base_wall:8.2f} {cpu:7.3f} "
              f"{cpu / base_cpu:8.2f}")
    print("targets: import usdhands < 0.2 s, synthesize < 1 s (warm kernel cache); on a loaded machine the wall "
          "times stretch, the CPU times (user + system of the process) much less")


if __name__ == "__main__":
    main()

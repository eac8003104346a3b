"""Fresh-process start-up: what a user waits for before any work is done.

Run: ``python benchmarks/bench_startup.py [--repeat N]``

Each row is the median wall time of ``N`` fresh Python processes, measured in the same
run as the baseline ``python -c "import numpy"`` (these machines are shared and noisy:
read the ratios):

- ``usdhands --help``;
- ``import usdhands``;
- ``usdhands synthesize`` of the bundled body-only conversation in each format (BVH,
  glTF, USD), with the bundled database, into a temporary folder.

The kernel cache is warmed once before timing (one synthesize run, not timed): these
are the times of every run after the first. The processes run with the checkout this
file belongs to first on ``PYTHONPATH``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "sample_assets" / "conversation_bodyonly"


def wall_times(cmd: list[str], repeat: int, env: dict) -> list[float]:
    """Wall seconds of ``repeat`` fresh runs of ``cmd``; raises if one fails."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        done = subprocess.run(cmd, env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        times.append(time.perf_counter() - t0)
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}): {done.stderr.decode()[-500:]}")
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=7, help="fresh processes per row (median reported)")
    args = ap.parse_args()

    env = dict(os.environ)
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
        # warm the kernel cache (first run compiles), not timed
        wall_times(rows["usdhands synthesize conversation .bvh"], 1, env)
        # interleave the rows so a slow spell of the machine hits every row alike
        samples: dict[str, list[float]] = {k: [] for k in rows}
        for _ in range(args.repeat):
            for name, cmd in rows.items():
                samples[name] += wall_times(cmd, 1, env)

    base = statistics.median(samples["python -c 'import numpy'"])
    print(f"fresh processes, median of {args.repeat} (python {sys.version.split()[0]}, {os.cpu_count()} cpus)")
    print(f"{'command':<44} {'median s':>9} {'min s':>7} {'x numpy':>8}")
    for name, ts in samples.items():
        med = statistics.median(ts)
        print(f"{name:<44} {med:9.3f} {min(ts):7.3f} {med / base:8.2f}")
    print("targets: import usdhands < 0.2 s, synthesize < 1 s (warm kernel cache)")


if __name__ == "__main__":
    main()

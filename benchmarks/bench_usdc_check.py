"""Cost of checking a .usdc's claims before USD opens it (usdhands/formats/usdc_crate.py).

Run: ``python benchmarks/bench_usdc_check.py [--repeat N]``

Prints, for the bundled ``conversation_bodyonly.usdc`` (1.6 MB, 1,800 arrays) and for
the sample humanoid as .usdc, the best CPU time of ``check_crate`` alone, of
``read_asset`` (which now includes it), and of opening the stage with USD alone
(``Usd.Stage.Open`` and traversal, no check), all measured in this run; the ratio
check / read is what the check adds to a read. The alternative the issue weighed,
opening each file in a subprocess under a memory limit, costs a fresh Python with
``pxr`` imported (printed as the last row, also measured here).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def best_cpu(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def open_bare(path: Path) -> int:
    """USD alone: open the stage and walk its prims (what read_asset starts with)."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    return sum(1 for _ in stage.Traverse())


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args(argv)
    from pxr import Sdf

    from usdhands.formats.io import read_asset
    from usdhands.formats.usdc_crate import check_crate

    folder = Path(tempfile.mkdtemp(prefix="bench_usdc_"))
    humanoid = folder / "humanoid.usdc"
    Sdf.Layer.FindOrOpen(str(ROOT / "sample_assets" / "humanoid.usda")).Export(str(humanoid))
    print(f"load average {os.getloadavg()[0]:.2f}; best CPU time of {args.repeat} runs")
    print(f"{'file':32s} {'check ms':>9s} {'read_asset ms':>14s} {'USD open ms':>12s} {'check/read':>11s}")
    for path in (ROOT / "sample_assets" / "conversation_bodyonly.usdc", humanoid):
        read_asset(path)  # warm caches (imports, schema registry)
        check = best_cpu(lambda: check_crate(path), args.repeat)
        read = best_cpu(lambda: read_asset(path), args.repeat)
        bare = best_cpu(lambda: open_bare(path), args.repeat)
        print(f"{path.name:32s} {check * 1e3:9.2f} {read * 1e3:14.1f} {bare * 1e3:12.1f} {check / read:11.1%}")
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "from pxr import Usd"], check=True)
    print(f"a subprocess importing pxr (the rejected alternative): {(time.perf_counter() - t0) * 1e3:.0f} ms wall")


if __name__ == "__main__":
    main()

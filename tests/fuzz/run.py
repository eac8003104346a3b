"""Fuzz one reader of usdhands: ``python tests/fuzz/run.py bvh --seconds 600``.

Readers: ``bvh`` (``--bvh-reader compiled`` reads with the numba kernels a process
running numba uses), ``gltf``, ``glb``, ``usda``, ``usdc``, ``usdz`` (a package whose root
is a crate, or a text layer sublayering a crate member: the crate check slices each member
out of the package; the file readers behind every command) and the side files: ``handmap``, ``config`` (synthesis configuration),
``interaction`` (interaction configuration), ``model`` (reduction model), ``manifest``
(a finger database's manifest, over the bundled database's arrays), ``markers`` (splice's
marker CSV) and ``labels`` (the labels CSV). Each starts from seeds generated from the
committed samples (see :mod:`fuzz_target`) and feeds mutated bytes to ``read_asset``
(or the side file's loader). The promise is the one of the command line: a
:class:`~usdhands.errors.UsdHandsError` or a clean read; any other exception, a crash
of the interpreter or a read over the time/memory bound is a finding.

Engines: ``atheris`` (libFuzzer, coverage guided; used when installed) or ``random``
(a seeded byte mutator of our own, the one the short CI run inside pytest uses).
Findings are written to ``--crashes`` (default ``tests/fuzz/crashes/``, not
committed): each one then becomes a case built by code in tests/test_hostile_findings.py
and gets fixed.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from fuzz_target import READERS, Target, mutate, seeds  # noqa: E402


def run_random(target: Target, seconds: float, seed: int, crashes: Path) -> dict:
    """Mutate the seeds at random for ``seconds``; returns counts and the findings."""
    import random

    rng = random.Random(seed)
    pool = seeds(target.reader)
    start = time.monotonic()
    runs = 0
    findings = []
    while time.monotonic() - start < seconds:
        data = mutate(rng.choice(pool), rng)
        problem = target.check(data)
        runs += 1
        if problem is not None:
            findings.append(target.save(data, problem, crashes))
    return {"reader": target.reader, "engine": "random", "runs": runs, "seconds": round(time.monotonic() - start, 1),
            "findings": findings}


def _choose_bvh_reader(choice: str) -> None:
    """``compiled``: BVH files read with the numba kernels (as in a process where numba runs);
    ``numpy``: without; ``auto``: as the reader decides (a fuzzing process: NumPy)."""
    import usdhands.formats.bvh as bvh

    bvh.USE_COMPILED = {"auto": None, "compiled": True, "numpy": False}[choice]


def run_atheris(target: Target, seconds: float, crashes: Path, bvh_reader: str = "auto") -> None:
    """Coverage-guided run with libFuzzer for ``seconds``; libFuzzer prints its own report and exits."""
    import atheris

    with atheris.instrument_imports(include=["usdhands"]):  # coverage of our Python code guides libFuzzer
        import usdhands.formats.bvh  # noqa: F401
        import usdhands.formats.gltf  # noqa: F401
        import usdhands.formats.io  # noqa: F401
        import usdhands.formats.usd  # noqa: F401
        import usdhands.model.hand_detection  # noqa: F401
        import usdhands.algorithms.synthesis.config  # noqa: F401
        import usdhands.algorithms.synthesis.database  # noqa: F401
        import usdhands.algorithms.reduction.model  # noqa: F401
        import usdhands.algorithms.interaction.finger_geometry  # noqa: F401
        import usdhands.jobs.inputs  # noqa: F401
        import usdhands.jobs.splicing  # noqa: F401
        import usdhands.input_files  # noqa: F401
    _choose_bvh_reader(bvh_reader)  # after the instrumented imports
    corpus = Path(tempfile.mkdtemp(prefix=f"usdhands_fuzz_{target.reader}_"))
    for k, data in enumerate(seeds(target.reader)):
        (corpus / f"seed{k}").write_bytes(data)
    crashes.mkdir(parents=True, exist_ok=True)

    def one(data: bytes) -> None:
        problem = target.check(data)
        if problem is not None:  # recorded, and the run goes on (libFuzzer would stop at the first)
            record = target.save(data, problem, crashes)
            print(f"FINDING {record['file']}: {problem}", file=sys.stderr, flush=True)

    atheris.Setup([sys.argv[0], f"-max_total_time={int(seconds)}", "-timeout=20", "-rss_limit_mb=3072",
                   f"-artifact_prefix={crashes}/{target.reader}-", str(corpus)], one)
    atheris.Fuzz()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("reader", choices=sorted(READERS))
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--engine", choices=("atheris", "random"), default=None,
                        help="default: atheris when installed, else random")
    parser.add_argument("--seed", type=int, default=0, help="random engine's seed")
    parser.add_argument("--crashes", type=Path, default=Path(__file__).resolve().parent / "crashes")
    parser.add_argument("--bvh-reader", choices=("auto", "compiled", "numpy"), default="auto",
                        help="BVH files read with the numba kernels, without, or as the reader decides (default)")
    args = parser.parse_args(argv)
    engine = args.engine
    if engine is None:
        try:
            import atheris  # noqa: F401
            engine = "atheris"
        except ImportError:
            engine = "random"
    target = Target(args.reader, timer=engine == "random")
    if engine == "atheris":
        run_atheris(target, args.seconds, args.crashes, args.bvh_reader)
        return 0
    _choose_bvh_reader(args.bvh_reader)
    report = run_random(target, args.seconds, args.seed, args.crashes)
    print(report)
    return 1 if report["findings"] else 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    sys.exit(main())

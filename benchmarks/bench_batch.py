"""Benchmark: ``usdhands batch --job synthesize`` over many short generated clips.

Generates N short clips (gesture takes of the sample generator, 2-3 s each, written as
BVH), then measures clips per second of:

- ``batch`` on the local process pool with 1 and 2 workers;
- ``batch`` on a local Dask cluster (``--scheduler local``) with 1 and 2 workers;
- ``batch`` sent to a Dask cluster that is already running (``dask scheduler`` and ``dask
  worker --nworkers N --nthreads 1`` started before, as a farm's are: ``--scheduler
  tcp://...``) with 1 and 2 workers;
- the baseline: one ``usdhands synthesize`` process per clip, run one after the other on
  the first ``--baseline`` clips (each pays the interpreter start-up and the database load).

Every batch run starts from an empty output folder; the pool or LocalCluster start-up is
included in its time (the running cluster's is not: that is the difference between them). Prints the rates and the ratios 2 workers / 1 worker and batch /
process-per-clip (targets: >= 1.7 and >= 5). The machine's load average is printed
beside them: other processes on a shared machine slow the 2-worker runs most.

Run: ``python benchmarks/bench_batch.py [--clips 200] [--baseline 20]``
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def make_clips(folder: Path, count: int) -> list[Path]:
    from usdhands.formats.io import write_asset
    from usdhands.model.asset import Asset
    from usdhands.samples.gestures import gesture_database

    folder.mkdir(parents=True, exist_ok=True)
    out, seed = [], 100
    while len(out) < count:
        for label, clip in gesture_database(seed=seed, takes=2):
            if len(out) == count:
                break
            path = folder / f"{label}_{seed}_{len(out):03d}.bvh"
            write_asset(Asset("generated", (clip.skeleton,), (clip,), ()), path)
            out.append(path)
        seed += 1
    return out


def run_batch_cli(inputs: Path, out: Path, workers: int, scheduler: str | None) -> float:
    """Seconds of one ``usdhands batch`` process (start-up included); checks every clip was done."""
    import json

    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", "usdhands", "batch", str(inputs), "--job", "synthesize", "--out", str(out),
           "--workers", str(workers)]
    if scheduler:
        cmd += ["--scheduler", scheduler]
    start = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    report = json.loads((out / "report.json").read_text())
    assert report["failed"] == 0 and report["done"] == len(report["clips"]), report
    return seconds


@contextlib.contextmanager
def running_dask_cluster(workers: int, folder: Path):
    """A ``dask scheduler`` and ``dask worker`` processes (``workers`` of 1 thread) on a free local
    port, started and waited for before the timing: the address."""
    import socket

    from distributed import Client

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "dask.log", "w") as log:
        procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port",
                                   str(port), "--no-dashboard"], stdout=log, stderr=log, cwd=folder)]
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", address, "--nworkers", str(workers),
                                       "--nthreads", "1", "--no-dashboard", "--local-directory", str(folder)],
                                      stdout=log, stderr=log, cwd=folder))
        try:
            with Client(address, timeout="60s") as client:
                client.wait_for_workers(workers, timeout=180)
            yield address
        finally:
            for p in reversed(procs):
                p.terminate()
                p.wait(timeout=60)


def process_per_clip(clips: list[Path], out: Path) -> float:
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    for c in clips:
        subprocess.run([sys.executable, "-m", "usdhands", "synthesize", str(c), "-o", str(out / c.name)],
                       check=True, capture_output=True)
    return time.perf_counter() - start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", type=int, default=200)
    ap.add_argument("--baseline", type=int, default=20, help="clips run as one process each (the baseline)")
    ap.add_argument("--no-dask", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        clips = make_clips(tmp / "in", args.clips)
        print(f"{len(clips)} clips generated in {time.perf_counter() - t0:.1f} s; {os.cpu_count()} CPUs; "
              f"load average {os.getloadavg()[0]:.1f}")
        rates = {}
        runs = [("local pool", None)] + ([] if args.no_dask else [("Dask LocalCluster", "local"),
                                                                  ("Dask cluster running", "running")])
        for name, scheduler in runs:
            for workers in (1, 2):
                load = os.getloadavg()[0]
                if scheduler == "running":
                    with running_dask_cluster(workers, tmp / f"dask{workers}") as address:
                        load = os.getloadavg()[0]
                        seconds = run_batch_cli(tmp / "in", tmp / "out", workers, address)
                else:
                    seconds = run_batch_cli(tmp / "in", tmp / "out", workers, scheduler)
                rates[(name, workers)] = len(clips) / seconds
                print(f"{name:18s} {workers} worker(s): {seconds:7.1f} s, {rates[(name, workers)]:6.2f} clips/s "
                      f"(load average before {load:.1f})")
        base = clips[:args.baseline]
        load = os.getloadavg()[0]
        seconds = process_per_clip(base, tmp / "single")
        baseline = len(base) / seconds
        print(f"one process per clip ({len(base)} clips): {seconds:7.1f} s, {baseline:6.2f} clips/s "
              f"(load average before {load:.1f})")
        for name, _ in runs:
            one, two = rates[(name, 1)], rates[(name, 2)]
            print(f"{name}: 2 workers / 1 worker = {two / one:.2f}x (target 1.7x); "
                  f"batch 1 worker / process per clip = {one / baseline:.1f}x, "
                  f"2 workers = {two / baseline:.1f}x (target 5x)")


if __name__ == "__main__":
    main()

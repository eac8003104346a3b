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
included in its time (the running cluster's is not: that is the difference between them).
Each engine runs ``--rounds`` times with 1 and with 2 workers, taking turns; its rates are
the clips over the median seconds. Prints the rates and the ratios 2 workers / 1 worker (of
the medians, and the range of the rounds' own ratios) and batch / process-per-clip (targets:
>= 1.7 and >= 5). The machine's load average is printed beside them: other processes on a
shared machine slow the 2-worker runs most.

CPU accounting (what a loaded machine distorts least): between the 10% and the 90% progress
lines of each run, the CPU time of every thread of every process involved -- the batch
process (for a LocalCluster: client, scheduler and nannies; sampled per thread), each worker
process (its busiest thread, which runs the clips, and its other threads: event loop,
monitors), the running cluster's scheduler and nanny processes -- per clip. The clips' own
work is the workers' busiest threads; everything else is the overhead that 2 workers on 2
cores take from the clips. Two workers can reach at most ``2 / (1 + overhead / clip work)``
the rate of one worker whose overhead runs on the other core: the line "bound" prints it.
The running cluster is started with the settings ``batch`` gives its own LocalCluster
(``usdhands.jobs.batch.QUIET_LOCAL_CLUSTER``, as environment variables of those processes only),
and its workers' malloc trim threshold at 1 GiB instead of Dask's 64 KiB (a Dask config file of
those processes), as docs/pipeline.md advises for a farm.

The CPU of a LocalCluster's whole run (every process batch starts, start-up and close included)
is sampled every 50 ms in one more run of each worker count, not timed: each sample (a walk of the
process tree) costs ~0.8 ms of CPU, ~1.6% of a core that two workers on two cores would lose.

Run: ``python benchmarks/bench_batch.py [--clips 200] [--baseline 20] [--rounds 3]``
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import subprocess
import sys
import statistics
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


def run_batch_cli(inputs: Path, out: Path, workers: int, scheduler: str | None,
                  cluster_pids: tuple[int, ...] = (), sample: bool = False) -> tuple[float, dict]:
    """Seconds of one ``usdhands batch`` process (start-up included) and its CPU accounting
    (:func:`cpu_by_role`, between the 10% and 90% progress lines); checks every clip was done.
    ``sample``: also the CPU of the whole run, sampled every 50 ms (:class:`ProcessTreeCpu`), whose
    walks of the process tree take CPU from the run: its seconds are not timings."""
    import json

    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", "usdhands", "batch", str(inputs), "--job", "synthesize", "--out", str(out),
           "--workers", str(workers)]
    if scheduler:
        cmd += ["--scheduler", scheduler]
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    sampler = ProcessTreeCpu(proc.pid) if sample else None
    marks, lines = [], []
    for line in proc.stderr:  # "synthesize: 20/200 done, 0 failed, ..." at each tenth (stderr is not a terminal)
        lines.append(line)
        done = line.split(":", 1)[-1].split(" done", 1)[0].strip().split("/")
        if len(done) == 2 and done[0].isdigit() and done[1].isdigit():
            finished, total = int(done[0]), int(done[1])
            if (not marks and finished >= total // 10) or (len(marks) == 1 and finished >= total - total // 10):
                marks.append((finished, time.perf_counter(), thread_cpu([proc.pid, *cluster_pids])))
    _, status, _ = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"batch failed ({proc.returncode}): {''.join(lines[-20:])}")
    seconds = time.perf_counter() - start
    report = json.loads((out / "report.json").read_text())
    assert report["failed"] == 0 and report["done"] == len(report["clips"]), report
    (n0, t0, a), (n1, t1, b) = marks
    acc = cpu_by_role(a, b, n1 - n0, t1 - t0, proc.pid)
    if sampler is not None:  # the LocalCluster's processes are all the batch process's descendants
        acc["whole run cpu"] = sampler.stop()
    return seconds, acc


class ProcessTreeCpu:
    """The CPU seconds (user + system) of a process and all its descendants, sampled every 50 ms in a
    thread until :meth:`stop`: each process's last reading (a process's last <= 50 ms are missed). The
    batch's own wait4 figures cannot give it: a LocalCluster's workers fork from the warm forkserver,
    whose children the batch process never waits for."""

    def __init__(self, pid: int):
        import threading

        self.pid, self.seen, self.done = pid, {}, threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        import psutil

        while not self.done.is_set():
            with contextlib.suppress(psutil.Error):
                root = psutil.Process(self.pid)
                for p in (root, *root.children(recursive=True)):
                    with contextlib.suppress(psutil.Error):
                        t = p.cpu_times()
                        self.seen[(p.pid, p.create_time())] = t.user + t.system
            self.done.wait(0.05)

    def stop(self) -> float:
        self.done.set()
        self.thread.join()
        return sum(self.seen.values())


def thread_cpu(roots: list[int]) -> dict:
    """``{(pid, tid): (role, CPU seconds)}`` for every thread of ``roots`` and their descendants."""
    import psutil

    procs = {}
    for pid in roots:
        with contextlib.suppress(psutil.Error):
            root = psutil.Process(pid)
            procs[pid] = root
            for child in root.children(recursive=True):
                procs[child.pid] = child
    out = {}
    for pid, p in procs.items():
        with contextlib.suppress(psutil.Error):
            role = process_role(p, roots[0])
            for t in p.threads():
                out[(pid, t.id)] = (role, t.user_time + t.system_time)
    return out


def process_role(p, batch_pid: int) -> str:
    import psutil

    if p.pid == batch_pid:
        return "batch process"
    try:
        cmd = " ".join(p.cmdline())
        parent = " ".join(p.parent().cmdline()) if p.parent() else ""
    except psutil.Error:
        return "other"
    if "resource_tracker" in cmd:
        return "resource tracker"
    if "forkserver" in cmd:
        return "worker" if "forkserver" in parent else "forkserver"
    if "spawn_main" in cmd or "multiprocessing-fork" in cmd or "dask worker [" in cmd:
        return "worker"
    if "dask scheduler" in cmd or "dask-scheduler" in cmd:
        return "scheduler process"
    if "dask worker" in cmd or "dask-worker" in cmd or "dask nanny" in cmd:
        return "nanny process"
    return "other"


def cpu_by_role(a: dict, b: dict, clips: int, seconds: float, batch_pid: int) -> dict:
    """CPU milliseconds per clip between two :func:`thread_cpu` snapshots, by role; a worker's busiest
    thread is its clips' own work ("worker clips"), its other threads "worker other"."""
    per_thread: dict = {}
    for key, (role, cpu) in b.items():
        per_thread[key] = (role, cpu - a.get(key, (role, 0.0))[1])
    busiest: dict = {}
    for (pid, tid), (role, d) in per_thread.items():
        if role == "worker" and d > busiest.get(pid, (None, -1.0))[1]:
            busiest[pid] = (tid, d)
    out: dict = {"clips": clips, "seconds": seconds}
    for (pid, tid), (role, d) in per_thread.items():
        if role == "worker":
            role = "worker clips" if busiest[pid][0] == tid else "worker other"
        out[role] = out.get(role, 0.0) + 1000 * d / clips
    return out


NOT_ROLES = ("clips", "seconds", "whole run cpu")


def print_cpu(acc: dict, clips: int) -> None:
    work = acc.get("worker clips", 0.0)
    parts = {k: v for k, v in acc.items() if k not in NOT_ROLES}
    overhead = sum(parts.values()) - work
    print(f"    CPU ms per clip (clips {acc['clips']} of the middle, {acc['clips'] / acc['seconds']:.2f} clips/s): "
          + ", ".join(f"{k} {v:.1f}" for k, v in sorted(parts.items(), key=lambda kv: -kv[1]))
          + f"; overhead {overhead:.1f} = {100 * overhead / max(work, 1e-9):.0f}% of the clips' work; "
          f"bound for 2 workers on 2 cores {2 / (1 + overhead / max(work, 1e-9)):.2f}x one clip thread")


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
    from usdhands.jobs.batch import QUIET_LOCAL_CLUSTER

    # the settings batch gives its LocalCluster, for these processes only (docs/pipeline.md: a farm's)
    env = dict(os.environ, **{"DASK_" + key.upper().replace(".", "__").replace("-", "_"): str(value)
                              for key, value in QUIET_LOCAL_CLUSTER.items()})
    # Dask's MALLOC_TRIM_THRESHOLD_ (64 KiB) overridden in a config file (an environment variable's name
    # would be lower-cased, and Dask's own value cannot be removed, only replaced): docs/pipeline.md
    (folder / "dask-config").mkdir(exist_ok=True)
    (folder / "dask-config" / "batch-workers.yaml").write_text(
        "distributed:\n  nanny:\n    pre-spawn-environ:\n      MALLOC_TRIM_THRESHOLD_: 1073741824\n")
    env["DASK_CONFIG"] = str(folder / "dask-config")
    with open(folder / "dask.log", "w") as log:
        procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port",
                                   str(port), "--no-dashboard"], stdout=log, stderr=log, cwd=folder, env=env)]
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", address, "--nworkers", str(workers),
                                       "--nthreads", "1", "--no-dashboard", "--local-directory", str(folder)],
                                      stdout=log, stderr=log, cwd=folder, env=env))
        try:
            with Client(address, timeout="60s") as client:
                client.wait_for_workers(workers, timeout=180)
            yield address, tuple(p.pid for p in procs)
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
    ap.add_argument("--rounds", type=int, default=3,
                    help="runs of each engine with 1 and 2 workers, taking turns; rates from the median seconds")
    ap.add_argument("--runs", default="pool,local,running",
                    help="which batches: pool (local process pool), local (Dask LocalCluster), running "
                         "(a Dask cluster already running); comma-separated")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        clips = make_clips(tmp / "in", args.clips)
        print(f"{len(clips)} clips generated in {time.perf_counter() - t0:.1f} s; {os.cpu_count()} CPUs; "
              f"load average {os.getloadavg()[0]:.1f}")
        rates, cpu, rounds = {}, {}, {}
        chosen = set(args.runs.split(",")) - ({"local", "running"} if args.no_dask else set())
        runs = [(name, scheduler) for key, name, scheduler in (
            ("pool", "local pool", None), ("local", "Dask LocalCluster", "local"),
            ("running", "Dask cluster running", "running")) if key in chosen]
        for name, scheduler in runs:
            seconds_of: dict = {1: [], 2: []}
            with contextlib.ExitStack() as stack:
                for r in range(args.rounds):  # 1 and 2 workers taking turns: a change of load hits both
                    for workers in (1, 2):
                        load = os.getloadavg()[0]
                        if scheduler == "running":  # a cluster of its own per run: every run starts from the same
                            address, pids = stack.enter_context(running_dask_cluster(workers, tmp / f"dask{workers}_{r}"))
                            load = os.getloadavg()[0]
                            seconds, acc = run_batch_cli(tmp / "in", tmp / "out", workers, address, pids)
                            stack.close()
                        else:
                            seconds, acc = run_batch_cli(tmp / "in", tmp / "out", workers, scheduler)
                        seconds_of[workers].append(seconds)
                        if r == 0:
                            cpu[(name, workers)] = acc
                        print(f"{name:18s} {workers} worker(s), round {r + 1}: {seconds:6.2f} s, "
                              f"{len(clips) / seconds:6.2f} clips/s (load average before {load:.1f})", flush=True)
            rounds[name] = [a / b for a, b in zip(seconds_of[1], seconds_of[2])]
            for workers in (1, 2):
                seconds = statistics.median(seconds_of[workers])
                rates[(name, workers)] = len(clips) / seconds
                acc = cpu[(name, workers)]
                fixed = seconds - len(clips) * acc["seconds"] / acc["clips"]
                print(f"{name:18s} {workers} worker(s): {seconds:7.2f} s (median of {args.rounds}), "
                      f"{rates[(name, workers)]:6.2f} clips/s; start-up and close {fixed:.2f} s (the run's seconds "
                      f"beyond its clips at the middle's rate, first round)")
                print_cpu(acc, len(clips))
            if scheduler == "local":  # its processes are the batch process's descendants: sampled, not timed
                for workers in (1, 2):
                    _, acc = run_batch_cli(tmp / "in", tmp / "out", workers, scheduler, sample=True)
                    whole = acc["whole run cpu"]
                    clip_cpu = sum(v for k, v in acc.items() if k not in NOT_ROLES)
                    print(f"{name:18s} {workers} worker(s): CPU of the whole run, the batch process and its "
                          f"descendants (an untimed run, sampled every 50 ms): {whole:.1f} s, of which start-up and "
                          f"close ~{whole - len(clips) * clip_cpu / 1000:.1f} s (beyond {len(clips)} clips at the "
                          f"middle's CPU)")
        base = clips[:args.baseline]
        load = os.getloadavg()[0]
        seconds = process_per_clip(base, tmp / "single")
        baseline = len(base) / seconds
        print(f"one process per clip ({len(base)} clips): {seconds:7.1f} s, {baseline:6.2f} clips/s "
              f"(load average before {load:.1f})")
        pool_one = rates.get(("local pool", 1))
        for name, _ in runs:
            one, two = rates[(name, 1)], rates[(name, 2)]
            middle = cpu[(name, 2)]["clips"] / cpu[(name, 2)]["seconds"] / (
                cpu[(name, 1)]["clips"] / cpu[(name, 1)]["seconds"])
            print(f"{name}: 2 workers / 1 worker = {two / one:.2f}x (target 1.7x; of the medians; per round "
                  f"{min(rounds[name]):.2f}-{max(rounds[name]):.2f}x; the middle 80% of the clips "
                  f"{middle:.2f}x); "
                  + (f"2 workers / the local pool's 1 worker = {two / pool_one:.2f}x; " if pool_one else "")
                  + f"batch 1 worker / process per clip = {one / baseline:.1f}x, "
                  f"2 workers = {two / baseline:.1f}x (target 5x)")
            total = {w: sum(v for k, v in cpu[(name, w)].items() if k not in NOT_ROLES) for w in (1, 2)}
            print(f"    CPU per clip, all processes: 1 worker {total[1]:.1f} ms, 2 workers {total[2]:.1f} ms "
                  f"(clips' own work {cpu[(name, 1)].get('worker clips', 0):.1f} and "
                  f"{cpu[(name, 2)].get('worker clips', 0):.1f} ms)")


if __name__ == "__main__":
    main()

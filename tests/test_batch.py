"""``usdhands batch``: local pool and Dask give each job's own outputs; failures recorded; resumable."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
import time

import pytest

import usdhands
import usdhands.cli
from usdhands.errors import UsdHandsError
from usdhands.jobs import batch
from usdhands.jobs.batch import BatchOptions, collect_inputs, run_batch


@pytest.fixture()
def clips(sample_assets, tmp_path):
    """Three gesture takes (one in a subfolder) and a corrupt .glb among them."""
    src = tmp_path / "in"
    (src / "sub").mkdir(parents=True)
    for name in ("ok_00.glb", "ok_01.glb"):
        shutil.copy(sample_assets / "gestures" / name, src / name)
    shutil.copy(sample_assets / "gestures" / "attention_00.glb", src / "sub" / "attention_00.glb")
    (src / "sub" / "broken.glb").write_bytes(b"glTF\x02\x00\x00\x00 truncated")
    return src


def _statuses(report):
    return {os.path.relpath(c.file, report_root(report)): c.status for c in report.clips}


def report_root(report):
    return os.path.commonpath([c.file for c in report.clips])


def test_local_pool_converts_like_the_job_alone_and_records_the_corrupt_clip(clips, tmp_path):
    out = tmp_path / "out"
    report = run_batch([clips], BatchOptions(job="convert", out=out, workers=2, to="usda"))
    assert _statuses(report) == {"ok_00.glb": "done", "ok_01.glb": "done", "sub/attention_00.glb": "done",
                                 "sub/broken.glb": "failed"}
    broken = next(c for c in report.clips if c.status == "failed")
    assert broken.error.startswith(str(clips / "sub" / "broken.glb")) and "\n" not in broken.error
    for rel in ("ok_00", "ok_01", "sub/attention_00"):
        usdhands.convert(clips / f"{rel}.glb", tmp_path / "alone.usda")
        assert (out / f"{rel}.usda").read_bytes() == (tmp_path / "alone.usda").read_bytes()
    saved = json.loads((out / "report.json").read_text())
    assert (saved["done"], saved["failed"], saved["skipped"]) == (3, 1, 0)
    assert [c["status"] for c in saved["clips"]] == [c.status for c in report.clips]


def test_rerun_skips_what_is_done_and_a_changed_option_reruns(clips, tmp_path):
    out = tmp_path / "out"
    options = BatchOptions(job="reduce", out=out, workers=1)
    first = run_batch([clips / "ok_00.glb", clips / "ok_01.glb"], options)
    assert [c.status for c in first.clips] == ["done", "done"]
    stamp = (out / "ok_00.glb").stat().st_mtime_ns
    again = run_batch([clips / "ok_00.glb", clips / "ok_01.glb"], options)
    assert [c.status for c in again.clips] == ["skipped", "skipped"]
    assert (out / "ok_00.glb").stat().st_mtime_ns == stamp
    # a newer input reruns that clip only
    time.sleep(0.01)
    os.utime(clips / "ok_01.glb")
    assert [c.status for c in run_batch([clips / "ok_00.glb", clips / "ok_01.glb"], options).clips] == [
        "skipped", "done"]
    changed = BatchOptions(job="reduce", out=out, workers=1,
                           job_options=usdhands.ReduceOptions(steps="range<5,rmsd<0.5"))
    assert [c.status for c in run_batch([clips / "ok_00.glb", clips / "ok_01.glb"], changed).clips] == [
        "done", "done"]
    usdhands.reduce(clips / "ok_00.glb", tmp_path / "alone.glb", usdhands.ReduceOptions(steps="range<5,rmsd<0.5"))
    assert (out / "ok_00.glb").read_bytes() == (tmp_path / "alone.glb").read_bytes()


def test_dask_local_cluster_synthesizes_like_the_job_alone(clips, tmp_path):
    pytest.importorskip("distributed")
    out = tmp_path / "out"
    options = usdhands.SynthesizeOptions(k=3)
    report = run_batch([clips / "ok_00.glb", clips / "sub"], BatchOptions(
        job="synthesize", out=out, workers=2, scheduler="local", dask_processes=False, job_options=options))
    assert [(os.path.basename(c.file), c.status) for c in report.clips] == [
        ("ok_00.glb", "done"), ("attention_00.glb", "done"), ("broken.glb", "failed")]
    usdhands.synthesize(clips / "ok_00.glb", tmp_path / "alone.glb", options)
    assert (out / "ok_00.glb").read_bytes() == (tmp_path / "alone.glb").read_bytes()
    assert report.scheduler == "local" and report.summary["clips_per_second"] > 0


def test_a_local_cluster_without_distributeds_private_start_wait_still_runs(clips, tmp_path, monkeypatch):
    """The LocalCluster's workers start after the first tasks are queued, waited for by distributed's
    private ``SpecCluster._correct_state``; a distributed without it waits for them by the public
    ``Client.wait_for_workers`` instead, with the same outputs and report."""
    pytest.importorskip("distributed")
    from distributed import Client

    waited = []
    real = Client.wait_for_workers
    monkeypatch.setattr(batch, "SPEC_CLUSTER_START_WAIT", "_not_in_this_distributed")
    monkeypatch.setattr(Client, "wait_for_workers", lambda self, n, **kw: waited.append(n) or real(self, n, **kw))
    report = run_batch([clips / "ok_00.glb", clips / "sub"], BatchOptions(
        job="convert", to="usda", out=tmp_path / "out", workers=2, scheduler="local", dask_processes=False))
    assert [(os.path.basename(c.file), c.status) for c in report.clips] == [
        ("ok_00.glb", "done"), ("attention_00.glb", "done"), ("broken.glb", "failed")]
    usdhands.convert(clips / "ok_00.glb", tmp_path / "alone.usda")
    assert (tmp_path / "out" / "ok_00.usda").read_text() == (tmp_path / "alone.usda").read_text()
    assert waited == [2]


def test_dask_tasks_are_fed_two_per_worker_thread_and_sized_by_the_measured_clips(clips, tmp_path, monkeypatch):
    """The first 2 * workers tasks are sized before any clip was measured, each later one when a task
    has finished, from the mean seconds of the clips done; every clip runs once, in order of the tasks."""
    pytest.importorskip("distributed")
    many = tmp_path / "many"
    many.mkdir()
    for i in range(24):
        shutil.copy(clips / "ok_00.glb", many / f"ok_{i:02d}.glb")
    sizes, real = [], batch.dask_task_size

    def sized(left, slots, clip_seconds):
        sizes.append((left, slots, clip_seconds, real(left, slots, clip_seconds)))
        return sizes[-1][-1]

    monkeypatch.setattr(batch, "dask_task_size", sized)
    report = run_batch([many], BatchOptions(job="convert", to="usda", out=tmp_path / "out", workers=2,
                                            scheduler="local", dask_processes=False))
    assert [c.status for c in report.clips] == ["done"] * 24
    assert sizes[0][0] == 24 and sum(size for *_, size in sizes) == 24
    assert all(b[0] == a[0] - a[-1] for a, b in zip(sizes, sizes[1:]))  # each task takes the next clips
    assert [clip_seconds for _, _, clip_seconds, _ in sizes[:4]] == [None] * 4 and all(s[1] == 2 for s in sizes)
    assert all(clip_seconds > 0 for _, _, clip_seconds, _ in sizes[4:])  # measured once the first tasks are back
    assert len(sizes) > 4


@pytest.mark.parametrize("processes", [True, False])
def test_dask_local_cluster_runs_without_profiler_and_monitors_and_the_callers_config_is_untouched(
        clips, tmp_path, processes):
    """batch's LocalCluster (worker processes, as ``--scheduler local`` makes them, or threads of this
    process) has no statistical profiler and slower health ticks and monitors (their CPU is what 2
    workers on 2 cores cannot spare); a worker process is started without Dask's MALLOC_TRIM_THRESHOLD_
    (2,900 page faults a synthesized clip instead of 8); the outputs are the job's own; the caller's Dask
    config is as it was, also while the clips run (a worker thread of this process reads it then), and
    so is its environment (the nannies, objects of this process, write their workers' variables into it)."""
    dask = pytest.importorskip("dask")
    pytest.importorskip("distributed")
    from batch_worker_probe import SETTINGS

    before, environ = {key: dask.config.get(key) for key in SETTINGS}, dict(os.environ)
    assert before["distributed.worker.profile.enabled"] is True  # Dask's default: the test sees a change
    out = tmp_path / "out"
    report = run_batch([clips / "ok_00.glb", clips / "ok_01.glb"], BatchOptions(
        job="batch_worker_probe:convert_and_describe_worker", out=out, workers=1, scheduler="local",
        dask_processes=processes, job_options=usdhands.ConvertOptions()))
    assert [c.status for c in report.clips] == ["done", "done"]
    for name in ("ok_00", "ok_01"):
        usdhands.convert(clips / f"{name}.glb", tmp_path / "alone.glb")
        assert (out / f"{name}.glb").read_bytes() == (tmp_path / "alone.glb").read_bytes()
        worker = json.loads((out / f"{name}.glb.worker.json").read_text())
        if processes:  # a worker process of its own, set up by its nanny with the settings
            assert worker["pid"] != os.getpid() and worker["settings"] == batch.QUIET_LOCAL_CLUSTER
            assert worker["malloc_trim_threshold"] is None
        else:  # a thread of this process, made with the settings; this process's config is Dask's own
            assert worker["pid"] == os.getpid() and worker["settings"] == before
        assert "profile" not in worker["callbacks"] and "profile-cycle" not in worker["callbacks"]
        assert {"heartbeat", "tick", "monitor"} <= set(worker["callbacks"])  # the rest of the worker as usual
        # batch's plugin, given to the workers when they are made: a process of its own set up as one
        assert "usdhands-own-process-worker" in worker["plugins"] and worker["own_process"] is processes
    assert {key: dask.config.get(key) for key in SETTINGS} == before
    assert dict(os.environ) == environ
    from distributed.nanny import WorkerProcess

    assert WorkerProcess._init_msg_interval == 0.05  # Dask's own again (batch's only while the cluster is made)


def test_inputs_from_a_list_file_and_check_outputs(clips, tmp_path, capsys):
    listing = tmp_path / "takes.txt"
    listing.write_text("# takes to check\nin/ok_00.glb\n\nin/sub/broken.glb\n")
    assert [str(p.relative_to(tmp_path)) for p, _ in collect_inputs([listing])] == ["in/ok_00.glb",
                                                                                     "in/sub/broken.glb"]
    code = usdhands.cli.main(["batch", str(listing), "--job", "check", "--out", str(tmp_path / "out"),
                              "--workers", "1", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 1 and [c["status"] for c in report["clips"]] == ["done", "failed"]
    written = json.loads((tmp_path / "out" / "ok_00.glb.check.json").read_text())
    assert written["files"][0]["status"] == "ok"


def test_bad_batch_options_are_refused_before_any_work(clips, tmp_path):
    with pytest.raises(UsdHandsError, match="--job convert needs --to"):
        run_batch([clips], BatchOptions(job="convert", out=tmp_path / "out"))
    with pytest.raises(UsdHandsError, match="--job expand needs --model"):
        run_batch([clips], BatchOptions(job="expand", out=tmp_path / "out"))
    with pytest.raises(UsdHandsError, match="no such file or folder"):
        run_batch([tmp_path / "nope"], BatchOptions(job="reduce", out=tmp_path / "out"))
    assert not (tmp_path / "out").exists()


@pytest.fixture()
def closing_clips(tmp_path):
    """Two takes of the hand closing into the cylinder (one in a subfolder), a corrupt .usda, the cylinder."""
    from interaction_data import write_closing_scene

    src = tmp_path / "in"
    (src / "sub").mkdir(parents=True)
    write_closing_scene(tmp_path)
    shutil.copy(tmp_path / "closing.usda", src / "a.usda")
    shutil.copy(tmp_path / "closing.usda", src / "sub" / "b.usda")
    (src / "sub" / "broken.usda").write_text("#usda 1.0\n(\n  this is not usd\n")
    return src, tmp_path / "cyl.obj"


@pytest.mark.parametrize("scheduler", [None, "local"])
def test_correct_in_batch_like_the_job_alone(closing_clips, tmp_path, scheduler):
    if scheduler:
        pytest.importorskip("distributed")
    src, cyl = closing_clips
    out = tmp_path / "out"
    options = usdhands.CorrectOptions(props=(cyl,), margin=0.5)
    batch = BatchOptions(job="correct", out=out, workers=2, scheduler=scheduler, dask_processes=False,
                         job_options=options)
    report = run_batch([src], batch)
    assert _statuses(report) == {"a.usda": "done", "sub/b.usda": "done", "sub/broken.usda": "failed"}
    usdhands.correct(src / "a.usda", tmp_path / "alone.usda", options)
    alone = (tmp_path / "alone.usda").read_text()
    assert (out / "a.usda").read_text() == alone
    assert (out / "sub" / "b.usda").read_text() == alone
    # a rerun skips; a newer prop reruns every clip
    assert [c.status for c in run_batch([src], batch).clips] == ["skipped", "skipped", "failed"]
    time.sleep(0.01)
    os.utime(cyl)
    assert [c.status for c in run_batch([src], batch).clips] == ["done", "done", "failed"]


def test_batch_correct_from_the_command_line(closing_clips, tmp_path, capsys):
    src, cyl = closing_clips
    code = usdhands.cli.main(["batch", str(src / "a.usda"), "--job", "correct", "--props", str(cyl),
                              "--out", str(tmp_path / "out"), "--workers", "1", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and [c["status"] for c in report["clips"]] == ["done"]
    fixed = usdhands.check(tmp_path / "out" / "a.usda", usdhands.CheckOptions(props=(cyl,)))
    assert fixed.exit_status == 0
    assert usdhands.check(src / "a.usda", usdhands.CheckOptions(props=(cyl,))).exit_status == 1
    with pytest.raises(UsdHandsError, match="--job correct needs --props"):
        run_batch([src], BatchOptions(job="correct", out=tmp_path / "none"))
    assert not (tmp_path / "none").exists()


@pytest.mark.parametrize("scheduler", [None, "local"])
def test_workers_run_kernels_on_one_thread_and_the_callers_process_is_untouched(clips, tmp_path, scheduler):
    """The local pool's workers (processes of their own) set numba's threads to 1; a Dask LocalCluster with
    processes=False runs its workers as threads of this process, which must keep numba's setting and
    environment as they were (the reverted a6aa675 leaked NUMBA_NUM_THREADS=1 into it)."""
    numba = pytest.importorskip("numba")
    if scheduler:
        pytest.importorskip("distributed")

    threads, env = numba.get_num_threads(), dict(os.environ)
    report = run_batch([clips / "ok_00.glb"], BatchOptions(
        job="synthesize", out=tmp_path / "out", workers=1, scheduler=scheduler, dask_processes=False,
        job_options=usdhands.SynthesizeOptions(k=3)))
    assert [c.status for c in report.clips] == ["done"]
    assert numba.get_num_threads() == threads and dict(os.environ) == env
    assert batch._own_worker_process is False
    if scheduler is None:
        from usdhands.jit import kernel_threads

        with batch._pool(1, "convert", usdhands.ConvertOptions()) as pool:
            assert pool.submit(kernel_threads).result() == 1


def test_a_synthesize_worker_loads_the_search_kernel_at_start_with_the_signature_of_every_search(
        sample_assets, tmp_path):
    """Without the kernels compiled ahead of time (USDHANDS_COMPILED_KERNELS=0, as an install without a C
    compiler): a worker process of its own loads the numba search kernel while it starts (it searched its
    first ~45 clips in NumPy at 2.5x the CPU before), with the argument types synthesis then calls it with:
    one signature after a clip (another would be compiled or loaded again, per clip). A worker that
    expects fewer than 20 clips keeps to NumPy (0.5 s of numba for ~28 ms saved a clip), and so does
    the caller's process warmed the same way."""
    pytest.importorskip("numba")
    code = (
        "import json, sys, usdhands\n"
        "from usdhands.jobs import batch\n"
        "from usdhands.algorithms.synthesis import segment_cost\n"
        "batch._warm_worker('synthesize', usdhands.SynthesizeOptions(), batch.KERNEL_AT_START_CLIPS)\n"
        "caller = segment_cost._kernel_loaded()\n"
        "batch.become_worker_process()\n"
        "batch._warm_worker('synthesize', usdhands.SynthesizeOptions(), batch.KERNEL_AT_START_CLIPS - 1)\n"
        "few = segment_cost._kernel_loaded()\n"
        "batch._warm_worker('synthesize', usdhands.SynthesizeOptions(), batch.KERNEL_AT_START_CLIPS)\n"
        "worker = segment_cost._kernel_loaded()\n"
        "from usdhands.algorithms.synthesis import _dtw_kernel\n"
        "loaded = len(_dtw_kernel.search.signatures)\n"
        f"usdhands.synthesize({str(sample_assets / 'conversation_bodyonly.bvh')!r}, {str(tmp_path / 'o.bvh')!r})\n"
        "print(json.dumps([caller, few, worker, loaded, len(_dtw_kernel.search.signatures)]))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, USDHANDS_COMPILED_KERNELS="0"))
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.splitlines()[-1]) == [False, False, True, 1, 1]


def test_a_synthesize_worker_with_the_kernels_compiled_ahead_of_time_never_imports_numba(sample_assets, tmp_path):
    """Where the kernels compiled at install were built, a worker warmed for many clips loads no numba and
    its clips run without it (the same output as numba's kernels: tests/test_compiled_kernels.py)."""
    from usdhands.compiled import KERNEL_MODULES, kernel_module

    if any(kernel_module(name) is None for name in KERNEL_MODULES):
        pytest.skip("the kernels compiled ahead of time were not built (no C compiler at install)")
    code = (
        "import json, sys, usdhands\n"
        "from usdhands.jobs import batch\n"
        "batch.become_worker_process()\n"
        "batch._warm_worker('synthesize', usdhands.SynthesizeOptions(), batch.KERNEL_AT_START_CLIPS)\n"
        "warm = 'numba' in sys.modules\n"
        "for n in range(2):\n"
        f"    r = batch.run_clip('synthesize', usdhands.SynthesizeOptions(), None,\n"
        f"                       usdhands.jobs.batch.Path({str(sample_assets / 'conversation_bodyonly.bvh')!r}),\n"
        f"                       usdhands.jobs.batch.Path({str(tmp_path)!r}) / f'o{{n}}.bvh')\n"
        "    assert r.status == 'done', r\n"
        "print(json.dumps([warm, 'numba' in sys.modules]))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.splitlines()[-1]) == [False, False]


def test_the_warm_forkserver_imports_what_a_clip_needs(sample_assets, tmp_path):
    """After the warm forkserver's preload, a synthesize of a BVH clip imports no further module (each
    worker's first clip then costs what the others do)."""
    code = (
        "import json, sys, usdhands\n"
        "from usdhands.jobs import batch\n"
        "batch._warm_forkserver_process()\n"
        "before = set(sys.modules)\n"
        f"usdhands.synthesize({str(sample_assets / 'conversation_bodyonly.bvh')!r}, {str(tmp_path / 'o.bvh')!r})\n"
        "print(json.dumps(sorted(set(sys.modules) - before)))")
    assert _run_fresh(code) == []


def _run_fresh(code: str, **environ) -> object:
    """``code`` run by a fresh interpreter (its own forkserver) with the tests folder importable and
    ``environ`` added to its environment: the JSON of its last printed line."""
    here = os.path.dirname(os.path.abspath(__file__))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([here, os.environ.get("PYTHONPATH", "")]), **environ)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.splitlines()[-1])


def test_a_worker_forked_from_the_warm_forkserver_with_dask_has_the_processor_name_already():
    """With Dask preloaded (a LocalCluster's forkserver), the processor's name each worker reports when it
    registers (``uname -p``) was asked once, in the forkserver, on a thread that ended before any fork;
    without Dask (the local pool's) it is left unasked."""
    pytest.importorskip("distributed")
    code = (
        "import json, multiprocessing\n"
        "from concurrent.futures import ProcessPoolExecutor\n"
        "from usdhands.jobs import batch\n"
        "import batch_dying_job\n"
        "assert batch.start_warm_forkserver(dask={dask})\n"
        "with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context('forkserver')) as pool:\n"
        "    print(json.dumps(pool.submit(batch_dying_job.processor_known).result()))\n")
    assert _run_fresh(code.format(dask=True)) == [True, 1]
    assert _run_fresh(code.format(dask=False)) == [False, 1]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/PID/maps")
def test_a_worker_forked_from_the_warm_forkserver_has_the_kernel_and_one_kernel_thread():
    """Without the kernels compiled ahead of time: the warm forkserver loaded numba but started none of its
    threads (a process forked after they started would have none); its workers load the search kernel and
    run kernels on one thread. A pool in a process that did not ask for it forks from a forkserver without
    numba. With them: neither the forkserver nor its workers import numba; a worker that does (a kernel
    of another job) runs its kernels on one thread."""
    pytest.importorskip("numba")
    from usdhands.compiled import KERNEL_MODULES, kernel_module

    code = (
        "import json, usdhands\n"
        "from usdhands.jobs import batch\n"
        "import batch_dying_job\n"
        "if {warm}:\n"
        "    assert batch.start_warm_forkserver()\n"
        "with batch._pool(2, 'synthesize', usdhands.SynthesizeOptions(), batch.KERNEL_AT_START_CLIPS) as pool:\n"
        "    states = [f.result() for f in [pool.submit(batch_dying_job.worker_state) for _ in range(4)]]\n"
        "print(json.dumps(states[0]))\n")
    without = {"USDHANDS_COMPILED_KERNELS": "0"}
    warm = _run_fresh(code.format(warm=True), **without)
    assert warm == {"had_numba": True, "kernel_threads": 1, "search_kernel": True, "parent_has_numba": True,
                    "parent_started_threads": False}
    cold = _run_fresh(code.format(warm=False), **without)
    assert cold == {"had_numba": True, "kernel_threads": 1, "search_kernel": True, "parent_has_numba": False,
                    "parent_started_threads": False}
    if all(kernel_module(name) is not None for name in KERNEL_MODULES):
        for warm in (True, False):
            assert _run_fresh(code.format(warm=warm)) == {
                "had_numba": False, "kernel_threads": 1, "search_kernel": False, "parent_has_numba": False,
                "parent_started_threads": False}


def test_only_a_batch_that_asks_starts_the_warm_forkserver(clips, tmp_path, monkeypatch):
    """run_batch's callers keep their process's forkserver as it is unless they set warm_forkserver (the
    command line does), and then only for synthesize on the local pool with enough clips a worker."""
    calls = []
    monkeypatch.setattr(batch, "start_warm_forkserver", lambda dask=False: calls.append(1) or True)
    monkeypatch.setattr(batch, "KERNEL_AT_START_CLIPS", 1)
    options = BatchOptions(job="convert", out=tmp_path / "a", workers=1, job_options=usdhands.ConvertOptions(),
                           to="usda")
    run_batch([clips / "ok_00.glb"], options)
    run_batch([clips / "ok_00.glb"], dataclasses.replace(options, warm_forkserver=True, out=tmp_path / "b"))
    assert calls == []
    synth = BatchOptions(job="synthesize", out=tmp_path / "c", workers=1, job_options=usdhands.SynthesizeOptions(k=3))
    run_batch([clips / "ok_00.glb"], synth)
    assert calls == []
    report = run_batch([clips / "ok_00.glb"], dataclasses.replace(synth, warm_forkserver=True, out=tmp_path / "d"))
    assert calls == [1] and [c.status for c in report.clips] == ["done"]
    parsed = []
    monkeypatch.setattr(batch, "run_batch", lambda inputs, options, progress=None: parsed.append(options) or
                        run_batch(inputs, options, progress))
    assert usdhands.cli.main(["batch", str(clips / "ok_00.glb"), "--job", "synthesize", "--k", "3", "--out",
                              str(tmp_path / "e"), "--workers", "1", "-q"]) == 0
    assert parsed[0].warm_forkserver is True


def test_a_warm_local_cluster_forks_its_worker_processes_from_the_warm_forkserver(clips, tmp_path, monkeypatch):
    """A synthesize batch asking for the warm forkserver on a LocalCluster of worker processes starts it with
    Dask loaded and makes the cluster with multiprocessing-method forkserver (its nannies fork their workers
    from it); a cluster of threads of this process or a caller that did not ask: Dask's spawn, and this
    process's Dask config is as it was."""
    dask = pytest.importorskip("dask")
    distributed = pytest.importorskip("distributed")
    calls, made, looks, warms = [], [], [], []

    class Made(Exception):
        pass

    def cluster(**kwargs):
        from distributed.nanny import WorkerProcess

        made.append((kwargs["processes"], dask.config.get("distributed.worker.multiprocessing-method")))
        looks.append(WorkerProcess._init_msg_interval)
        plugin, = kwargs["plugins"]
        warms.append(plugin.warm[2])
        raise Made

    monkeypatch.setattr(batch, "start_warm_forkserver", lambda dask=False: calls.append(dask) or True)
    monkeypatch.setattr(batch, "KERNEL_AT_START_CLIPS", 1)
    monkeypatch.setattr(distributed, "LocalCluster", cluster)
    before = dask.config.get("distributed.worker.multiprocessing-method")
    options = BatchOptions(job="synthesize", out=tmp_path / "a", workers=1, scheduler="local", warm_forkserver=True,
                           job_options=usdhands.SynthesizeOptions(k=3))
    for n, change in enumerate(({}, {"dask_processes": False}, {"warm_forkserver": False})):
        with pytest.raises(Made):
            run_batch([clips / "ok_00.glb"], dataclasses.replace(options, out=tmp_path / str(n), **change))
    assert calls == [True]
    assert made == [(True, "forkserver"), (False, before), (True, before)]
    assert dask.config.get("distributed.worker.multiprocessing-method") == before
    # the nannies look for their new worker every 5 ms while the cluster is made (Dask: 50 ms), as before after
    from distributed.nanny import WorkerProcess

    assert looks == [batch.NANNY_LOOK_INTERVAL] * 3 and WorkerProcess._init_msg_interval == 0.05
    assert warms == [1, 1, 1]  # each worker warms for its share of the clips (one clip, one worker)


def test_a_local_cluster_whose_workers_fork_from_the_warm_forkserver_synthesizes_like_the_job_alone(clips, tmp_path):
    """The worker processes forked from the warm forkserver (Dask, synthesis and numba loaded) run the
    clips as spawned ones do: the job's own outputs."""
    pytest.importorskip("numba")
    pytest.importorskip("distributed")
    code = (
        "import json, usdhands\n"
        "from pathlib import Path\n"
        "from usdhands.jobs import batch\n"
        "batch.KERNEL_AT_START_CLIPS = 1\n"
        f"report = batch.run_batch([{str(clips / 'ok_00.glb')!r}, {str(clips / 'ok_01.glb')!r}], batch.BatchOptions("
        f"job='synthesize', out=Path({str(tmp_path / 'out')!r}), workers=2, scheduler='local', warm_forkserver=True,"
        " job_options=usdhands.SynthesizeOptions(k=3)))\n"
        "print(json.dumps([c.status for c in report.clips]))\n")
    assert _run_fresh(code) == ["done", "done"]
    for name in ("ok_00", "ok_01"):
        usdhands.synthesize(clips / f"{name}.glb", tmp_path / "alone.glb", usdhands.SynthesizeOptions(k=3))
        assert (tmp_path / "out" / f"{name}.glb").read_bytes() == (tmp_path / "alone.glb").read_bytes()


def test_a_refused_batch_starts_no_forkserver(tmp_path):
    """A batch refused by its options (an option of another job) is one line, exit status 2, and starts
    no warm forkserver (numba's ~0.5 s start for nothing): the options are checked before the inputs
    are listed and the forkserver is started."""
    src = tmp_path / "in"
    src.mkdir()
    for n in range(2 * batch.KERNEL_AT_START_CLIPS):
        (src / f"c{n:02d}.bvh").write_text("HIERARCHY\n")
    code = (
        "import json, sys\n"
        "from usdhands.jobs import batch\n"
        "started = []\n"
        "batch.start_warm_forkserver = lambda dask=False: started.append(dask) or False\n"
        f"sys.argv = ['usdhands', 'batch', {str(src)!r}, '--job', 'synthesize', '--steps', 'range<5',\n"
        f"            '--out', {str(tmp_path / 'out')!r}, '--workers', '2']\n"
        "from usdhands.cli import entry_point\n"
        "try:\n"
        "    entry_point()\n"
        "except SystemExit as e:\n"
        "    code = e.code\n"
        "print(json.dumps([code, started, 'numba' in sys.modules]))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert json.loads(done.stdout.splitlines()[-1]) == [2, [], False], done.stderr[-2000:]
    assert done.stderr == "usdhands: error: --steps is not an option of --job synthesize\n"
    assert not (tmp_path / "out").exists()


def test_the_command_line_starts_the_warm_forkserver_before_numpy_loads(tmp_path):
    """``usdhands batch --job synthesize`` starts the workers' forkserver as soon as it has parsed its
    arguments (where the kernels compiled ahead of time were built): before NumPy loads."""
    from usdhands.compiled import KERNEL_MODULES, kernel_file_built

    if not all(kernel_file_built(name) for name in KERNEL_MODULES if not name.startswith("algorithms.interaction.")):
        pytest.skip("the kernels compiled ahead of time were not built: the forkserver starts once the batch is listed")
    code = ("import json, sys\n"
            "from usdhands.jobs import batch\n"
            "seen = []\n"
            "batch.start_warm_forkserver = lambda dask=False: seen.append(['numpy' in sys.modules, dask])\n"
            "from usdhands.cli import main\n"
            f"code = main(['batch', {str(tmp_path / 'none')!r}, '--job', 'synthesize', '--out', "
            f"{str(tmp_path / 'out')!r}, '--scheduler', 'local'])\n"
            "print(json.dumps([code, seen[0]]))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert json.loads(done.stdout.splitlines()[-1]) == [2, [False, True]], done.stderr[-2000:]
    assert "no such file or folder" in done.stderr


def test_the_warm_forkserver_ends_at_once_at_exit_its_streams_flushed():
    """The warm forkserver's preload makes its exit end at once: what it wrote is flushed, the exit
    handlers registered before (and Python's teardown of the modules) are skipped."""
    code = ("import atexit, sys\n"
            "atexit.register(lambda: print('an earlier exit handler ran', flush=True))\n"
            "import usdhands.jobs.batch_forkserver\n"
            "sys.stdout.write('written, not flushed')\nsys.stderr.write('to stderr')\nsys.exit(3)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert (done.returncode, done.stdout, done.stderr) == (0, "written, not flushed", "to stderr")


@pytest.mark.parametrize("how", ["freeze_at_exit", "dask_plugin", "dask_plugin_farm", "cli"])
def test_processes_batch_starts_exit_without_the_last_collections_and_keep_their_status(how):
    """The LocalCluster's workers (not a farm's) and the command line's process freeze the garbage
    collector at exit (its last collections over numba's objects took ~0.3 s): an exit handler
    registered before still runs, after the freeze, and the exit status is kept."""
    setup = {
        "freeze_at_exit": "from usdhands.jobs.batch import freeze_at_exit\nfreeze_at_exit()\nsys.exit(3)\n",
        "dask_plugin": "import pickle\npickle.loads(bytes.fromhex(sys.argv[1])).setup(None)\nsys.exit(3)\n",
        "dask_plugin_farm": "import pickle\npickle.loads(bytes.fromhex(sys.argv[1])).setup(None)\nsys.exit(3)\n",
        "cli": "sys.argv = ['usdhands', 'no-such-command']\nfrom usdhands.cli import entry_point\nentry_point()\n",
    }[how]
    args = []
    if how.startswith("dask_plugin"):
        pytest.importorskip("distributed")
        import pickle

        from usdhands.jobs.dask_worker import OwnProcessWorker

        args = [pickle.dumps(OwnProcessWorker(freeze_at_exit=how == "dask_plugin")).hex()]
    code = ("import atexit, gc, sys\n"
            "atexit.register(lambda: print('frozen', gc.get_freeze_count() > 0, flush=True))\n" + setup)
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=600)
    assert done.returncode == (2 if how == "cli" else 3), done.stderr[-2000:]
    assert done.stdout.splitlines()[-1] == f"frozen {how != 'dask_plugin_farm'}"


def test_a_clip_that_kills_a_worker_forked_warm_is_retried_once_then_failed(clips, tmp_path):
    """Workers forked from the warm forkserver die and are replaced as before: the killer fails alone."""
    pytest.importorskip("numba")
    shutil.copy(clips / "ok_00.glb", clips / "die_00.glb")
    (clips / "sub" / "broken.glb").unlink()
    code = (
        "import json, usdhands\n"
        "from pathlib import Path\n"
        "from usdhands.jobs import batch\n"
        "assert batch.start_warm_forkserver()\n"
        f"report = batch.run_batch([{str(clips)!r}], batch.BatchOptions(job='batch_dying_job:convert_or_die', "
        f"out=Path({str(tmp_path / 'out')!r}), workers=2, job_options=usdhands.ConvertOptions()))\n"
        "print(json.dumps({Path(c.file).name: [c.status, c.error] for c in report.clips}))\n")
    died = "the worker process died on this clip (retried once, alone)"
    assert _run_fresh(code) == {"die_00.glb": ["failed", died], "ok_00.glb": ["done", None],
                                "ok_01.glb": ["done", None], "attention_00.glb": ["done", None]}


def test_a_clip_that_kills_its_worker_is_retried_once_then_failed_and_the_others_are_done(clips, tmp_path):
    """``tests/batch_dying_job.py`` ends the worker process (os._exit) on clips named die*: the pool
    breaks and every clip in flight is retried once, alone; the killer fails, the others are done."""
    for name in ("die_00.glb", "die_01.glb"):
        shutil.copy(clips / "ok_00.glb", clips / name)
    (clips / "sub" / "broken.glb").unlink()
    out = tmp_path / "out"
    report = run_batch([clips], BatchOptions(job="batch_dying_job:convert_or_die", out=out, workers=2,
                                             job_options=usdhands.ConvertOptions()))
    assert _statuses(report) == {"die_00.glb": "failed", "die_01.glb": "failed", "ok_00.glb": "done",
                                 "ok_01.glb": "done", "sub/attention_00.glb": "done"}
    failed = [c for c in report.clips if c.status == "failed"]
    assert all(c.error == "the worker process died on this clip (retried once, alone)" for c in failed)
    usdhands.convert(clips / "ok_01.glb", tmp_path / "alone.glb")
    assert (out / "ok_01.glb").read_bytes() == (tmp_path / "alone.glb").read_bytes()
    assert not (out / "die_00.glb").exists()
    assert json.loads((out / "report.json").read_text())["failed"] == 2


@pytest.fixture()
def dask_cluster(tmp_path):
    """``dask scheduler`` and ``dask worker`` (2 worker processes, 1 thread each) as subprocesses on a free
    port: the address. The scheduler retries a task whose worker died once (allowed-failures 1) and
    sends each worker one task at a time, so a death counts against the clip that caused it."""
    pytest.importorskip("distributed")
    import socket
    import subprocess
    import sys

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    here = os.path.dirname(os.path.abspath(__file__))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.path.dirname(here), here, os.environ.get("PYTHONPATH", "")]),
               DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES="1",
               DASK_DISTRIBUTED__SCHEDULER__WORKER_SATURATION="1.0")
    address = f"tcp://127.0.0.1:{port}"
    log = open(tmp_path / "dask.log", "w")
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], env=env, stdout=log, stderr=log, cwd=tmp_path)]
    procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", address, "--nworkers", "2", "--nthreads",
                                   "1", "--no-dashboard", "--local-directory", str(tmp_path / "dask")],
                                  env=env, stdout=log, stderr=log, cwd=tmp_path))
    try:
        from distributed import Client

        with Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=180)
        yield address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        log.close()


def test_dask_tasks_are_sized_by_the_clips_measured_seconds_and_shrink_to_one_clip_at_the_end():
    """A task aims at DASK_TASK_SECONDS of clips (2 clips before any was measured), at most half a
    thread's share of the clips left, at least one."""
    assert batch.DASK_TASK_SECONDS == 0.25 and batch.DASK_FIRST_TASK_CLIPS == 2
    assert batch.dask_task_size(200, 2, None) == 2  # nothing measured yet
    assert batch.dask_task_size(200, 2, 0.011) == 22  # 0.25 s of 11 ms clips
    assert batch.dask_task_size(200, 2, 0.5) == 1 and batch.dask_task_size(200, 2, 3.0) == 1  # long clips: one each
    assert batch.dask_task_size(60, 2, 0.011) == 15  # half of a thread's share of 60 clips
    assert batch.dask_task_size(3, 2, 0.011) == 1 and batch.dask_task_size(3, 1, 0.011) == 1
    assert batch.dask_task_size(10, 64, 0.001) == 1
    for slots in (1, 2, 3, 8):  # a batch of 200 clips of 11 ms: every clip once, tasks shrinking to one at the end
        left, sizes = 200, []
        while left:
            sizes.append(batch.dask_task_size(left, slots, 0.011 if len(sizes) >= 2 * slots else None))
            left -= sizes[-1]
        assert sizes[:2 * slots] == [2] * 2 * slots and sizes[-1] == 1
        assert sizes[2 * slots] == min(22, (200 - 4 * slots) // (2 * slots))
        assert sizes[2 * slots:] == sorted(sizes[2 * slots:], reverse=True)
        if slots == 2:  # bench_batch's: 25 tasks (tasks of up to 8 clips, each a quarter of a share: 47)
            assert sizes == [2] * 4 + [22] * 5 + [20, 15, 11, 9, 6, 5, 4, 3, 2] + [1] * 7


def test_the_dask_plugin_warms_each_worker_and_leaves_a_failed_warm_up_to_the_clips(monkeypatch):
    """The worker plugin batch gives a LocalCluster's workers when they are made (and registers on a running
    cluster) warms the worker before its first task; in the caller's process (a LocalCluster of threads) it
    changes nothing else; a warm-up that raises does not stop the worker from starting (each clip then
    records its own error)."""
    pytest.importorskip("distributed")
    from usdhands.jobs.dask_worker import OwnProcessWorker

    warmed = []
    options = usdhands.SynthesizeOptions(k=3)
    monkeypatch.setattr(batch, "_warm_worker", lambda *args: warmed.append(args))
    OwnProcessWorker(warm=("synthesize", options, 7)).setup(None)
    OwnProcessWorker().setup(None)  # no warm-up asked
    assert warmed == [("synthesize", options, 7)] and batch._own_worker_process is False
    monkeypatch.setattr(batch, "_warm_worker", lambda *args: 1 / 0)
    OwnProcessWorker(warm=("synthesize", options, 7)).setup(None)


def test_remote_scheduler_runs_the_batch_and_a_killer_clip_fails_alone(clips, tmp_path, dask_cluster):
    shutil.copy(clips / "ok_00.glb", clips / "die_00.glb")
    (clips / "sub" / "broken.glb").unlink()
    out = tmp_path / "out"
    report = run_batch([clips], BatchOptions(job="batch_dying_job:convert_or_die", out=out, workers=2,
                                             scheduler=dask_cluster, job_options=usdhands.ConvertOptions()))
    assert _statuses(report) == {"die_00.glb": "failed", "ok_00.glb": "done", "ok_01.glb": "done",
                                 "sub/attention_00.glb": "done"}
    assert next(c for c in report.clips if c.status == "failed").error.startswith("KilledWorker")
    usdhands.convert(clips / "sub" / "attention_00.glb", tmp_path / "alone.glb")
    assert (out / "sub" / "attention_00.glb").read_bytes() == (tmp_path / "alone.glb").read_bytes()
    # the workers are processes of their own: the plugin made them run kernels on one thread
    from distributed import Client

    with Client(dask_cluster, timeout="60s") as client:
        client.wait_for_workers(2, timeout=180)  # the nanny restarts the killer's worker: it may still be joining
        flags = client.run(lambda: __import__("usdhands.jobs.batch").jobs.batch._own_worker_process)
    assert sorted(flags.values()) == [True, True]
    # a longer batch goes in tasks of several clips: the task holding the killer dies twice, then its
    # clips run alone; the killer fails, its task mates and every other clip are done
    many = tmp_path / "many"
    many.mkdir()
    for i in range(15):
        shutil.copy(clips / "ok_00.glb", many / f"ok_{i:02d}.glb")
    shutil.copy(clips / "ok_00.glb", many / "die_07.glb")
    todo = sorted(many.iterdir())
    assert batch.dask_task_size(len(todo), 2, None) == 2 and todo[0].name == "die_07.glb"  # in a 2-clip task
    report = run_batch([many], BatchOptions(job="batch_dying_job:convert_or_die", out=tmp_path / "many_out",
                                            workers=2, scheduler=dask_cluster, job_options=usdhands.ConvertOptions()))
    statuses = {os.path.basename(c.file): c.status for c in report.clips}
    assert statuses == {**{f"ok_{i:02d}.glb": "done" for i in range(15)}, "die_07.glb": "failed"}
    assert next(c for c in report.clips if c.status == "failed").error.startswith("KilledWorker")
    # and through the command line, with --scheduler ADDRESS
    code = usdhands.cli.main(["batch", str(clips / "ok_01.glb"), "--job", "convert", "--to", "usda",
                              "--out", str(tmp_path / "cli"), "--scheduler", dask_cluster])
    assert code == 0 and (tmp_path / "cli" / "ok_01.usda").stat().st_size > 0

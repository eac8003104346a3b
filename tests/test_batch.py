"""``usdhands batch``: local pool and Dask give each job's own outputs; failures recorded; resumable."""

from __future__ import annotations

import json
import os
import shutil
import time

import pytest

import usdhands
import usdhands.cli
from usdhands.errors import UsdHandsError
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
    import usdhands.jobs.batch as batch

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

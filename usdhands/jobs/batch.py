"""The batch runner: one job over many clips, on a local process pool or a Dask cluster.

::

    import usdhands
    from usdhands.jobs.batch import BatchOptions, run_batch

    report = run_batch(["takes/"], BatchOptions(job="synthesize", out=Path("out"), workers=2,
                                               job_options=usdhands.SynthesizeOptions(k=8)))
    print(report.summary)     # {"done", "skipped", "failed", "seconds", "clips_per_second"}

- Inputs: files, folders (searched recursively for the job's input extensions) or a text
  file listing paths (one a line, ``#`` comments; relative paths from the list's folder).
- Outputs under ``out``, at the input's path relative to the folder it was found in (its
  name for a file given directly); ``convert`` takes the extension ``to``; ``check``
  writes ``<name>.check.json``. Written atomically by the jobs.
- Resumable: an output newer than its input (and the ``expand`` model) and than the
  options recorded in ``out/batch_options.json`` is skipped; a changed option rewrites
  that file, so every clip runs again.
- A failing clip is recorded (``out/report.json``: file, status, seconds, error line) and
  does not stop the others. A worker process that dies is replaced and its clips retried
  once, each alone, so a clip that kills its worker is the only one to fail. (Dask runs a
  long batch in tasks of about a quarter of a second of clips, :func:`dask_task_size`; a task
  whose worker died twice is retried clip by clip, and a clip that kills its worker twice
  alone fails with ``KilledWorker``.)
- Start-up is paid once per worker, and the database loaded once per worker
  (:func:`usdhands.jobs.inputs.cached_database`).
- A worker in a process of its own (the local pool's, a Dask worker process) runs numba's
  parallel kernels on one thread (:func:`usdhands.jit.set_kernel_threads`): one clip per
  core, not every clip's kernel threads fighting over all cores. The caller's process is
  never changed: Dask workers that are threads of the caller (``LocalCluster(processes=False)``)
  keep numba's default, and no environment variable is set anywhere.
- ``scheduler``: None for a local process pool (``workers`` processes), ``"local"`` for a
  ``dask.distributed.LocalCluster`` of ``workers`` processes, or a scheduler address
  (``tcp://host:8786``) to send the clips to an existing Dask cluster (``pip install
  'usdhands[dask]'``; the workers need usdhands installed and the paths visible). The
  LocalCluster runs without Dask's profiler and with slower health checks
  (:data:`QUIET_LOCAL_CLUSTER`, in Dask's config only while batch makes the cluster).

- ``correct`` (and ``check`` with ``props``): a changed prop file reruns every clip, as a
  changed option does.

Adding a job: an entry in :data:`JOBS` naming its module, function and options class. A
pipeline's own job runs without one: ``job="package.module:function"``, a function
``(source, output, options)`` importable in the workers, with ``job_options`` given.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import json
import os
import tempfile
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, as_completed, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from usdhands.errors import UsdHandsError, one_line

ANIMATION_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz", ".gltf", ".glb", ".bvh")

#: job -> (module under usdhands.jobs, function, options class)
JOBS = {
    "synthesize": ("synthesis", "synthesize", "SynthesizeOptions"),
    "reduce": ("reduction", "reduce", "ReduceOptions"),
    "expand": ("expansion", "expand", "ExpandOptions"),
    "convert": ("conversion", "convert", "ConvertOptions"),
    "check": ("validation", "check", "CheckOptions"),
    "correct": ("correction", "correct", "CorrectOptions"),
}
OPTIONS_FILE = "batch_options.json"
REPORT_FILE = "report.json"


@dataclass(frozen=True)
class BatchOptions:
    """Options of :func:`run_batch`.

    Attributes
    ----------
    job : str
        A key of :data:`JOBS`.
    out : Path
        Output folder (made when missing).
    job_options : dataclass or None
        The job's options (``SynthesizeOptions`` ...); None: its defaults.
    workers : int
        Worker processes (at least 1).
    scheduler : str or None
        None: local process pool; ``"local"``: a Dask LocalCluster; else a Dask scheduler address.
    to : str or None
        ``convert``: the output extension (``".usda"``, ``"glb"`` ...).
    model : Path or None
        ``expand``: the reduction model JSON.
    dask_processes : bool
        ``scheduler="local"``: worker processes (True) or threads of this process (False, for tests).
    warm_forkserver : bool
        ``synthesize`` on the local pool or on a LocalCluster of worker processes
        (:func:`wants_warm_forkserver`): start this process's multiprocessing forkserver at once with
        synthesis, the bundled database and the kernels compiled ahead of time loaded (numba where
        those were not built; and Dask, for the LocalCluster: :func:`start_warm_forkserver`), so
        that the workers fork from it warm. It changes the
        process's forkserver for the rest of its life: for a process that runs batch and nothing
        else (the command line sets it); library callers keep False.
    """

    job: str
    out: Path
    job_options: object = None
    workers: int = 1
    scheduler: str | None = None
    to: str | None = None
    model: Path | None = None
    dask_processes: bool = True
    warm_forkserver: bool = False


@dataclass(frozen=True)
class ClipRecord:
    """One clip of a batch: ``status`` is ``"done"``, ``"skipped"`` or ``"failed"``."""

    file: str
    output: str
    status: str
    seconds: float = 0.0
    error: str | None = None

    def to_json(self) -> dict:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class BatchReport:
    """What a batch did: a record per clip and the summary."""

    job: str
    clips: tuple[ClipRecord, ...]
    seconds: float
    workers: int
    scheduler: str | None = None
    notes: tuple[str, ...] = field(default=())

    def count(self, status: str) -> int:
        return sum(c.status == status for c in self.clips)

    @property
    def summary(self) -> dict:
        done = self.count("done")
        return {"done": done, "skipped": self.count("skipped"), "failed": self.count("failed"),
                "seconds": round(self.seconds, 3),
                "clips_per_second": round(done / self.seconds, 3) if self.seconds > 0 else 0.0}

    def to_json(self) -> dict:
        """The content of ``report.json``."""
        return {"job": self.job, "workers": self.workers, "scheduler": self.scheduler, **self.summary,
                "clips": [c.to_json() for c in self.clips]}


def run_batch(inputs: Sequence[str | os.PathLike], options: BatchOptions,
              progress: Callable[[int, int, int, str], None] | None = None) -> BatchReport:
    """Run ``options.job`` on every clip of ``inputs``; writes the outputs and ``report.json`` under ``options.out``.

    Parameters
    ----------
    inputs : paths
        Files, folders or text files listing paths.
    options : BatchOptions
    progress : callable, optional
        ``progress(finished, total, failed, what)`` after each clip (skipped ones included).

    Raises
    ------
    UsdHandsError
        No inputs, an unknown job, bad options, or Dask missing for a ``scheduler``; a
        failing clip does not raise (it is recorded).
    """
    if options.job not in JOBS and not _own_job(options.job):
        raise UsdHandsError(f"unknown job {options.job!r}; expected one of {', '.join(JOBS)} "
                            f"or package.module:function")
    if options.workers < 1:
        raise UsdHandsError(f"--workers must be at least 1, got {options.workers}")
    if options.job_options is None and options.job not in JOBS:
        raise UsdHandsError(f"job {options.job}: give its options (job_options)")
    job_options = options.job_options if options.job_options is not None else _options_class(options.job)()
    if options.job == "expand" and options.model is None:
        raise UsdHandsError("--job expand needs --model MODEL.json")
    if options.job == "convert" and not options.to:
        raise UsdHandsError("--job convert needs --to EXT (usda, glb, bvh, ...)")
    if options.job == "correct":
        from usdhands.jobs.correction import check_correct_options

        if not getattr(job_options, "props", ()):
            raise UsdHandsError("--job correct needs --props PROP...")
        check_correct_options(job_options)
    if options.job in JOBS and hasattr(job_options, "props"):  # --self, --interaction-config...: nothing reads them
        from usdhands.jobs.props import refuse_prop_options_without_props

        refuse_prop_options_without_props(job_options)
    extensions = ANIMATION_EXTENSIONS
    # it loads while the inputs are listed and the outputs checked (where it loads no numba, whatever the
    # batch's size), else while the outputs are checked and the pool or the cluster is made
    warm = wants_warm_forkserver(options) and start_warm_forkserver(dask=options.scheduler is not None)
    pairs = []
    out = Path(options.out)
    for src, rel in collect_inputs(inputs, extensions):
        pairs.append((src, out / output_name(rel, options)))
    if not warm and wants_warm_forkserver(options, len(pairs)):
        warm = start_warm_forkserver(dask=options.scheduler is not None)
    if not pairs:
        named = [Path(p) for p in inputs]
        raise UsdHandsError(f"no input clips found ({', '.join(extensions)})",
                            path=named[0] if len(named) == 1 else None)
    check_side_files(_side_inputs(options, job_options), out)
    resolved = {Path(p).resolve() for p, _ in pairs}
    identities = {_identity(p) for p, _ in pairs} - {None}
    out.mkdir(parents=True, exist_ok=True)
    recorded = _record_options(out, options, job_options)
    todo, records = [], {}
    for src, dst in pairs:
        if dst.resolve() in resolved or _identity(dst) in identities:  # the same path, a symlink or a hard link
            records[src] = ClipRecord(str(src), str(dst), "failed", 0.0, "the output would overwrite an input")
        elif _up_to_date(src, dst, recorded, _side_files(options, job_options)):
            records[src] = ClipRecord(str(src), str(dst), "skipped")
        else:
            todo.append((src, dst))
    finished = [len(records), sum(r.status == "failed" for r in records.values())]  # clips finished, failed

    def report(record: ClipRecord) -> None:
        records[Path(record.file)] = record
        finished[0] += 1
        finished[1] += record.status == "failed"
        if progress:
            progress(finished[0], len(pairs), finished[1], Path(record.file).name)

    if progress and records:
        progress(finished[0], len(pairs), finished[1], "")
    task = (options.job, job_options, options.model)
    start = time.perf_counter()
    if todo:
        if options.scheduler is None:
            _run_local(todo, task, options.workers, report)
        else:
            _run_dask(todo, task, options, report, warm)
    seconds = time.perf_counter() - start
    result = BatchReport(options.job, tuple(records[src] for src, _ in pairs), seconds, options.workers,
                         options.scheduler)
    _write_json(out / REPORT_FILE, result.to_json())
    return result


# ----------------------------------------------------------------------------- inputs and outputs
def collect_inputs(inputs: Sequence[str | os.PathLike], extensions=ANIMATION_EXTENSIONS) -> list[tuple[Path, Path]]:
    """``(file, path relative to where it was found)`` for files, folders (recursive) and lists of paths."""
    out: list[tuple[Path, Path]] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            for f in sorted(p.rglob("*")):
                if f.is_file() and f.suffix.lower() in extensions:
                    out.append((f, f.relative_to(p)))
        elif p.suffix.lower() in extensions:
            if not p.exists():  # a clip named on the command line (or in a list): refused before any work
                raise UsdHandsError("no such file", path=p)
            if not p.is_file():  # a named pipe would block a worker forever, /dev/zero never end
                raise UsdHandsError("not a regular file", path=p)
            out.append((p, Path(p.name)))
        elif p.is_file():
            try:
                lines = p.read_text(encoding="utf-8").splitlines()
            except (OSError, UnicodeDecodeError) as e:
                raise UsdHandsError(f"cannot read the list of inputs: {e}", path=p) from None
            for n, line in enumerate(lines, 1):
                line = line.strip()
                if line and not line.startswith("#"):
                    listed = Path(line) if Path(line).is_absolute() else p.parent / line
                    if listed.suffix.lower() not in extensions and not listed.is_dir():
                        raise UsdHandsError(f"not an animation file or folder: {line}", path=p, location=f"line {n}")
                    out += collect_inputs([listed], extensions)
        else:
            raise UsdHandsError("no such file or folder" if not p.exists() else "not an animation file or a list",
                                path=p)
    seen, unique = set(), []
    for src, rel in out:
        key = src.resolve()
        if key not in seen:
            seen.add(key)
            unique.append((src, rel))
    return unique


def output_name(rel: Path, options: BatchOptions) -> Path:
    """Where under ``out`` the output of the clip at ``rel`` goes."""
    if options.job == "convert":
        return rel.with_suffix("." + options.to.lstrip(".").lower())
    if options.job == "check":
        return rel.with_name(rel.name + ".check.json")
    return rel


def _own_job(job: str) -> bool:
    """``package.module:function``: a pipeline's own job."""
    module, colon, function = job.partition(":")
    return bool(colon) and all(part.isidentifier() for part in module.split(".") + [function])


def _job_function(job: str):
    if job in JOBS:
        module, function, _ = JOBS[job]
        return getattr(importlib.import_module(f"usdhands.jobs.{module}"), function)
    module, _, function = job.partition(":")
    return getattr(importlib.import_module(module), function)


def _options_class(job: str):
    module, _, cls = JOBS[job]
    return getattr(importlib.import_module(f"usdhands.jobs.{module}"), cls)


def _options_json(options: BatchOptions, job_options) -> dict:
    values = dataclasses.asdict(job_options) if dataclasses.is_dataclass(job_options) else {}
    return json.loads(json.dumps({"job": options.job, "options": values, "to": options.to,
                                  "model": None if options.model is None else str(options.model)}, default=str))


def _record_options(out: Path, options: BatchOptions, job_options) -> float:
    """Write ``batch_options.json`` when the options differ from those recorded; its modification time."""
    path = out / OPTIONS_FILE
    current = _options_json(options, job_options)
    try:
        if json.loads(path.read_text()) == current:
            return path.stat().st_mtime
    except (OSError, ValueError):
        pass
    _write_json(path, current)
    return path.stat().st_mtime


def _side_inputs(options: BatchOptions, job_options) -> dict:
    """Every side file the batch's clips read, by option (None or () where not given)."""
    return {"--handmap": getattr(job_options, "handmap", None), "--config": getattr(job_options, "config", None),
            "--interaction-config": getattr(job_options, "interaction_config", None),
            "--model": options.model, "--props": tuple(getattr(job_options, "props", ()) or ()),
            "--db": getattr(job_options, "db", None)}


def check_side_files(inputs: dict, out: Path) -> None:
    """Refuse, before any clip runs, a side file every clip would fail on, and ``report.json`` or
    ``batch_options.json`` landing on a side file.

    What a side file is for is checked once here instead of once per clip: it must be a
    regular file (``--db`` a folder), JSON side files strict JSON valid under their schema
    (a hand map's joints are checked per clip, against each skeleton).

    Raises
    ------
    UsdHandsError
        One line naming the side file, or the batch's own file that would overwrite it.
    """
    from usdhands.errors import ConfigError, OutputPathError
    from usdhands.formats.registry import same_file
    from usdhands.input_files import check_regular_file, read_json
    from usdhands.jobs.outputs import check_paths, each_path

    check_paths(inputs)  # a named pipe or a device: refused before anything is opened
    for label, value in inputs.items():
        for path in each_path(value):
            for name in (REPORT_FILE, OPTIONS_FILE):
                if same_file(out / name, path):
                    raise OutputPathError(f"batch writes {name} over the {label} file; choose another --out folder",
                                          path=out / name)
            if label == "--db":
                if not path.is_dir():
                    raise ConfigError("no such finger database folder" if not path.exists() else
                                      "is a file, not a finger database (a folder made by 'usdhands db build')",
                                      path=path)
            elif label == "--props":
                check_regular_file(path, what="prop file")
            elif label == "--config":
                from usdhands.jobs.inputs import load_config

                load_config(path)
            elif label == "--interaction-config":
                from usdhands.algorithms.interaction.finger_geometry import load_interaction_config

                load_interaction_config(path)
            elif label == "--model":
                from usdhands.algorithms.reduction.model import ReductionModel

                ReductionModel.load(path)
            else:  # a hand map: its joints are checked against each clip's skeleton
                from usdhands.json_schemas import first_schema_error

                data = read_json(path, what="hand map file", error=ConfigError)
                error = first_schema_error(data, "handmap")
                if error is not None:
                    raise ConfigError(f"invalid hand map at {error[0]}: {error[1]}", path=path)


def _identity(path: Path) -> tuple[int, int] | None:
    """(device, inode) of an existing file, None for a missing one: hard links share it."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _side_files(options: BatchOptions, job_options) -> list[Path]:
    """Files besides the clip that every output depends on: the ``expand`` model, the props."""
    files = [Path(p) for p in getattr(job_options, "props", ())]
    return files + ([Path(options.model)] if options.model is not None else [])


def _up_to_date(src: Path, dst: Path, options_time: float, side_files: Sequence[Path] = ()) -> bool:
    try:
        made = dst.stat().st_mtime
        newest = max([src.stat().st_mtime, options_time] + [p.stat().st_mtime for p in side_files])
    except OSError:
        return False
    return made >= newest


def _write_json(path: Path, obj) -> None:
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    except OSError as e:  # a read-only folder: named, not the temporary file
        from usdhands.errors import OutputPathError

        raise OutputPathError(f"cannot write into folder {str(path.parent)!r}: {e.strerror}", path=path) from None
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(obj, f, indent=2)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


# ----------------------------------------------------------------------------- one clip, in a worker
#: True only in a worker process of its own (set by :func:`become_worker_process`), never in the caller's
_own_worker_process = False


def become_worker_process() -> None:
    """Mark this process as a batch worker of its own: its clips run numba's kernels on one thread.

    Called by the local pool's initializer (a fresh forkserver/spawn process) and by the Dask
    worker plugin when the worker is not in the caller's process; never in the caller's.
    """
    global _own_worker_process
    _own_worker_process = True
    _one_kernel_thread()


def _one_kernel_thread() -> None:
    """In a worker process of its own: this thread's kernels on one thread (numba's setting is per thread,
    and Dask runs tasks on threads of its own)."""
    if _own_worker_process:
        from usdhands.jit import set_kernel_threads

        set_kernel_threads(1)


def run_clip(job: str, job_options, model: Path | None, src: Path, dst: Path) -> ClipRecord:
    """Run one job on one clip in this process; never raises for a bad clip (a ``failed`` record)."""
    start = time.perf_counter()
    _one_kernel_thread()
    try:
        dst.parent.mkdir(parents=True, exist_ok=True)
        run = _job_function(job)
        error = None
        if job == "expand":
            run(src, model, dst, job_options)
        elif job == "check":
            result = run([src], job_options)
            _write_json(dst, result.to_json())
            bad = result.files[0]
            error = bad.error or (str(bad.findings[0]) if bad.findings else None)
        else:
            run(src, dst, job_options)
    except UsdHandsError as e:
        error = str(e)
    except Exception as e:  # a bug on one clip must not end the batch: recorded with its type
        error = f"{type(e).__name__}: {e}"
    seconds = time.perf_counter() - start
    return ClipRecord(str(src), str(dst), "failed" if error else "done", round(seconds, 4),
                      None if error is None else one_line(error))


#: Clips a synthesize worker must expect (its share of the batch) to load the search kernel while it
#: starts: numba's import and first kernel take ~0.5 s, the NumPy search ~28 ms more per bench clip
KERNEL_AT_START_CLIPS = 20


def _start_pool_worker(job: str, job_options, clips_each: int) -> None:
    """The local pool's initializer: runs in each fresh worker process only."""
    become_worker_process()
    _warm_worker(job, job_options, clips_each)


def _warm_worker(job: str, job_options, clips_each: int) -> None:
    """Worker start-up: import the job's module and load the database once; a worker process of
    its own that expects ``clips_each`` clips or more also loads synthesis's search kernel (the numba
    kernels it would otherwise load only after its first ~45 clips, searched in NumPy at 2.5 times
    the CPU; a worker of a few clips keeps to NumPy, as one ``usdhands synthesize`` does)."""
    with contextlib.suppress(ImportError, AttributeError):  # a failing import is each clip's error
        _job_function(job)
    if job == "synthesize":
        from usdhands.algorithms.synthesis.segment_cost import load_search_kernel
        from usdhands.jobs.inputs import cached_database

        with contextlib.suppress(UsdHandsError):
            cached_database(getattr(job_options, "db", None))
        # never in the caller's process; never where the kernels compiled ahead of time search
        if _own_worker_process and clips_each >= KERNEL_AT_START_CLIPS and not _synthesis_kernels_built():
            _one_kernel_thread()  # Dask warms its workers on another thread than their tasks'
            load_search_kernel()


#: The module the warm forkserver imports before it forks a worker (:func:`start_warm_forkserver`)
WARM_FORKSERVER_MODULE = "usdhands.jobs.batch_forkserver"


def wants_warm_forkserver(options: BatchOptions, clips: int | None = None, built: bool | None = None) -> bool:
    """Whether a batch forks its workers from the warm forkserver: it asked
    (:attr:`BatchOptions.warm_forkserver`), ``synthesize`` on the local pool or on a LocalCluster of
    worker processes, and either the kernels compiled ahead of time are built (the forkserver then
    loads no numba: any batch gains; decided before its inputs are listed, ``clips`` None) or,
    without them, ``clips`` reaches :data:`KERNEL_AT_START_CLIPS` a worker (a smaller batch would
    wait for numba's ~0.5 s start that its workers, searching in NumPy, never need). ``built``: whether
    those kernels were built, when known (else they are loaded to see)."""
    if not (options.warm_forkserver and options.job == "synthesize" and options.workers >= 1
            and (options.scheduler is None or (options.scheduler == "local" and options.dask_processes))):
        return False
    built = _synthesis_kernels_built() if built is None else built
    return built if clips is None else not built and clips >= KERNEL_AT_START_CLIPS * options.workers


def start_warm_forkserver_early(job: str, workers: int, scheduler: str | None) -> bool:
    """For a process that runs batch and nothing else (the command line, which then sets
    :attr:`BatchOptions.warm_forkserver`): :func:`start_warm_forkserver` as soon as the job, the
    workers and the scheduler are known, where :func:`run_batch` would start it before listing its
    inputs (:func:`wants_warm_forkserver`), the kernels compiled ahead of time guessed built from their
    files (:func:`usdhands.compiled.kernel_file_built`: nothing imported, NumPy neither). The warm
    forkserver then loads while the caller checks its side files and makes the job's options, which
    load NumPy (~45 ms); :func:`run_batch` finds it running. Whether it started."""
    from usdhands.compiled import kernel_file_built

    built = all(kernel_file_built(name) for name in _synthesis_kernel_modules())
    options = BatchOptions(job=job, out=Path(), workers=workers, scheduler=scheduler, warm_forkserver=True)
    return wants_warm_forkserver(options, built=built) and start_warm_forkserver(dask=scheduler is not None)


def _synthesis_kernel_modules() -> tuple[str, ...]:
    """The kernels compiled ahead of time that a synthesize worker runs (the interaction's are not among
    them: without those, its NumPy twins run, never numba), by their names under ``usdhands``."""
    from usdhands.compiled import KERNEL_MODULES

    return tuple(name for name in KERNEL_MODULES if not name.startswith("algorithms.interaction."))


def _synthesis_kernels_built() -> bool:
    """Whether the kernels of :func:`_synthesis_kernel_modules` were built (and load)."""
    from usdhands.compiled import kernel_module

    return all(kernel_module(name) is not None for name in _synthesis_kernel_modules())


def start_warm_forkserver(dask: bool = False) -> bool:
    """Start this process's multiprocessing forkserver now, preloading :data:`WARM_FORKSERVER_MODULE`
    (:func:`_warm_forkserver_process`) and, with ``dask``, Dask's ``distributed`` for the worker
    processes of a LocalCluster (:func:`_run_dask`); False where there is no forkserver (the pool spawns).

    The pool's workers then fork from a process that has imported synthesis and loaded its kernels
    (:func:`_warm_forkserver_process`), instead of each importing and loading them after it starts;
    the forkserver loads while the batch process lists its inputs and checks its outputs. A forkserver already
    running in this process keeps what it has (the workers then warm themselves, as without).
    The preload stays set for this process's forkserver: see :attr:`BatchOptions.warm_forkserver`.
    """
    import multiprocessing

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return False
    from multiprocessing import forkserver

    # __main__: multiprocessing's default
    forkserver.set_forkserver_preload(["__main__", *(["distributed"] if dask else []), WARM_FORKSERVER_MODULE])
    forkserver.ensure_running()
    return True


def _warm_forkserver_process() -> None:
    """The warm forkserver's preload: the synthesize job's modules, the bundled database and the
    kernels compiled ahead of time (:mod:`usdhands.compiled`), which the workers then run without
    numba. Where those were not built: numba and one serial kernel of synthesis instead (numba's
    import and CPU target: ~0.5 s once instead of in each worker); numba's threads are not started
    here (the parallel search kernel is not loaded): a process forked after they started would have
    none; each worker starts its own, one kernel thread, and loads the search kernel
    (:func:`_warm_worker`). Never raises (a forkserver whose preload failed would start no worker):
    what failed is loaded again by each worker.

    With Dask loaded (the preload of a LocalCluster's forkserver), the processor's name that each worker
    reports when it registers (``platform.uname().processor``: ``uname -p`` run once a process, ~8 ms) is
    asked on a thread of its own while the rest loads, and kept for the workers forked after.

    At its exit the forkserver ends at once, its streams flushed (:func:`_end_at_once_at_exit`).
    """
    import sys
    import threading

    asking = None
    if "distributed" in sys.modules:
        thread = threading.Thread(target=_warm_scheduler_versions, daemon=True)
        with contextlib.suppress(RuntimeError):  # no thread to be had: each worker asks for itself
            thread.start()
            asking = thread
    with contextlib.suppress(Exception):
        import numpy as np

        from usdhands.algorithms.synthesis.output_warp import limit_steps_fast
        from usdhands.jobs.inputs import cached_database
        from usdhands.jobs.synthesis import import_what_a_clip_needs

        _job_function("synthesize")
        cached_database(None)
        import_what_a_clip_needs()  # the kernels compiled ahead of time among them
        if not _synthesis_kernels_built():  # else the workers run those: no numba
            limit_steps_fast(np.zeros((2, 1)), np.zeros(1))
    if asking is not None:
        asking.join()  # no thread left running when the forkserver forks
    _end_at_once_at_exit()


def _end_at_once_at_exit() -> None:
    """The warm forkserver's exit (when the batch process has exited): its standard streams flushed,
    it ends at once (``os._exit(0)``), before its other exit handlers and Python's teardown of the
    modules it loaded (``distributed``, NumPy, synthesis: ~14 ms, measured), during which it still
    held the batch's stderr, which whoever reads that waits to be closed. A process that only forks
    needs neither (no thread, no file of its own, no child it waits for; nobody reads its exit status).
    """
    import atexit
    import sys

    def end() -> None:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(0)

    atexit.register(end)  # exit handlers run last-registered first


def freeze_at_exit() -> None:
    """At this process's exit, before the other exit handlers, move every object out of the garbage
    collector's reach (``gc.freeze``): Python's exit then skips its last collections over them.

    With numba and a kernel loaded those took ~0.3 s of a 0.32 s exit (0.04 s frozen), during
    which a batch's forkserver or Dask worker still held the batch's stderr, or its nanny waited.
    The exit is otherwise Python's own: exit handlers, streams flushed, the exit status kept.
    For processes batch starts (the warm forkserver, a LocalCluster's workers), never the caller's.
    """
    import atexit
    import gc

    atexit.register(gc.freeze)  # exit handlers run last-registered first


# ----------------------------------------------------------------------------- local process pool
def _run_local(todo, task, workers: int, report) -> None:
    job, job_options, model = task
    broken = []
    with _pool(workers, job, job_options, -(-len(todo) // workers)) as pool:
        pending = {pool.submit(run_clip, job, job_options, model, src, dst): (src, dst) for src, dst in todo}
        for f in as_completed(pending):  # one waiter on every future, where wait() put one on each clip's turn
            try:
                report(f.result())
            except BrokenProcessPool:
                broken.append(pending[f])
    if broken:
        _retry_alone(broken, task, workers, report)


def _retry_alone(clips, task, workers: int, report) -> None:
    """The clips a dead worker took down, retried once, each alone in a process of its own.

    A dead worker breaks the whole pool, so the clip that killed it cannot be told from the
    others in flight. Here up to ``workers`` single-process pools run one clip at a time: a
    clip that kills its process again is the one at fault and fails; only that pool is
    replaced.
    """
    job, job_options, model = task
    queue = list(clips)
    slots: dict = {}  # future -> (pool, src, dst)
    idle: list = []
    try:
        while queue or slots:
            while queue and len(slots) < workers:
                src, dst = queue.pop(0)
                pool = idle.pop() if idle else _pool(1, job, job_options)
                slots[pool.submit(run_clip, job, job_options, model, src, dst)] = (pool, src, dst)
            done, _ = wait(slots, return_when=FIRST_COMPLETED)
            for f in done:
                pool, src, dst = slots.pop(f)
                try:
                    report(f.result())
                    idle.append(pool)
                except BrokenProcessPool:
                    pool.shutdown(wait=False)
                    report(ClipRecord(str(src), str(dst), "failed", 0.0,
                                      "the worker process died on this clip (retried once, alone)"))
    finally:
        for pool, _, _ in slots.values():
            pool.shutdown(wait=False, cancel_futures=True)
        for pool in idle:
            pool.shutdown(wait=True)


def _pool(workers: int, job: str, job_options, clips_each: int = 1) -> ProcessPoolExecutor:
    """``workers`` fresh worker processes for ``job``, each expecting ``clips_each`` clips (:func:`_warm_worker`)."""
    import multiprocessing

    # forkserver/spawn: a fresh interpreter per worker (fork would copy the parent's threads and locks)
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context(method),
                               initializer=_start_pool_worker, initargs=(job, job_options, clips_each))


# ----------------------------------------------------------------------------- Dask
def _run_dask(todo, task, options: BatchOptions, report, warm: bool = False) -> None:
    """The clips on a Dask cluster; ``warm``: this process's warm forkserver runs, with Dask loaded, and a
    LocalCluster's nannies fork their worker processes from it (``multiprocessing-method``: forkserver)
    instead of spawning interpreters that import Dask, then synthesis and numba (restarted workers spawn)."""
    try:
        import dask
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise UsdHandsError("--scheduler needs Dask: pip install 'usdhands[dask]'") from None
    from usdhands.jobs.dask_worker import OwnProcessWorker

    job, job_options, model = task
    with contextlib.ExitStack() as stack:
        if options.scheduler == "local":
            # a worker that dies is retried once by the scheduler (a remote one: its own
            # distributed.scheduler.allowed-failures); one task at a time per worker thread, so a
            # death counts against the task that caused it and no other; QUIET_LOCAL_CLUSTER. Dask
            # reads these when the scheduler, the nannies and the workers are made (a nanny hands
            # them to the worker processes it starts and restarts): the caller's config holds them
            # only while the cluster is made, never while the batch runs
            # Its nannies, objects of this process, put their worker's environment into this process's
            # os.environ before they start (and restart) a worker process (Dask's pre-spawn-environ and
            # PYTHONHASHSEED): the caller's environment is given back when the cluster has closed
            stack.enter_context(_environ_kept())
            forked = {"distributed.worker.multiprocessing-method": "forkserver"} if warm else {}
            slots = options.workers  # one thread each
            # each worker sets itself up and warms (the plugin) before it registers, so the first task
            # waits for no round trip to the workers; a worker the nanny restarts does the same
            plugin = OwnProcessWorker(freeze_at_exit=True, warm=(job, job_options, -(-len(todo) // slots)))
            _warm_scheduler_versions()
            with dask.config.set({"distributed.scheduler.allowed-failures": 1,
                                  "distributed.scheduler.worker-saturation": 1.0, **QUIET_LOCAL_CLUSTER,
                                  "distributed.nanny.pre-spawn-environ": worker_environ(), **forked}), \
                    _nannies_look_often():
                # the scheduler first, then the client and the first tasks, then the workers: each worker's
                # first task is sent when it registers, with no round trip left to the client
                cluster = stack.enter_context(LocalCluster(
                    n_workers=0, threads_per_worker=1, processes=options.dask_processes, dashboard_address=None,
                    plugins=(plugin,)))
                client = stack.enter_context(Client(cluster))
                feed = _TaskFeed(client, todo, task, slots)
                cluster.scale(options.workers)
                correct = getattr(cluster, SPEC_CLUSTER_START_WAIT, None)  # private in distributed: optional
                if correct is not None:
                    cluster.sync(correct)  # the workers started (raises as LocalCluster(n_workers) does)
                else:
                    client.wait_for_workers(options.workers, timeout=LOCAL_WORKERS_START_S)
        else:
            try:
                client = stack.enter_context(Client(options.scheduler, timeout="10s"))
            except (OSError, TimeoutError) as e:
                raise UsdHandsError(f"cannot reach the Dask scheduler {options.scheduler}: {e}") from None
            slots = sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()) or 1
            # every worker (and any that joins later) sets itself up and warms before the first task
            client.register_plugin(OwnProcessWorker(warm=(job, job_options, -(-len(todo) // slots))))
            feed = _TaskFeed(client, todo, task, slots)
        alone = []
        for future in feed:
            chunk = feed.chunks[future]
            try:
                records = future.result()
            except Exception as e:  # KilledWorker and the like: the task took its worker down twice
                if len(chunk) > 1:  # which clip did it is not known: each is retried alone
                    alone.extend(chunk)
                else:
                    src, dst = chunk[0]
                    report(ClipRecord(str(src), str(dst), "failed", 0.0, one_line(f"{type(e).__name__}: {e}")))
                feed.done()
                continue
            feed.done(records)
            for record in records:
                report(record)
        if alone:
            futures = {client.submit(run_clips, job, job_options, model, [pair], pure=False): [pair] for pair in alone}
            for future in as_completed(futures):
                ((src, dst),) = futures[future]
                try:
                    report(future.result()[0])
                except Exception as e:
                    report(ClipRecord(str(src), str(dst), "failed", 0.0, one_line(f"{type(e).__name__}: {e}")))


#: The Dask settings of the LocalCluster batch starts (``--scheduler local``). With Dask's defaults
#: its machinery took ~7 ms of CPU per 20-40 ms clip (CPU of every thread of every process, sampled
#: between the 20th and the 180th of 200 clips): a fifth of a core on two workers, which two cores
#: cannot spare. What a batch never looks at goes: the statistical profiler (every 10 ms it walked
#: the clip's stack in the worker's event loop), the event loop's health tick (every 20 ms in the
#: scheduler, each nanny and each worker), the system monitor (twice a second, each of them); the
#: memory monitor (nanny and worker, ten times a second) looks once a second.
QUIET_LOCAL_CLUSTER = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
}

def worker_environ() -> dict:
    """The environment batch's LocalCluster gives its worker processes: Dask's own
    (``distributed.nanny.pre-spawn-environ``: one BLAS thread...) without ``MALLOC_TRIM_THRESHOLD_``.

    Dask sets that to 64 KiB so that a worker hands freed memory back to the system at once,
    which also fixes glibc's mmap threshold at 128 KiB: every larger array a clip makes is then
    new pages from the system, zeroed for it. A synthesized clip of bench_batch took ~2,900 page
    faults instead of ~8, and 26.6 instead of 21.3 ms of CPU (the same loop in one process, with
    and without the variable). A batch worker holds a clip at a time, a few hundred MB at most.
    """
    import dask

    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", default={}) or {})
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    return environ


@contextlib.contextmanager
def _environ_kept():
    """``os.environ`` as it was on entry, again on exit (what was added removed, what was changed set back)."""
    saved = dict(os.environ)
    try:
        yield
    finally:
        for key in set(os.environ) - set(saved):
            del os.environ[key]
        for key, value in saved.items():
            if os.environ.get(key) != value:
                os.environ[key] = value


#: How often (seconds) a LocalCluster's nanny looks whether the worker process it started is up, while batch
#: makes the cluster (Dask's ``WorkerProcess._init_msg_interval``, 0.05 s: ~25 ms of each start waited for
#: nothing, up to 50 ms); a worker the nanny restarts later is looked for at Dask's pace
NANNY_LOOK_INTERVAL = 0.005


@contextlib.contextmanager
def _nannies_look_often():
    """:data:`NANNY_LOOK_INTERVAL` for the nannies started inside (Dask's own interval again on exit)."""
    try:
        from distributed.nanny import WorkerProcess
    except ImportError:  # pragma: no cover - a Dask without it
        yield
        return
    own = "_init_msg_interval" in WorkerProcess.__dict__
    before = WorkerProcess.__dict__.get("_init_msg_interval")
    WorkerProcess._init_msg_interval = NANNY_LOOK_INTERVAL
    try:
        yield
    finally:
        if own:
            WorkerProcess._init_msg_interval = before
        else:
            del WorkerProcess._init_msg_interval


def _warm_scheduler_versions() -> None:
    """Ask the platform for what Dask reports of this machine when a worker registers
    (``platform.uname().processor`` runs ``uname -p`` once a process, then keeps it): in the batch process
    while the worker processes start, not while the first one waits for the scheduler's answer; in the
    warm forkserver (:func:`_warm_forkserver_process`) for the worker processes it forks."""
    import platform

    with contextlib.suppress(Exception):
        platform.uname().processor


#: The private method of distributed's ``SpecCluster`` that a LocalCluster's start waits on (raising what a
#: worker's start raised); a batch that queues its tasks before its local workers start waits on it too
SPEC_CLUSTER_START_WAIT = "_correct_state"
#: Where distributed has no such method: how long a batch waits for its local workers to register (by the
#: public ``Client.wait_for_workers``) before it fails
LOCAL_WORKERS_START_S = 120.0
#: How long a Dask task aims to run, in its clips' measured seconds. Each task costs ~6 ms of CPU
#: besides its clips, half in the caller's process (the scheduler's and the client's messages, its
#: result fetched), half in the worker's event loop, and the worker waits ~3 ms between two tasks; on
#: two workers with two cores, that CPU is taken from the clips. bench_batch, between its 10% and 90%
#: marks: tasks of 8 clips (~90 ms) 0.8 ms of that CPU a clip, 6% of the clips' own; tasks of a quarter
#: of a second 0.3-0.4 ms, 3%. The progress still moves every few tenths of a second with two workers,
#: whatever the clips' length
DASK_TASK_SECONDS = 0.25
#: The clips of each first task, before any clip of the batch was measured (the worker's first clip
#: also pays its warm-up)
DASK_FIRST_TASK_CLIPS = 2


def dask_task_size(left: int, slots: int, clip_seconds: float | None) -> int:
    """How many of the ``left`` clips the next Dask task takes, for ``slots`` worker threads; ``clip_seconds``:
    the mean seconds of the batch's clips measured so far (None: none yet).

    About :data:`DASK_TASK_SECONDS` of clips (:data:`DASK_FIRST_TASK_CLIPS` before any was measured),
    at most half a thread's share of the clips left (not yet submitted), at least one: a long batch of
    short clips runs in tasks of a quarter of a second, then shorter ones down to one clip at its end,
    so that the workers finish together; a clip of a quarter of a second or more is a task of its own;
    a short batch is one or two clips per task.
    """
    most = left // (2 * max(1, slots))
    aimed = DASK_FIRST_TASK_CLIPS if clip_seconds is None else int(DASK_TASK_SECONDS / max(clip_seconds, 1e-4))
    return max(1, min(most, aimed))


class _TaskFeed:
    """A batch's clips, in order, as Dask tasks of :func:`run_clips` sized by :func:`dask_task_size`,
    with ``2 * slots`` of them submitted and unfinished at a time: one running on each worker thread
    and one waiting for each in the scheduler, so that a worker that finishes a task starts the next
    without a round trip to this process.

    Iterate for the tasks' futures as they finish; :meth:`done` (with the finished task's records)
    measures their clips and submits the next task. ``chunks``: future -> its (source, output) pairs.
    """

    def __init__(self, client, todo: list, task: tuple, slots: int) -> None:
        from distributed import as_completed

        self.client, self.todo, self.task, self.slots = client, todo, task, slots
        self.chunks: dict = {}
        self.next = 0  # the first clip not submitted
        self.seconds, self.clips = 0.0, 0  # measured
        self.finished = as_completed(loop=client.loop)
        for _ in range(2 * slots):
            self._submit()

    def _submit(self) -> None:
        left = len(self.todo) - self.next
        if left <= 0:
            return
        size = dask_task_size(left, self.slots, self.seconds / self.clips if self.clips else None)
        chunk = self.todo[self.next:self.next + size]
        self.next += size
        job, job_options, model = self.task
        future = self.client.submit(run_clips, job, job_options, model, chunk, pure=False)
        self.chunks[future] = chunk
        self.finished.add(future)

    def __iter__(self):
        return iter(self.finished)

    def done(self, records: Sequence[ClipRecord] = ()) -> None:
        """A task finished: its ``records`` measured (none for a task that failed), the next task submitted."""
        for record in records:
            self.seconds += record.seconds
            self.clips += 1
        self._submit()


def run_clips(job: str, job_options, model: Path | None, pairs) -> list[ClipRecord]:
    """:func:`run_clip` on each (source, output) pair of ``pairs``, in order (one Dask task)."""
    return [run_clip(job, job_options, model, src, dst) for src, dst in pairs]

"""``usdhands batch INPUTS... --job JOB --out DIR [job options] [--workers N] [--scheduler ADDRESS]``.

Runs one job over many clips on a local process pool, or on a Dask cluster with
``--scheduler tcp://HOST:8786`` (an existing scheduler) or ``--scheduler local`` (a
``LocalCluster``). Resumable; a failing clip is recorded in ``DIR/report.json`` and the
others go on. See :mod:`usdhands.jobs.batch`.
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time
from pathlib import Path

from usdhands.commands._common import add_prop_arguments, print_json, print_table

BATCH_JOBS = ("synthesize", "correct", "reduce", "expand", "convert", "check")
#: the prop options (:func:`add_prop_arguments`)
PROP_FLAGS = ("--props", "--margin", "--self", "--attach", "--prop-units", "--prop-up", "--interaction-config")
#: job -> the job options it reads; any other job option is refused (it would do nothing)
JOB_FLAGS = {
    "synthesize": ("--animation", "--handmap", "--hands", "--db", "--k", "--config", "--finger-reference",
                   *PROP_FLAGS),
    "correct": ("--animation", "--handmap", *PROP_FLAGS),
    "reduce": ("--animation", "--handmap", "--hands", "--steps"),
    "expand": ("--animation", "--model"),
    "convert": ("--animation", "--to", "--fps", "--bvh-units"),
    "check": ("--require-provenance", "--tolerance", *(f for f in PROP_FLAGS if f != "--margin")),
}


def register(sub) -> None:
    p = sub.add_parser("batch", help="run a job over many clips (local process pool or a Dask cluster)",
                       description="Run synthesize, correct, reduce, expand, convert or check over files, folders "
                                   "(recursive) or text files listing paths; outputs under --out at the same "
                                   "relative paths. Outputs newer than their input and the options are skipped; "
                                   "failures are recorded in OUT/report.json and do not stop the others.")
    p.add_argument("inputs", type=Path, nargs="+", metavar="INPUT", help="files, folders or lists of paths")
    p.add_argument("--job", required=True, choices=BATCH_JOBS, help="the job to run on every clip")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: the CPU count)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="send the clips to Dask: a scheduler address (tcp://host:8786) or 'local' for a "
                        "LocalCluster (pip install 'usdhands[dask]')")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    g = p.add_argument_group("job options")
    g.add_argument("--animation", default=None, help="animation name or index (default the first)")
    g.add_argument("--handmap", type=Path, default=None, help="synthesize, correct, reduce: hand map JSON")
    g.add_argument("--hands", default=None, help="synthesize, reduce: left, right or left,right")
    g.add_argument("--db", type=Path, default=None, help="synthesize: database folder (default: bundled)")
    g.add_argument("--k", type=int, default=None, help="synthesize: candidates per segment")
    g.add_argument("--config", type=Path, default=None, help="synthesize: configuration JSON")
    g.add_argument("--finger-reference", choices=("rest", "input"), default="rest", help="synthesize")
    g.add_argument("--steps", default=None, help="reduce: the reduction steps (default as 'usdhands reduce')")
    g.add_argument("--model", type=Path, default=None, help="expand: reduction model JSON")
    g.add_argument("--to", default=None, metavar="EXT", help="convert: output extension (usda, glb, bvh, ...)")
    g.add_argument("--fps", type=float, default=None, help="convert: resample to this rate")
    g.add_argument("--bvh-units", default="cm", help="convert: unit of BVH numbers (default cm)")
    g.add_argument("--require-provenance", action="store_true", help="check: finger motion must record provenance")
    add_prop_arguments(g, required=False)
    g.add_argument("--tolerance", type=float, default=0.5, metavar="MM",
                   help="check with --props: the deepest finger penetration let through, millimetres (default 0.5)")
    # a job option left out is missing from the parsed arguments (run() fills in its default), so
    # one given at its default value is still seen as given
    defaults = {}
    for action in g._group_actions:
        defaults[action.dest] = (action.option_strings[-1], action.default)
        action.default = argparse.SUPPRESS
    p.set_defaults(func=run, job_option_defaults=defaults)


def job_options(args):
    """The job's options dataclass from the parsed arguments."""
    from usdhands.jobs.option_checks import parse_list
    from usdhands.model.handmap import SIDES

    hands = tuple(parse_list(args.hands, SIDES))
    if args.job == "synthesize":
        from usdhands.jobs.synthesis import SynthesizeOptions

        return SynthesizeOptions(db=args.db, k=args.k, hands=hands, config=args.config, handmap=args.handmap,
                                 animation=args.animation, finger_reference=args.finger_reference,
                                 margin=args.margin, **_prop_options(args))
    if args.job == "reduce":
        from usdhands.jobs.reduction import ReduceOptions

        extra = {"steps": args.steps} if args.steps else {}
        return ReduceOptions(hands=hands, animation=args.animation, handmap=args.handmap, **extra)
    if args.job == "expand":
        from usdhands.jobs.expansion import ExpandOptions

        return ExpandOptions(animation=args.animation)
    if args.job == "convert":
        from usdhands.jobs.conversion import ConvertOptions

        return ConvertOptions(animation=args.animation, fps=args.fps, bvh_units=args.bvh_units)
    if args.job == "correct":
        from usdhands.jobs.correction import CorrectOptions

        return CorrectOptions(margin=args.margin, handmap=args.handmap, animation=args.animation,
                              **_prop_options(args))
    from usdhands.jobs.validation import CheckOptions

    return CheckOptions(require_provenance=args.require_provenance, penetration_tolerance_mm=args.tolerance,
                        **_prop_options(args))


def _prop_options(args) -> dict:
    """The prop options every job with props shares (synthesize, correct, check)."""
    return {"props": tuple(args.props), "attach": tuple(args.attach), "prop_units": args.prop_units,
            "prop_up": args.prop_up, "self_collision": args.self_collision,
            "interaction_config": args.interaction_config}


def _job_options_given(args) -> list[str]:
    """The job options given on the command line (in the parser's order); fills in the others' defaults."""
    given = []
    for dest, (flag, default) in args.job_option_defaults.items():
        if hasattr(args, dest):
            given.append(flag)
        else:
            setattr(args, dest, copy.copy(default))
    return given


def run(args) -> int:
    from usdhands.errors import UsdHandsError
    from usdhands.jobs.batch import BatchOptions, check_side_files, run_batch, start_warm_forkserver_early

    for flag in _job_options_given(args):
        if flag not in JOB_FLAGS[args.job]:
            raise UsdHandsError(f"{flag} is not an option of --job {args.job}")
    workers = args.workers or os.cpu_count() or 1
    # the workers' forkserver loads while the side files are checked and the options made (NumPy)
    start_warm_forkserver_early(args.job, workers, args.scheduler)
    # every side file given (the job reads each: the others were refused above) is checked before any clip runs
    check_side_files({"--handmap": args.handmap, "--config": args.config, "--model": args.model,
                      "--interaction-config": args.interaction_config, "--props": args.props, "--db": args.db},
                     args.out)
    options = BatchOptions(job=args.job, out=args.out, job_options=job_options(args),
                           workers=workers, scheduler=args.scheduler, to=args.to,
                           model=args.model, warm_forkserver=True)
    bar = _progress_bar(args.job)
    try:
        report = run_batch(args.inputs, options, progress=bar)
    finally:
        bar.close()
    if args.json:
        print_json(report.to_json())
    else:
        rows = [(Path(c.file).name, c.status, f"{c.seconds:.2f}", c.error or "") for c in report.clips
                if c.status != "skipped" or len(report.clips) <= 50]
        print_table(rows, ["file", "status", "seconds", "error"])
        s = report.summary
        print(f"{s['done']} done, {s['skipped']} skipped, {s['failed']} failed in {s['seconds']:.1f} s "
              f"({s['clips_per_second']:.2f} clips/s, {report.workers} worker(s)"
              f"{', Dask ' + report.scheduler if report.scheduler else ''}); report: {args.out / 'report.json'}")
    return 1 if report.count("failed") else 0


class _progress_bar:
    """``progress(finished, total, failed, what)`` drawn with tqdm on a terminal (a line per 10% otherwise)."""

    def __init__(self, label: str):
        self.label = label
        self.bar = None
        self.start = time.perf_counter()
        self.shown = -1

    def __call__(self, finished: int, total: int, failed: int, what: str) -> None:
        if sys.stderr.isatty():
            try:
                from tqdm import tqdm
            except ImportError:
                tqdm = None
            if tqdm is not None:
                if self.bar is None:
                    self.bar = tqdm(total=total, desc=self.label, unit="clip", file=sys.stderr)
                self.bar.set_postfix(failed=failed, refresh=False)
                self.bar.update(finished - self.bar.n)
                return
        step = max(total // 10, 1)
        if finished // step != self.shown or finished == total:
            self.shown = finished // step
            rate = finished / max(time.perf_counter() - self.start, 1e-9)
            print(f"{self.label}: {finished}/{total} done, {failed} failed, {rate:.2f} clips/s", file=sys.stderr)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()

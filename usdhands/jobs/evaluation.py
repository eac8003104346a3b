"""The evaluate job: how well body motion predicts finger motion (Jörg, Hodgins, Safonova 2012, section 4).

Three analyses over clips (files or the generated gesture set):

- leave-one-out (the default; needs labels): for each predictor, the share of the k closest
  segments (DTW-aligned squared differences) that come from a clip of the same label, and
  the confusion matrix of ``wrist_pos+0.5rot`` (P + 0.5·R);
- ``holdout``: every clip's fingers synthesized from the others, the finger-angle error next
  to three baselines;
- ``folds=K``: k-fold held-out synthesis (windows of each take held out against the rest)
  against five baselines, and the feature sets behind the segment cost compared on the same
  folds.

::

    import usdhands
    from usdhands.jobs.evaluation import EvaluateOptions, evaluate

    result = evaluate(["takes/"], EvaluateOptions(labels=r"^([a-z]+)_"))
    print(result.report["predictors"]["wrist_pos+0.5rot"], result.report["best"])
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from usdhands.errors import UsdHandsError

ProgressCallback = Callable[[int, int, str], None]

#: The PNGs ``--plot`` may write (leave-one-out's pair, then k-fold's).
PLOT_FILES = ("predictors.png", "confusion.png", "kfold_errors.png", "kfold_worst_window.png")


@dataclass(frozen=True)
class EvaluateOptions:
    """Options of :func:`evaluate`; the defaults are the command line's.

    Attributes
    ----------
    labels : str or None
        Label of a clip: the first group of this regular expression searched in its file name.
    labels_file : Path or None
        CSV with rows ``file,label``.
    k : int or None
        Neighbours per segment (leave-one-out, default 5); candidates per segment for
        ``holdout`` and ``folds`` (default the configuration's, 5).
    predictors : tuple of str or None
        Predictors to compare (``wrist_rot``, ``wrist_pos+0.5rot``, ...); None: the default
        list, less those the hand maps lack the joints for.
    holdout : bool
        Held-out synthesis of every clip against baselines instead of leave-one-out.
    folds : int or None
        k-fold held-out synthesis with this many folds (at least 2).
    feature_sets : tuple of str or None
        With ``folds``: feature sets behind the segment cost to compare.
    keep_rest : bool
        Leave-one-out: keep each hand's rest at both ends of a take (default: trimmed).
    samples : bool
        Use the generated gesture set instead of files.
    fps : float or None
        Resample clips to this rate (default the first clip's; 30 for ``holdout`` and ``folds``).
    config, handmap : Path or None
        Synthesis configuration JSON; hand map JSON overriding detection (all inputs).
    animation : str or None
        Animation name or index in each file.
    seed : int
        Seed of the random-segments baseline.
    plot : Path or None
        Folder to write the PNG figures into (leave-one-out and ``folds``).
    """

    labels: str | None = None
    labels_file: Path | None = None
    k: int | None = None
    predictors: tuple[str, ...] | None = None
    holdout: bool = False
    folds: int | None = None
    feature_sets: tuple[str, ...] | None = None
    keep_rest: bool = False
    samples: bool = False
    fps: float | None = None
    config: Path | None = None
    handmap: Path | None = None
    animation: str | None = None
    seed: int = 0
    plot: Path | None = None


@dataclass(frozen=True)
class EvaluateResult:
    """What :func:`evaluate` found.

    Attributes
    ----------
    analysis : str
        ``"leave-one-out"``, ``"holdout"`` or ``"folds"``.
    report : dict
        The analysis's figures (see :func:`usdhands.algorithms.synthesis.evaluation.evaluate_predictors`,
        ``holdout_evaluation`` and :func:`usdhands.algorithms.synthesis.kfold.kfold_evaluation`).
    clips : int
        Clips evaluated.
    plots : tuple of Path
        PNGs written with ``plot``.
    warnings : tuple of str
        Things the caller should know (clips whose fingers never move).
    """

    analysis: str
    report: dict
    clips: int
    plots: tuple[Path, ...] = ()
    warnings: tuple[str, ...] = field(default=())

    def to_json(self) -> dict:
        """The ``usdhands evaluate --json`` report."""
        out = dict(self.report)
        if self.plots:
            out["plots"] = [str(p) for p in self.plots]
        return out


def evaluate(inputs: Sequence[str | os.PathLike], options: EvaluateOptions = EvaluateOptions(),
             progress: ProgressCallback | None = None) -> EvaluateResult:
    """Run the leave-one-out analysis (or ``holdout`` / ``folds``) on the clips of ``inputs``.

    Parameters
    ----------
    inputs : paths
        Animation files or folders (empty with ``options.samples``).
    options : EvaluateOptions
    progress : callable, optional
        ``progress(done, total, what)``.

    Raises
    ------
    UsdHandsError
        Bad options, unreadable inputs, clips without labels (leave-one-out) or without
        finger motion (``holdout``, ``folds``).
    """
    from usdhands.algorithms.synthesis.evaluation import DEFAULT_PREDICTORS, parse_predictor
    from usdhands.algorithms.synthesis.kfold import parse_feature_set
    from usdhands.jobs.inputs import check_plot_folder, load_config
    from usdhands.jobs.option_checks import check_fps, check_seed
    from usdhands.jobs.outputs import MAIN_INPUT, check_paths

    inputs = [Path(p) for p in inputs]
    progress = progress or _no_progress
    check_fps(options.fps)
    check_seed(options.seed)
    named_inputs = {MAIN_INPUT: inputs, "--labels-file": options.labels_file, "--config": options.config,
                    "--handmap": options.handmap}
    check_paths(named_inputs)
    if options.k is not None and options.k < 1:
        raise UsdHandsError(f"--k must be at least 1, got {options.k}")
    check_plot_folder(options.plot, PLOT_FILES, named_inputs)
    cfg = load_config(options.config)
    predictors = list(options.predictors or ()) or list(DEFAULT_PREDICTORS)
    for name in predictors:
        try:
            parse_predictor(name)
        except ValueError as e:
            raise UsdHandsError(str(e)) from None
    if options.folds is not None:
        if options.folds < 2:
            raise UsdHandsError(f"--folds must be at least 2, got {options.folds}")
        if options.holdout:
            raise UsdHandsError("give --holdout or --folds, not both")
    elif options.feature_sets is not None:
        raise UsdHandsError("--feature-sets needs --folds K")
    feature_sets = list(options.feature_sets or ())
    for name in feature_sets:
        try:
            parse_feature_set(name)
        except ValueError as e:
            raise UsdHandsError(str(e)) from None
    items = _items(inputs, options, progress)
    if options.folds is not None or options.holdout:
        if options.k is not None:
            cfg = cfg.with_values(segment_cost={"k": options.k})
        flag = "--folds" if options.folds is not None else "--holdout"
        warnings: list[str] = []
        dbitems = _database_items(items, flag, warnings)
        if options.folds is not None:
            return _folds(options, dbitems, cfg, feature_sets, len(items), warnings, progress)
        return _holdout(options, dbitems, cfg, len(items), warnings, progress)
    return _leave_one_out(options, items, cfg, predictors, progress)


def _no_progress(done: int, total: int, what: str = "") -> None:
    pass


def _items(inputs, options: EvaluateOptions, progress):
    """``(path, label, clip, handmap)`` for every clip evaluated."""
    from usdhands.jobs.inputs import expand_inputs, labeller, read_labelled, sample_database_items, stage_progress

    if options.samples:
        if inputs:
            raise UsdHandsError("give input files or --samples, not both")
        return [(it.source, it.label, it.clip, it.handmap) for it in sample_database_items()]
    if not inputs:
        raise UsdHandsError("no input files given (or use --samples)")
    paths = expand_inputs(inputs)
    synth = options.holdout or options.folds is not None
    if not synth and not (options.labels or options.labels_file):
        raise UsdHandsError("evaluate needs --labels REGEX or --labels-file CSV (or --holdout, --folds K)")
    return read_labelled(paths, labeller(options.labels, options.labels_file), options.fps, options.handmap,
                         options.animation, stage_progress(progress, "reading"), fingerless=not synth)


def _leave_one_out(options: EvaluateOptions, items, cfg, predictors, progress) -> EvaluateResult:
    from usdhands.algorithms.synthesis.evaluation import evaluate_predictors, prepare_eval_set
    from usdhands.jobs.inputs import stage_progress

    k = 5 if options.k is None else options.k
    unlabeled = [str(p) for p, lab, _, _ in items if lab is None]
    if unlabeled:
        raise UsdHandsError(f"clips without a label: {unlabeled[:3]}")
    if len(items) < 2:
        raise UsdHandsError("leave-one-out needs at least two clips")
    if len({lab for _, lab, _, _ in items}) < 2:
        raise UsdHandsError(f"leave-one-out needs at least two labels; every clip is {items[0][1]!r}")
    left_out = []
    if options.predictors is None:  # the default list: leave out what these rigs cannot answer
        predictors, left_out = _answerable(predictors, items)
    try:
        es = prepare_eval_set([(lab, clip, hm) for _, lab, clip, hm in items], cfg, options.fps,
                              predictors=predictors, trim_rest=not options.keep_rest)
        result = evaluate_predictors(es, predictors, k, cfg, progress=stage_progress(progress, "leave-one-out"))
    except ValueError as e:
        raise UsdHandsError(str(e)) from None
    result["idle_hands"] = [f"{c}:{s}" for c, s in es.idle]
    if left_out:
        result["left_out_predictors"] = left_out
    plots = []
    if options.plot is not None:
        from usdhands.jobs.plots.synthesis import plot_confusion, plot_predictors

        plots = _write_plots(options.plot, [(lambda p: plot_predictors(result, p), "predictors.png"),
                                            (lambda p: plot_confusion(result, p), "confusion.png")])
    return EvaluateResult("leave-one-out", result, len(items), tuple(plots))


def _answerable(predictors, items):
    """Split predictors into those every hand map has the joints for and the others."""
    from usdhands.algorithms.synthesis.evaluation import parse_predictor

    have = {"wrist", "elbow", "shoulder"}
    for _, _, _, handmap in items:
        for hand in handmap.sides:
            have &= {"wrist"} | ({"elbow"} if hand.forearm else set()) | ({"shoulder"} if hand.shoulder else set())
    keep = [p for p in predictors if all(key.split("_")[0] in have for key, _ in parse_predictor(p))]
    return keep, [p for p in predictors if p not in keep]


def _database_items(items, flag: str, warnings: list) -> list:
    """The clips as database items, refusing clips without fingers; a warning for still ones."""
    from usdhands.algorithms.synthesis.database import DatabaseClip
    from usdhands.jobs.inputs import still_hands

    dbitems = []
    for p, lab, clip, hm in items:
        if not any(h.finger_joints for h in hm.sides):
            raise UsdHandsError(f"no finger joints: {flag} needs clips with finger animation", path=p)
        dbitems.append(DatabaseClip(clip, hm, lab, str(p)))
    if len(dbitems) < 2 and flag == "--holdout":
        raise UsdHandsError("--holdout needs at least two clips")
    still = [str(p) for p, _, clip, hm in items if len(still_hands(clip, hm)) == len(
        [h for h in hm.sides if h.finger_joints])]
    if len(still) == len(items):
        raise UsdHandsError(f"the fingers never move in any of these clips: {flag} needs clips with finger "
                            "animation (body-only files have no ground truth)")
    if still:
        warnings.append(f"the fingers never move in {len(still)} of {len(items)} clips "
                        f"({', '.join(still[:3])}{', ...' if len(still) > 3 else ''}); they count as ground truth")
    return dbitems


def _holdout(options: EvaluateOptions, dbitems, cfg, clips: int, warnings, progress) -> EvaluateResult:
    from usdhands.algorithms.synthesis.database import build_database
    from usdhands.algorithms.synthesis.evaluation import holdout_evaluation
    from usdhands.jobs.inputs import stage_progress

    from usdhands.algorithms.synthesis.feature_sets import extra_keys, feature_terms

    try:
        db = build_database(dbitems, fps=options.fps or 30.0, segmentation=cfg.segmentation,
                            arm_features=extra_keys(feature_terms(cfg.segment_cost)))
    except ValueError as e:  # segment_cost.features naming a joint a hand map lacks
        raise UsdHandsError(str(e), path=options.config) from None
    result = {"k": cfg.segment_cost.k, **holdout_evaluation(db, cfg, seed=options.seed,
                                                             progress=stage_progress(progress, "holdout"))}
    return EvaluateResult("holdout", result, clips, (), tuple(warnings))


def _folds(options: EvaluateOptions, dbitems, cfg, feature_sets, clips: int, warnings, progress) -> EvaluateResult:
    from usdhands.algorithms.synthesis.kfold import kfold_evaluation
    from usdhands.jobs.inputs import stage_progress

    try:
        result = kfold_evaluation(dbitems, cfg, options.folds, fps=options.fps or 30.0, feature_sets=feature_sets,
                                  seed=options.seed, progress=stage_progress(progress, "k-fold"))
    except ValueError as e:
        raise UsdHandsError(str(e)) from None
    plots = []
    if options.plot is not None:
        from usdhands.jobs.plots.synthesis import plot_kfold_errors, plot_worst_window

        plots = _write_plots(options.plot, [(lambda p: plot_kfold_errors(result, p), "kfold_errors.png"),
                                            (lambda p: plot_worst_window(result, p), "kfold_worst_window.png")])
    return EvaluateResult("folds", result, clips, tuple(plots), tuple(warnings))


def _write_plots(folder: Path, plotters) -> list:
    """Run ``plotters`` (pairs of a plot function of the PNG path, and a file name) into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return [plot(folder / name) for plot, name in plotters]

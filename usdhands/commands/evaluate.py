"""``usdhands evaluate``: how well body motion predicts finger motion (Jörg, Hodgins, Safonova 2012, section 4).

``evaluate INPUTS... --labels REGEX`` runs the leave-one-out analysis over labelled
clips (body motion is enough): for each predictor, the share of the k closest
segments (DTW-aligned squared differences) that come from a clip of the same label,
and the confusion matrix of ``wrist_pos+0.5rot`` (P + 0.5·R). ``--holdout``
synthesizes every clip's fingers from the others instead and reports the finger-angle
error next to three baselines. ``--folds K`` runs k-fold held-out synthesis (windows of
each take held out against the rest) against five baselines, and compares feature
sets (``--feature-sets``) on the same folds.
"""

from __future__ import annotations

from pathlib import Path

from usdhands.commands._common import Progress, print_json, print_json_with_plots, print_table, write_plots
from usdhands.jobs.option_checks import check_fps, check_seed
from usdhands.jobs.outputs import MAIN_INPUT, check_paths
from usdhands.errors import UsdHandsError


#: evaluation.DEFAULT_PREDICTORS, written out so that building the parser (every command, --help)
#: does not import the synthesis algorithms; a test checks they agree
DEFAULT_PREDICTORS_HELP = ("shoulder_pos,shoulder_rot,elbow_pos,elbow_rot,wrist_pos,wrist_rot,wrist_pos+0.25rot,"
                           "wrist_pos+0.5rot,wrist_pos+rot,elbow_pos+wrist_pos")


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="leave-one-out: which body features predict finger motion (Jörg et al. 2012, sec. 4)",
                       description="Leave-one-out analysis of Jorg, Hodgins, Safonova 2012, section 4, on labelled "
                                   "clips; with --holdout, held-out finger synthesis error against baselines.")
    p.add_argument("inputs", type=Path, nargs="*", help="animation files or folders")
    p.add_argument("--labels", default=None, metavar="REGEX",
                   help="label of a clip: the first group of REGEX searched in its file name")
    p.add_argument("--labels-file", type=Path, default=None, metavar="CSV", help="rows 'file,label'")
    p.add_argument("--k", type=int, default=None,
                   help="neighbours per segment (default 5; with --holdout, candidates per segment: the config's, 5)")
    p.add_argument("--predictors", default=None,
                   help="comma-separated predictors, e.g. wrist_rot,wrist_pos+0.5rot,elbow_pos "
                        f"(default: {DEFAULT_PREDICTORS_HELP})")
    p.add_argument("--holdout", action="store_true",
                   help="synthesize each clip's fingers from the others; error against ground truth and baselines")
    p.add_argument("--folds", type=int, default=None, metavar="K",
                   help="k-fold held-out synthesis on clips with fingers: windows of each take held out against "
                        "the rest, against baselines (mean pose, medoid pose, nearest frame, mean of 10 nearest, "
                        "random segments)")
    p.add_argument("--feature-sets", default=None, metavar="SETS",
                   help="with --folds: comma-separated feature sets behind the segment cost to compare, e.g. "
                        "wrist_pos+0.5rot+0.5elbow_pos,wrist_pos+0.5rot+0.1vel,wrist_pos+0.5rot+0.5other_wrist_pos")
    p.add_argument("--keep-rest", action="store_true",
                   help="leave-one-out: keep each hand's rest at both ends of a take (default: trimmed, as sec. 4)")
    p.add_argument("--samples", action="store_true", help="use the generated gesture set instead of files")
    p.add_argument("--fps", type=float, default=None, help="resample clips to this rate (default the first clip's; 30 with --holdout)")
    p.add_argument("--config", type=Path, default=None, help="synthesis configuration JSON")
    p.add_argument("--handmap", type=Path, default=None, help="hand map JSON overriding detection (all inputs)")
    p.add_argument("--animation", default=None, help="animation name or index in each file")
    p.add_argument("--seed", type=int, default=0, help="seed of the random-segments baseline (default 0)")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--plot", type=Path, default=None, metavar="DIR", help="write PNG figures into DIR")
    p.set_defaults(func=run)


def _items(args):
    from usdhands.jobs.inputs import expand_inputs, labeller, read_labelled, sample_database_items

    if args.samples:
        if args.inputs:
            raise UsdHandsError("give input files or --samples, not both")
        return [(it.source, it.label, it.clip, it.handmap) for it in sample_database_items()]
    if not args.inputs:
        raise UsdHandsError("no input files given (or use --samples)")
    paths = expand_inputs(args.inputs)
    synth = args.holdout or args.folds is not None
    if not synth and not (args.labels or args.labels_file):
        raise UsdHandsError("evaluate needs --labels REGEX or --labels-file CSV (or --holdout, --folds K)")
    return read_labelled(paths, labeller(args.labels, args.labels_file), args.fps, args.handmap, args.animation,
                         Progress("reading"), fingerless=not synth)


def run(args) -> int:
    from usdhands.jobs.inputs import load_config

    check_fps(args.fps)
    check_seed(args.seed)
    check_paths({MAIN_INPUT: args.inputs, "--labels-file": args.labels_file, "--config": args.config,
                 "--handmap": args.handmap})

    if args.k is not None and args.k < 1:
        raise UsdHandsError(f"--k must be at least 1, got {args.k}")
    from usdhands.algorithms.synthesis.evaluation import (
        DEFAULT_PREDICTORS, evaluate_predictors, parse_predictor, prepare_eval_set,
    )
    from usdhands.algorithms.synthesis.kfold import parse_feature_set
    from usdhands.jobs.option_checks import parse_list

    from usdhands.jobs.inputs import check_plot_folder

    check_plot_folder(args.plot)
    cfg = load_config(args.config)
    predictors = parse_list(args.predictors) or list(DEFAULT_PREDICTORS)
    for name in predictors:
        try:
            parse_predictor(name)
        except ValueError as e:
            raise UsdHandsError(str(e)) from None
    if args.folds is not None:
        if args.folds < 2:
            raise UsdHandsError(f"--folds must be at least 2, got {args.folds}")
        if args.holdout:
            raise UsdHandsError("give --holdout or --folds, not both")
    elif args.feature_sets is not None:
        raise UsdHandsError("--feature-sets needs --folds K")
    feature_sets = parse_list(args.feature_sets) or []
    for name in feature_sets:
        try:
            parse_feature_set(name)
        except ValueError as e:
            raise UsdHandsError(str(e)) from None
    items = _items(args)
    if args.folds is not None:
        if args.k is not None:
            cfg = cfg.with_values(segment_cost={"k": args.k})
        from usdhands.commands._evaluate_folds import run_folds

        return run_folds(args, _database_items(args, items, "--folds"), cfg, feature_sets)
    if args.holdout:
        if args.k is not None:
            cfg = cfg.with_values(segment_cost={"k": args.k})
        return _run_holdout(args, items, cfg)
    k = 5 if args.k is None else args.k
    unlabeled = [str(p) for p, lab, _, _ in items if lab is None]
    if unlabeled:
        raise UsdHandsError(f"clips without a label: {unlabeled[:3]}")
    if len(items) < 2:
        raise UsdHandsError("leave-one-out needs at least two clips")
    if len({lab for _, lab, _, _ in items}) < 2:
        raise UsdHandsError(f"leave-one-out needs at least two labels; every clip is {items[0][1]!r}")
    left_out = []
    if args.predictors is None:  # the default list: leave out what these rigs cannot answer
        predictors, left_out = _answerable(predictors, items)
    try:
        es = prepare_eval_set([(lab, clip, hm) for _, lab, clip, hm in items], cfg, args.fps,
                              predictors=predictors, trim_rest=not args.keep_rest)
        result = evaluate_predictors(es, predictors, k, cfg, progress=Progress("leave-one-out"))
    except ValueError as e:
        raise UsdHandsError(str(e)) from None
    result["idle_hands"] = [f"{c}:{s}" for c, s in es.idle]
    if left_out:
        result["left_out_predictors"] = left_out
    written = []
    if args.plot is not None:
        from usdhands.jobs.plots.synthesis import plot_confusion, plot_predictors

        written = write_plots(args.plot, [(lambda p: plot_predictors(result, p), "predictors.png"),
                                          (lambda p: plot_confusion(result, p), "confusion.png")])
    if args.json:
        print_json_with_plots(result, written)
        return 0
    print(f"leave-one-out over {result['segments']} segments of {len(items)} clips, k={result['k']} "
          f"({len(es.idle)} idle hands left out; {'rest kept' if args.keep_rest else 'rest trimmed at both ends'})")
    per_hand = result["per_hand"]
    pct = lambda v: "" if v is None else f"{100 * v:.1f}%"  # noqa: E731
    rows = [[name, pct(share), pct(per_hand[name].get("left")), pct(per_hand[name].get("right"))]
            for name, share in result["predictors"].items()]
    rows.append(["(chance)", pct(result["chance"]), "", ""])
    print_table(rows, ["predictor", "correct type", "left hand", "right hand"])
    if left_out:
        print(f"left out (joints missing from a hand map): {', '.join(left_out)}")
    print(f"best: {result['best']}")
    conf = result["confusion"]
    print(f"\nconfusion ({conf['predictor']}), % of the closest segments by type:")
    short = [lab[:8] for lab in conf["labels"]]
    print_table([[lab] + [f"{100 * v:.0f}" for v in row] for lab, row in zip(conf["labels"], conf["matrix"])],
                ["true \\ found"] + short)
    for w in written:
        print(f"wrote {w}")
    return 0


def _answerable(predictors, items):
    """Split predictors into those every hand map has the joints for and the others."""
    from usdhands.algorithms.synthesis.evaluation import parse_predictor

    have = {"wrist", "elbow", "shoulder"}
    for _, _, _, handmap in items:
        for hand in handmap.sides:
            have &= {"wrist"} | ({"elbow"} if hand.forearm else set()) | ({"shoulder"} if hand.shoulder else set())
    keep = [p for p in predictors if all(key.split("_")[0] in have for key, _ in parse_predictor(p))]
    return keep, [p for p in predictors if p not in keep]


def _database_items(args, items, flag: str) -> list:
    """The clips as database items, refusing clips without fingers and warning about still ones."""
    from usdhands.algorithms.synthesis.database import DatabaseClip

    dbitems = []
    for p, lab, clip, hm in items:
        if not any(h.finger_joints for h in hm.sides):
            raise UsdHandsError(f"no finger joints: {flag} needs clips with finger animation", path=p)
        dbitems.append(DatabaseClip(clip, hm, lab, str(p)))
    if len(dbitems) < 2 and flag == "--holdout":
        raise UsdHandsError("--holdout needs at least two clips")
    from usdhands.commands.db import _still_hands

    still = [str(p) for p, _, clip, hm in items if len(_still_hands(clip, hm)) == len(
        [h for h in hm.sides if h.finger_joints])]
    if len(still) == len(items):
        raise UsdHandsError(f"the fingers never move in any of these clips: {flag} needs clips with finger "
                            "animation (body-only files have no ground truth)")
    if still:
        import sys

        print(f"usdhands: warning: the fingers never move in {len(still)} of {len(items)} clips "
              f"({', '.join(still[:3])}{', ...' if len(still) > 3 else ''}); they count as ground truth",
              file=sys.stderr)
    return dbitems


def _run_holdout(args, items, cfg) -> int:
    from usdhands.algorithms.synthesis.database import build_database
    from usdhands.algorithms.synthesis.evaluation import holdout_evaluation

    dbitems = _database_items(args, items, "--holdout")
    db = build_database(dbitems, fps=args.fps or 30.0, segmentation=cfg.segmentation)
    result = {"k": cfg.segment_cost.k, **holdout_evaluation(db, cfg, seed=args.seed, progress=Progress("holdout"))}
    if args.json:
        print_json(result)
        return 0
    print(f"held-out synthesis over {result['clips']} clips ({result['frames']} hand-frames, k={result['k']}); "
          f"ground truth mean angular speed {result['ground_truth_speed_deg_s']:.1f} deg/s")
    rows = [[m, f"{v['error_deg']:.2f}", f"{v['speed_deg_s']:.2f}"] for m, v in result["methods"].items()]
    print_table(rows, ["method", "finger error (deg)", "angular speed (deg/s)"])
    return 0

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

from usdhands.commands._common import Progress, print_json, print_table


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


def options_from(args):
    """The job's options from parsed arguments."""
    from usdhands.jobs.evaluation import EvaluateOptions
    from usdhands.jobs.option_checks import parse_list

    def listed(value):
        return None if value is None else tuple(parse_list(value))

    return EvaluateOptions(labels=args.labels, labels_file=args.labels_file, k=args.k,
                           predictors=listed(args.predictors), holdout=args.holdout, folds=args.folds,
                           feature_sets=listed(args.feature_sets), keep_rest=args.keep_rest, samples=args.samples,
                           fps=args.fps, config=args.config, handmap=args.handmap, animation=args.animation,
                           seed=args.seed, plot=args.plot)


def run(args) -> int:
    import sys

    from usdhands.jobs.evaluation import evaluate

    result = evaluate(args.inputs, options_from(args), progress=Progress("evaluate"))
    for w in result.warnings:
        print(f"usdhands: warning: {w}", file=sys.stderr)
    if args.json:
        print_json(result.to_json())
        return 0
    {"leave-one-out": _print_leave_one_out, "holdout": _print_holdout, "folds": _print_folds}[result.analysis](
        result, args)
    for w in result.plots:
        print(f"wrote {w}")
    return 0


def _print_leave_one_out(res, args) -> None:
    result = res.report
    print(f"leave-one-out over {result['segments']} segments of {res.clips} clips, k={result['k']} "
          f"({len(result['idle_hands'])} idle hands left out; "
          f"{'rest kept' if args.keep_rest else 'rest trimmed at both ends'})")
    per_hand = result["per_hand"]
    pct = lambda v: "" if v is None else f"{100 * v:.1f}%"  # noqa: E731
    rows = [[name, pct(share), pct(per_hand[name].get("left")), pct(per_hand[name].get("right"))]
            for name, share in result["predictors"].items()]
    rows.append(["(chance)", pct(result["chance"]), "", ""])
    print_table(rows, ["predictor", "correct type", "left hand", "right hand"])
    if result.get("left_out_predictors"):
        print(f"left out (joints missing from a hand map): {', '.join(result['left_out_predictors'])}")
    print(f"best: {result['best']}")
    conf = result["confusion"]
    print(f"\nconfusion ({conf['predictor']}), % of the closest segments by type:")
    short = [lab[:8] for lab in conf["labels"]]
    print_table([[lab] + [f"{100 * v:.0f}" for v in row] for lab, row in zip(conf["labels"], conf["matrix"])],
                ["true \\ found"] + short)


def _print_holdout(res, args) -> None:
    result = res.report
    print(f"held-out synthesis over {result['clips']} clips ({result['frames']} hand-frames, k={result['k']}); "
          f"ground truth mean angular speed {result['ground_truth_speed_deg_s']:.1f} deg/s")
    rows = [[m, f"{v['error_deg']:.2f}", f"{v['speed_deg_s']:.2f}"] for m, v in result["methods"].items()]
    print_table(rows, ["method", "finger error (deg)", "angular speed (deg/s)"])


def _print_folds(res, args) -> None:
    result = res.report
    truth = result["truth"]
    print(f"{result['folds']}-fold held-out synthesis over {result['windows']} windows of {result['tracks']} hand "
          f"tracks ({result['frames']} hand-frames, k={result['k']}); real: {truth['speed_deg_s']:.1f} deg/s, "
          f"largest jump {truth['largest_jump_deg']:.1f} deg, {100 * truth['repeated_share']:.1f}% repeated frames")
    rows = [[m, f"{v['error_deg']:.2f}", f"{v['expressive_error_deg']:.2f}", f"{v['speed_ratio']:.2f}",
             f"{v['largest_jump_deg']:.1f}", f"{100 * v['repeated_share']:.1f}%"] for m, v in result["methods"].items()]
    print_table(rows, ["method", "error (deg)", "expressive quarter", "speed / real", "largest jump", "repeated"])
    r = result["ratios"]
    print(f"synthesis / mean pose {r['to_mean_pose']:.2f}, / nearest frame {r['to_nearest_frame']:.2f}; "
          f"expressive quarter / mean pose {r['expressive_to_mean_pose']:.2f}")
    if result["feature_sets"]:
        print("\nfeature sets behind the segment cost (same folds):")
        print_table([[name, f"{v['error_deg']:.2f}", f"{v['expressive_error_deg']:.2f}", f"{v['to_mean_pose']:.2f}"]
                     for name, v in result["feature_sets"].items()],
                    ["feature set", "error (deg)", "expressive quarter", "/ mean pose"])
    if result["feature_sets_left_out"]:
        print(f"left out (joints missing from a hand map): {', '.join(result['feature_sets_left_out'])}")

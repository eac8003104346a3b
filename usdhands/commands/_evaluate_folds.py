"""``usdhands evaluate --folds K``: k-fold held-out synthesis against baselines, printed or as JSON."""

from __future__ import annotations

from usdhands.commands._common import Progress, print_json_with_plots, print_table, write_plots
from usdhands.errors import UsdHandsError


def run_folds(args, items, cfg, feature_sets) -> int:
    from usdhands.algorithms.synthesis.kfold import kfold_evaluation

    try:
        result = kfold_evaluation(items, cfg, args.folds, fps=args.fps or 30.0, feature_sets=feature_sets,
                                  seed=args.seed, progress=Progress("k-fold"))
    except ValueError as e:
        raise UsdHandsError(str(e)) from None
    written = []
    if args.plot is not None:
        from usdhands.jobs.plots.synthesis import plot_kfold_errors, plot_worst_window

        written = write_plots(args.plot, [(lambda p: plot_kfold_errors(result, p), "kfold_errors.png"),
                                          (lambda p: plot_worst_window(result, p), "kfold_worst_window.png")])
    if args.json:
        print_json_with_plots(result, written)
        return 0
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
    for w in written:
        print(f"wrote {w}")
    return 0

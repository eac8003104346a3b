"""``usdhands reduce IN``: find irrelevant and redundant finger DOFs (Jörg and O'Sullivan 2009).

Prints the DOFs left after each step with the reconstruction error (the paper's table 5),
the curves made constant (tables 1 and 3) and the relations (tables 2 and 4); ``--json``
prints the same as JSON. ``-o OUT`` writes the simplified animation into a copy of the
input, ``--model`` saves the model that ``usdhands expand`` rebuilds a hand from, and
``--plot DIR`` draws the histograms, scatter plots and curves of the paper's figures.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from usdhands.commands._common import parse_list, print_json, print_table
from usdhands.commands._output import MAIN_INPUT, add_layer_argument, check_paths, layer_options
from usdhands.errors import UsdHandsError


def register(sub) -> None:
    from usdhands.algorithms.reduction.reduce import DEFAULT_STEPS

    p = sub.add_parser(
        "reduce", help="find irrelevant and redundant finger DOFs; rebuild a hand from a few curves",
        description="Finger DOF reduction by range and RMS deviation (Jorg and O'Sullivan 2009): curves with "
                    "a small range become constants, curves that are a linear function of another curve are "
                    "rebuilt from it. Steps run in order and accumulate like the paper's four steps.")
    p.add_argument("file", type=Path, help="input animation (.usd/.usda/.usdc/.usdz, .gltf/.glb, .bvh)")
    p.add_argument("--hands", default=None, help="hands to reduce: left, right or left,right (default: all found)")
    p.add_argument("--steps", default=DEFAULT_STEPS,
                   help=f"comma-separated steps range<N (degrees), rmsd<N, rmsd1<N, rmsd2<N (default {DEFAULT_STEPS!r})")
    p.add_argument("--step", type=int, default=None,
                   help="which step's result -o, --model and the JSON relations use (1-based; default the last)")
    p.add_argument("--json", action="store_true", help="print JSON instead of tables")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="write the simplified animation (every finger curve rebuilt) into a copy of the input")
    add_layer_argument(p)
    p.add_argument("--model", type=Path, default=None, help="save the reduction model as JSON (for 'usdhands expand')")
    p.add_argument("--plot", type=Path, default=None, metavar="DIR",
                   help="draw histograms, scatter plots and original-vs-rebuilt curves as PNGs into DIR")
    p.add_argument("--animation", default=None, help="animation name or index in the file (default the first)")
    p.add_argument("--handmap", type=Path, default=None, help="hand map JSON overriding detection")
    p.add_argument("--order", default="XYZ", help="Euler order of the finger curves (default XYZ)")
    p.add_argument("--across-hands", action="store_true",
                   help="also relate curves of different hands (the paper compared all 50 curves)")
    p.set_defaults(func=run)


def load_finger_curves(path: Path, animation, handmap_path, hands_arg: str | None, order: str):
    """Read a clip and the finger curves of the chosen hands.

    Returns ``(clip, handmap, curves, sides)``: ``curves`` a FingerCurves over the chosen
    hands' finger joints (left first), kept continuous through gimbal regions
    (:func:`~usdhands.algorithms.reduction.reduce.continuous_euler_curves`); ``sides`` the side
    of each curve. Curve names: :func:`~usdhands.algorithms.reduction.reduce.curve_names` (not
    ``curves.names``, which repeat when two joints share a short name).
    """
    from usdhands.algorithms.reduction.reduce import continuous_euler_curves
    from usdhands.formats.io import read_clip
    from usdhands.model.finger_dofs import finger_curves
    from usdhands.formats.hands import hands_for
    from usdhands.model.handmap import SIDES

    _check_order(order)
    try:
        chosen = parse_list(hands_arg, SIDES)
    except UsdHandsError as e:
        raise UsdHandsError(f"--hands: {e.message}") from None
    clip = read_clip(path, animation=animation)
    if clip.num_frames < 2:
        raise UsdHandsError(f"the animation has {clip.num_frames} frame(s); finger curves need at least 2",
                            path=path)
    handmap = hands_for(path, clip.skeleton, handmap_path)[0]
    wanted = chosen or [h.side for h in handmap.sides if h.finger_joints]
    if not wanted:
        raise UsdHandsError("no hand with finger joints", path=path)
    joints, sides = [], []
    for side in SIDES:
        if side not in wanted:
            continue
        hand = handmap[side]
        if hand is None or not hand.finger_joints:
            found = ", ".join(h.side for h in handmap.sides if h.finger_joints) or "none"
            raise UsdHandsError(f"no {side} hand with fingers (hands found: {found})", path=path)
        for name in hand.finger_joints:
            joints.append(clip.skeleton.index(name))
            sides += [side] * 3
    curves = finger_curves(clip, joints, order.upper())
    curves = curves.with_values(continuous_euler_curves(curves.values))
    return clip, handmap, curves, sides


def _check_order(order: str) -> None:
    o = order.upper()
    if len(o) != 3 or set(o) != set("XYZ"):
        raise UsdHandsError(f"bad --order {order!r}: expected a permutation of XYZ such as XYZ or ZYX")


def run(args) -> int:
    from usdhands.algorithms.reduction.reduce import RangeRule, curve_names, paper_style_names, parse_steps, reduce_curves
    from usdhands.commands._common import Progress
    from usdhands.commands._synthesis_common import check_plot_folder

    steps = parse_steps(args.steps)
    write_opts = layer_options(args.layer, args.file, args.output) if args.output is not None else {}
    if args.layer and args.output is None:
        raise UsdHandsError("--as-layer needs -o OUT")
    check_paths({MAIN_INPUT: args.file, "--handmap": args.handmap}, {"-o": args.output, "--model": args.model})
    check_plot_folder(args.plot)
    progress = Progress("reduce")
    progress(0, 3, "reading")
    clip, handmap, curves, sides = load_finger_curves(args.file, args.animation, args.handmap, args.hands, args.order)
    progress(1, 3, "reducing")
    names = curve_names(clip.skeleton, curves.joints, curves.order)
    result = reduce_curves(curves.values, names, steps,
                           groups=sides, across_groups=args.across_hands, order=curves.order,
                           source=args.file.name)
    k = len(result.steps) if args.step is None else args.step
    if not 1 <= k <= len(result.steps):
        raise UsdHandsError(f"--step {args.step} is out of range: {len(result.steps)} step(s) given")
    chosen = result.steps[k - 1]
    paper = paper_style_names(handmap, curves.order, clip.skeleton)

    if args.output is not None or args.model is not None or args.plot is not None:
        progress(2, 3, "writing")
    written = []
    if args.output is not None:
        from usdhands.algorithms.reduction.reduce import expand_clip
        from usdhands.formats.io import write_clip

        # what 'usdhands expand' gives for this clip and model (the curves read for the model: the
        # same as these unless rotations jump between frames)
        from usdhands.model.provenance import provenance_record

        out_clip = expand_clip(clip, curves.joints, chosen.model)
        record = provenance_record("reduction", database=args.model, parameters={
            "step": k, "controlling": list(chosen.model.controlling_curves), "curves": len(chosen.model.curves)})
        written.append(write_clip(args.file, out_clip, args.output, provenance=record, **write_opts))
    if args.model is not None:
        model = chosen.model
        model = dataclasses.replace(model, metadata={
            **model.metadata, "paper_names": {c: paper[c] for c in model.curves if c in paper},
            "frames": int(clip.num_frames), "fps": float(clip.fps)})
        written.append(model.save(args.model))
    if args.plot is not None:
        from usdhands.commands._reduction_plots import plot_reduction

        written += plot_reduction(result, curves.values, args.plot, step=k - 1, paper_names=paper,
                                  fps=clip.fps)
    progress(3, 3, "done")

    if args.json:
        report = result.to_dict(step=k - 1)
        report = {"file": str(args.file), "frames": int(clip.num_frames), "fps": float(clip.fps), **report}
        for r in report["relations"]:
            r["dependent_paper"] = paper.get(r["dependent"])
            r["controlling_paper"] = paper.get(r["controlling"])
        for c in report["constants"]:
            c["curve_paper"] = paper.get(c["curve"])
        if written:
            report["written"] = [str(w) for w in written]
        print_json(report)
        return 0

    by_hand = ", ".join(f"{s} {sides.count(s)}" for s in ("left", "right") if s in sides)
    print(f"{args.file}: {len(names)} finger curves ({by_hand}), {clip.num_frames} frames at {clip.fps:g} fps")
    print()
    def pname(c: str) -> str:
        return paper.get(c, "-")

    rows = [("original", len(names), 0.0, 0.0, "-")]
    rows += [(s.condition, s.dofs_left, s.rms_error_deg, s.max_error_deg,
              "-" if s.worst_curve is None else f"{s.worst_curve} ({pname(s.worst_curve)})") for s in result.steps]
    print_table(rows, ["condition", "DOFs left", "RMS error (deg)", "max error (deg)", "max error at"])

    # like the paper's tables: the first range step lists its constants (table 1), a later
    # one the curves it adds (table 3); the first rmsd step lists its relations (table 2),
    # a later one those added or changed since the previous rmsd step (table 4)
    prev_constants: tuple[int, set] | None = None
    prev_relations: tuple[int, dict] | None = None
    for i, s in enumerate(result.steps, start=1):
        model = s.model
        if isinstance(s.rule, RangeRule):
            if prev_constants is None:
                new, what = list(model.constants), "constant curves"
            else:
                new = [c for c in model.constants if c.curve not in prev_constants[1]]
                what = f"constant curves besides those of step {prev_constants[0]}"
            print(f"\nstep {i} ({s.condition}): {len(new)} {what}")
            if new:
                print_table([(c.curve, pname(c.curve), round(c.range, 3), round(c.value, 2) + 0.0) for c in new],
                            ["curve", "paper name", "range", "mean"])
            prev_constants = (i, {c.curve for c in model.constants})
        else:
            if prev_relations is None:
                changed, what = list(model.relations), "relations"
            else:
                changed = [r for r in model.relations if prev_relations[1].get(r.dependent) != (r.controlling, r.kind)]
                dropped = len(set(prev_relations[1]) - {r.dependent for r in model.relations})
                what = (f"relations added or changed since step {prev_relations[0]} (of {len(model.relations)}"
                        + (f"; {dropped} no longer dependent)" if dropped else ")"))
            print(f"\nstep {i} ({s.condition}): {len(changed)} {what}")
            if changed:
                print_table([(r.dependent, pname(r.dependent), r.controlling, pname(r.controlling),
                              f"{r.kind} = {r.rmsd:.2f}") for r in changed],
                            ["dependent", "paper name", "controlling", "paper name", "rmsd"])
            prev_relations = (i, {r.dependent: (r.controlling, r.kind) for r in model.relations})
    print(f"\nstep {k} ({chosen.condition}) keeps {chosen.dofs_left} of {len(names)} curves: "
          + (", ".join(f"{c} ({pname(c)})" if c in paper else c for c in chosen.model.free_curves) or "none"))
    for w in written:
        print(f"wrote {w}")
    return 0

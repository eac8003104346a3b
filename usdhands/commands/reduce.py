"""``usdhands reduce IN``: find irrelevant and redundant finger DOFs (Jörg and O'Sullivan 2009).

Prints the DOFs left after each step with the reconstruction error (the paper's table 5),
the curves made constant (tables 1 and 3) and the relations (tables 2 and 4); ``--json``
prints the same as JSON. ``-o OUT`` writes the simplified animation into a copy of the
input, ``--model`` saves the model that ``usdhands expand`` rebuilds a hand from, and
``--plot DIR`` draws the histograms, scatter plots and curves of the paper's figures.
"""

from __future__ import annotations

from pathlib import Path

from usdhands.commands._common import Progress, add_layer_argument, print_json, print_table

#: reduce.DEFAULT_STEPS (the paper's four steps, ReduceOptions' default), written out so that building
#: the parser (every command, --help) does not import the job and the reduction steps (bench_startup:
#: ``usdhands --help`` 0.085-0.089 -> 0.078-0.079 s); a test checks they agree
DEFAULT_STEPS = "range<1,rmsd<0.3,range<5,rmsd<0.5"


def register(sub) -> None:
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


def run(args) -> int:
    from usdhands.jobs.option_checks import parse_list
    from usdhands.jobs.reduction import RangeRule, ReduceOptions, reduce
    from usdhands.model.handmap import SIDES
    from usdhands.errors import UsdHandsError

    try:
        hands = tuple(parse_list(args.hands, SIDES))
    except UsdHandsError as e:
        raise UsdHandsError(f"--hands: {e.message}") from None
    options = ReduceOptions(steps=args.steps, step=args.step, hands=hands, animation=args.animation,
                            handmap=args.handmap, order=args.order, across_hands=args.across_hands,
                            as_layer=args.layer, plot=args.plot)
    job = reduce(args.file, args.output, options, model_output=args.model, progress=Progress("reduce"))

    if args.json:
        print_json(job.to_json())
        return 0
    result, paper, names, sides, k, chosen = job.reduction, job.paper_names, job.curve_names, job.sides, job.step, job.chosen

    by_hand = ", ".join(f"{s} {sides.count(s)}" for s in ("left", "right") if s in sides)
    print(f"{args.file}: {len(names)} finger curves ({by_hand}), {job.frames} frames at {job.fps:g} fps")
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
    for w in job.written:
        print(f"wrote {w}")
    return 0

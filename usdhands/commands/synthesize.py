"""``usdhands synthesize IN -o OUT``: finger motion for a body clip, from wrist motion (Jörg, Hodgins, Safonova 2012).

Segments each hand's wrist motion, finds the k most similar database segments
(eq. 1), picks the least-cost path through the graph of transitions (eq. 2–3),
stitches the chosen finger motion and writes the input file again with the finger
animation added; every other joint and everything else in the file stay as they
were. Without ``--db`` the database bundled in the package is used.
"""

from __future__ import annotations

from pathlib import Path

from usdhands.commands._common import Progress, add_prop_arguments, print_json, print_table


def register(sub) -> None:
    p = sub.add_parser("synthesize", help="give a body clip finger motion from a database (Jörg et al. 2012)",
                       description="Data-driven finger motion synthesis (Jorg, Hodgins, Safonova 2012).")
    p.add_argument("file", type=Path, help="input animation (.usd*, .gltf/.glb, .bvh)")
    p.add_argument("-o", "--output", type=Path, required=True, help="output file (same format as the input)")
    p.add_argument("--db", type=Path, default=None, help="database folder from 'usdhands db build' (default: bundled)")
    p.add_argument("--k", type=int, default=None, help="candidates per segment (default 5, or the config's)")
    p.add_argument("--hands", default=None, help="left, right or left,right (default: every hand with fingers)")
    p.add_argument("--config", type=Path, default=None, help="synthesis configuration JSON (weights, thresholds)")
    p.add_argument("--handmap", type=Path, default=None, help="hand map JSON overriding detection")
    p.add_argument("--animation", default=None,
                   help="animation name or index in the file (default the first), or 'all': every animation")
    p.add_argument("--as-layer", "--layer", dest="layer", action="store_true",
                   help="USD: write a sparse override layer on top of the input")
    p.add_argument("--graft-hands", action="store_true",
                   help="add finger joints from the database's hand to a skeleton without them (skeleton-only "
                        "files: BVH, USD without skinned meshes); the output is a new file with the new joints")
    p.add_argument("--finger-reference", choices=("rest", "input"), default="rest",
                   help="finger rotations relative to the rig's rest pose (default) or to the pose the input's "
                        "fingers hold at its first frame (body-only clips from files whose rest/zero pose is not "
                        "the bind pose, e.g. BVH written from a rig with rest rotations)")
    p.add_argument("--plot", type=Path, default=None, metavar="DIR",
                   help="write PNGs: wrist speed with segments, the graph with the chosen path, finger curves")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    add_prop_arguments(p, required=False)
    p.add_argument("--collision-weight", type=float, default=1.0, metavar="WC",
                   help="with --props: weight wc of the collision term wc*sum|D-D*|^2/(n*m) in the segment cost")
    p.set_defaults(func=run)


def options_from(args):
    """The job's options from parsed arguments."""
    from usdhands.jobs.option_checks import parse_list
    from usdhands.jobs.synthesis import SynthesizeOptions
    from usdhands.model.handmap import SIDES

    return SynthesizeOptions(db=args.db, k=args.k, hands=tuple(parse_list(args.hands, SIDES)), config=args.config,
                             handmap=args.handmap, animation=args.animation, as_layer=args.layer,
                             graft_hands=args.graft_hands, finger_reference=args.finger_reference, plot=args.plot,
                             props=tuple(args.props), margin=args.margin, self_collision=args.self_collision,
                             attach=tuple(args.attach), prop_units=args.prop_units, prop_up=args.prop_up,
                             interaction_config=args.interaction_config, collision_weight=args.collision_weight)


def run(args) -> int:
    import sys

    from usdhands.jobs.synthesis import synthesize

    result = synthesize(args.file, args.output, options_from(args), progress=Progress("synthesize"))
    for w in result.warnings:
        print(f"usdhands: warning: {w}", file=sys.stderr)
    if args.json:
        print_json(result.to_json())
        return 0
    if result.every_animation:
        for r in result.animations:
            print(f"animation {r['animation']!r}:")
            _print_report(r)
            for p in r.get("plots", []):
                print(f"wrote {p}")
        print(f"wrote {result.output}")
        return 0
    report = result.animations[0]
    if result.animations_in_file > 1 and args.animation is None:
        print(f"animation {report['animation']!r}, the first of {result.animations_in_file} in the file "
              f"(--animation NAME for another, or all; the others are written unchanged)")
    _print_report(report)
    if result.grafted_joints:
        print(f"grafted {len(result.grafted_joints)} finger joints from the database's hands")
    for p in report.get("plots", []):
        print(f"wrote {p}")
    print(f"wrote {result.output}")
    return 0


def _print_report(report) -> None:
    rows = []
    for side, h in report["hands"].items():
        rows.append([side, h["segments"], h["top_labels"], f"{h['mean_segment_cost']:.1f}",
                     f"{h['seams_blended']}/{h['seams']}", f"{100 * h['pruned_share']:.0f}%"])
    print_table(rows, ["hand", "segments", "labels chosen", "mean cS", "seams blended", "pruned"])
    for side, m in report["mapping"].items():
        if m["no_source"]:
            print(f"{side}: no database counterpart, left as they were: {', '.join(m['no_source'])}")
        if m["dropped"]:
            print(f"{side}: database slots with no joint in this rig: {', '.join(m['dropped'])}")
    if "interaction" in report:
        i = report["interaction"]
        b, a = i["penetration_before_mm"], i["penetration_after_mm"]
        print(f"props: penetration before correction max {b['max']:.2f} mm ({b['frames']} frames), after "
              f"{a['max']:.3f} mm ({a['frames']} frames); jitter {i['jitter_before']:.0f} -> {i['jitter_after']:.0f} "
              f"deg/s^2; {i['frames_corrected']} frames corrected")

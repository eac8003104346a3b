"""``usdhands synthesize IN -o OUT``: finger motion for a body clip, from wrist motion (Jörg, Hodgins, Safonova 2012).

Segments each hand's wrist motion, finds the k most similar database segments
(eq. 1), picks the least-cost path through the graph of transitions (eq. 2–3),
stitches the chosen finger motion and writes the input file again with the finger
animation added; every other joint and everything else in the file stay as they
were. Without ``--db`` the database bundled in the package is used.
"""

from __future__ import annotations

from pathlib import Path

from usdhands.commands._common import Progress, print_json, print_table
from usdhands.commands._interaction_common import add_prop_arguments, check_prop_options
from usdhands.commands._output import MAIN_INPUT, check_paths, layer_options
from usdhands.commands._synthesis_common import check_plot_folder
from usdhands.errors import UsdHandsError


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


def run(args) -> int:

    from usdhands.algorithms.synthesis.database import load_database
    from usdhands.algorithms.synthesis.synthesize import synthesize_clip
    from usdhands.commands._synthesis_common import bundled_database_path, load_config
    from usdhands.formats.io import read_asset, write_asset, write_clip
    from usdhands.model.asset import Asset

    _check_output(args)
    if args.props:
        check_prop_options(args)
        if args.animation == "all":
            raise UsdHandsError("--props works on one animation; give --animation NAME")
        if not (args.collision_weight >= 0):
            raise UsdHandsError(f"--collision-weight must be 0 or more, got {args.collision_weight:g}")
    cfg = load_config(args.config)
    if args.k is not None:
        if args.k < 1:
            raise UsdHandsError(f"--k must be at least 1, got {args.k}")
        cfg = cfg.with_values(segment_cost={"k": args.k})
    progress = Progress("synthesize")
    progress(0, 4, "reading")
    # the bundled database's manifest is validated by the tests, not on every run
    db = load_database(args.db) if args.db else load_database(bundled_database_path(), check_schema=False)
    record = _provenance(args, cfg)
    asset = read_asset(args.file)
    if args.animation == "all" and not any(c.name == "all" for c in asset.clips):
        return _run_all(args, asset, db, cfg, progress)
    try:
        clip = asset.clip(args.animation)
    except KeyError as e:
        raise UsdHandsError(str(e.args[0]).split(": ", 1)[-1], path=args.file) from None
    clip, handmap, with_fingers, added = _prepare(args, asset, clip, db, cfg)
    progress(1, 4, "synthesizing")
    interaction, colliders, iconfig = None, None, None
    if args.props:
        from usdhands.algorithms.interaction.finger_geometry import InteractionConfig, load_interaction_config
        from usdhands.commands._interaction_common import read_scene_props, synthesis_interaction

        iconfig = load_interaction_config(args.interaction_config) if args.interaction_config else InteractionConfig()
        props = read_scene_props(args, clip)
        interaction, colliders = synthesis_interaction(args, clip, handmap, db, cfg, props, iconfig)
    result = synthesize_clip(clip, handmap, db, cfg, tuple(with_fingers), finger_reference=args.finger_reference,
                             interaction=interaction)
    correction = None
    if args.props:
        from dataclasses import replace

        from usdhands.algorithms.interaction.correction import correct_clip
        from usdhands.model.handmap import HandMap

        corrected_hands = HandMap(**{s: handmap[s] for s in with_fingers})
        fixed, correction = correct_clip(result.clip, corrected_hands, colliders, margin_mm=args.margin,
                                         config=iconfig)
        result = replace(result, clip=fixed)
    progress(2, 4, "writing")
    if added:
        out = write_asset(Asset(str(args.file), (result.clip.skeleton,), (result.clip,), ()), args.output,
                          inputs=(args.file,), provenance=record)
    else:
        out = write_clip(args.file, result.clip, args.output, provenance=record,
                         **layer_options(args.layer, args.file, args.output))
    report = _report(result, db, cfg)
    report["grafted_joints"] = added
    if correction is not None:
        report["interaction"] = {**correction.to_dict(), "chains_corrected": correction.chains_corrected}
    report["output"] = str(out)
    report["animation"] = clip.name
    report["animations_in_file"] = len(asset.clips)
    if args.plot is not None:
        report["plots"] = [str(p) for p in _plots(args.plot, clip, result, db, cfg)]
    progress(4, 4, "done")
    if args.json:
        print_json(report)
        return 0
    if len(asset.clips) > 1 and args.animation is None:
        print(f"animation {clip.name!r}, the first of {len(asset.clips)} in the file (--animation NAME for another, "
              f"or all; the others are written unchanged)")
    _print_report(report)
    if added:
        print(f"grafted {len(added)} finger joints from the database's hands")
    for p in report.get("plots", []):
        print(f"wrote {p}")
    print(f"wrote {out}")
    return 0


def _prepare(args, asset, clip, db, cfg):
    """Hand map, hands to synthesize and grafting for one clip: ``(clip, handmap, sides, grafted joints)``."""
    import numpy as np

    from usdhands.commands._common import parse_list
    from usdhands.commands._synthesis_common import handmap_for
    from usdhands.errors import NoHandsError
    from usdhands.model.handmap import SIDES, HandMap

    wanted = parse_list(args.hands, SIDES) or list(SIDES)
    try:
        handmap = handmap_for(clip, args.file, args.handmap)
    except NoHandsError:
        if not args.graft_hands:
            raise
        handmap = HandMap()
    with_fingers = [s for s in wanted if handmap[s] is not None and handmap[s].finger_joints]
    added = []
    if args.graft_hands and len(with_fingers) < len(wanted):
        clip, handmap, added = _graft(args, asset, clip, handmap, db, [s for s in wanted if s not in with_fingers],
                                      explicit=bool(args.hands))
        with_fingers = [s for s in wanted if handmap[s] is not None and handmap[s].finger_joints]
        if added and args.layer:
            raise UsdHandsError("--as-layer cannot add joints to the skeleton it overrides; with --graft-hands "
                                "the output is a new file (drop --as-layer)", path=args.file)
    if not with_fingers:
        found = ", ".join(f"{h.side} (wrist {h.wrist})" for h in handmap.sides) or "none"
        raise UsdHandsError(f"the skeleton has no finger joints on the {' or '.join(wanted)} hand "
                            f"(hands found: {found}); synthesis needs a rig with finger joints "
                            f"(or --graft-hands on a skeleton-only file)", path=args.file)
    if args.hands:
        missing = [s for s in wanted if s not in with_fingers]
        if missing:
            raise UsdHandsError(f"no {', '.join(missing)} hand with finger joints in this skeleton", path=args.file)
    db_sides = {SIDES[s] for s in np.unique(db.tracks[:, 3])}
    for s in with_fingers:
        if s not in db_sides:
            raise UsdHandsError(f"the database has no {s}-hand motion; rebuild it with --mirror", path=db.path)
    differ = {key: (value, db.segmentation[key]) for key, value in vars(cfg.segmentation).items()
              if key in db.segmentation and abs(float(value) - float(db.segmentation[key])) > 1e-9}
    if differ:
        import sys

        print("usdhands: warning: the input is segmented with other values than the database was ("
              + ", ".join(f"{key} {a:g} here, {b:g} there" for key, (a, b) in differ.items())
              + "); rebuild the database with the same --config for like segments", file=sys.stderr)
    return clip, handmap, with_fingers, added


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


def _provenance(args, cfg) -> dict:
    """The UsdHandsFingerMotionAPI / extras record of a synthesis with these options."""
    from usdhands.commands._synthesis_common import bundled_database_path
    from usdhands.model.provenance import provenance_record

    return provenance_record("synthesis", database=args.db or bundled_database_path(), parameters={
        "config": cfg.to_dict(), "finger_reference": args.finger_reference, "graft_hands": bool(args.graft_hands),
        **({"props": [str(p) for p in args.props], "margin_mm": args.margin} if getattr(args, "props", None) else {})})


def _run_all(args, asset, db, cfg, progress) -> int:
    """``--animation all``: every animation of the file gets fingers, written in one output."""
    import contextlib
    import os
    import tempfile

    from usdhands.algorithms.synthesis.synthesize import synthesize_clip
    from usdhands.formats.io import write_clip

    if args.graft_hands or args.layer:
        raise UsdHandsError("--animation all works without --graft-hands and --as-layer", path=args.file)
    if not asset.clips:
        raise UsdHandsError("no animation in file", path=args.file)
    results = []
    for i, clip in enumerate(asset.clips):
        progress(i, len(asset.clips), clip.name)
        clip, handmap, with_fingers, _ = _prepare(args, asset, clip, db, cfg)
        results.append((clip, synthesize_clip(clip, handmap, db, cfg, tuple(with_fingers),
                                              finger_reference=args.finger_reference)))
    # one animation per write: each write keeps the file's other animations, so chain them
    temps = []
    try:
        current = args.file
        for i, (_, res) in enumerate(results):
            if i == len(results) - 1:
                target = args.output
            else:
                fd, name = tempfile.mkstemp(suffix=args.output.suffix, prefix=f".{args.output.stem}.",
                                            dir=args.output.parent)
                os.close(fd)
                os.unlink(name)
                target = type(args.output)(name)
                temps.append(target)
            out = write_clip(current, res.clip, target, provenance=_provenance(args, cfg))
            current = target
    finally:
        for t in temps:
            with contextlib.suppress(OSError):
                t.unlink()
    reports = []
    for clip, res in results:
        r = _report(res, db, cfg)
        r["animation"] = clip.name
        if args.plot is not None:
            r["plots"] = [str(p) for p in _plots(args.plot / _safe_name(clip.name), clip, res, db, cfg)]
        reports.append(r)
    progress(len(asset.clips), len(asset.clips), "done")
    if args.json:
        print_json({"database": str(db.path), "k": cfg.segment_cost.k, "animations": reports, "output": str(out)})
        return 0
    for r in reports:
        print(f"animation {r['animation']!r}:")
        _print_report(r)
        for p in r.get("plots", []):
            print(f"wrote {p}")
    print(f"wrote {out}")
    return 0


def _safe_name(name: str) -> str:
    import re

    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name.rsplit("/", 1)[-1]) or "animation"


def _check_output(args) -> None:
    """Refuse a bad output before any work: the input itself, a missing folder, --as-layer
    without USD on both sides, or another format than the input's (without --graft-hands,
    which writes a new file in any format)."""
    from usdhands.formats.registry import handler_for

    check_paths({MAIN_INPUT: args.file, "--db": args.db, "--config": args.config, "--handmap": args.handmap,
                 "--props": args.props, "--interaction-config": args.interaction_config},
                {"-o": args.output})
    layer_options(args.layer, args.file, args.output)
    check_plot_folder(args.plot)
    if not args.graft_hands and args.file.exists():
        if handler_for(args.output, "write") is not handler_for(args.file, "read"):
            raise UsdHandsError(f"the output is the input file with fingers added, so it must have the input's "
                                f"format ({args.file.suffix}); use 'usdhands convert' first or after", path=args.output)


def _graft(args, asset, clip, handmap, db, sides, explicit):
    """Add finger joints for ``sides`` (those with a wrist) from the database's hand templates."""
    from usdhands.algorithms.synthesis.hand_graft import find_wrists, graft_hands
    from usdhands.model.handmap import HandMap, HandSide

    if asset.meshes:
        raise UsdHandsError("--graft-hands works on skeleton-only files (BVH, USD without skinned meshes): "
                            "this file has skinned meshes, which would need new skin weights", path=args.file)
    sk = clip.skeleton
    wrists = find_wrists(sk)
    todo = {}
    for side in sides:
        if handmap[side] is not None:
            h = handmap[side]
        elif side in wrists:
            w = wrists[side]
            chain = sk.chain_to_root(w)
            name = lambda i: sk.joint_names[chain[i]] if i < len(chain) else None  # noqa: E731
            h = HandSide(side, name(0), name(1), name(2), sk.joint_names[chain[-1]])
        elif explicit:
            raise UsdHandsError(f"--graft-hands: no {side} wrist joint found (looked for names with hand or wrist "
                                f"and a side: LeftHand, hand_l, Wrist.R, ...)", path=args.file)
        else:
            continue
        if side not in db.hands:
            raise UsdHandsError(f"the database holds no {side} hand geometry to graft (rebuild it with this "
                                f"version of usdhands, or with --mirror)", path=db.path)
        todo[side] = h
    if not todo:
        raise UsdHandsError("--graft-hands: no wrist joint found (looked for names with hand or wrist and a side: "
                            "LeftHand, hand_l, Wrist.R, ...); give --handmap", path=args.file)
    clip, grafted, added = graft_hands(clip, todo, db.hands)
    merged = {s: grafted[s] if s in todo else handmap[s] for s in SIDES_}
    return clip, HandMap(**merged), added


SIDES_ = ("left", "right")


def _report(result, db, cfg) -> dict:
    from collections import Counter

    import numpy as np

    labels = db.segment_labels()
    hands = {}
    for side, h in result.hands.items():
        chosen = [labels[s] for s in h.chosen]
        counts = Counter("(no label)" if c is None else str(c) for c in chosen)
        hands[side] = {
            "segments": int(len(h.chosen)),
            "chosen_labels": [None if c is None else str(c) for c in chosen],
            "top_labels": ", ".join(f"{lab} {n}" for lab, n in counts.most_common(3)),
            "mean_segment_cost": float(np.mean(h.segment_costs[np.arange(len(h.path)), h.path])),
            "seams": int(len(h.seams.frame)),
            "seams_blended": int(h.seams.blended.sum()),
            "pruned_share": float(h.search.pruned_share),
            "body_scale": float(result.scale[side]),
        }
    return {"database": str(db.path), "k": cfg.segment_cost.k, "hands": hands, "mapping": result.mapping}


def _plots(folder: Path, clip, result, db, cfg) -> list[Path]:
    import numpy as np

    from usdhands.commands._synthesis_plots import plot_finger_curves, plot_graph, plot_segmentation
    from usdhands.model.finger_dofs import finger_curves

    folder.mkdir(parents=True, exist_ok=True)
    labels = db.segment_labels()
    out = []
    for side, h in result.hands.items():
        out.append(plot_segmentation(h, db.fps, cfg.segmentation.speed_threshold_cm_s, folder / f"{side}_segments.png"))
        out.append(plot_graph(h, labels, folder / f"{side}_graph.png"))
        mapped = result.mapping[side]["mapped"]
        # the most proximal phalanx of each finger (slot d2, else the most proximal mapped)
        pick = []
        for finger in ("thumb", "index", "middle", "ring", "pinky"):
            js = sorted((slot, j) for j, slot in mapped if slot.startswith(finger + ".") and slot[-1] != "3")
            if js:
                pick.append(js[-1][1])
        joints = [clip.skeleton.index(j) for j in pick]
        before = finger_curves(clip, joints)
        after = finger_curves(result.clip, joints)
        # per joint, the axis that moves most (the flexion on most rigs)
        rng = np.ptp(after.values, axis=0).reshape(len(joints), 3)
        cols = [3 * i + int(np.argmax(rng[i])) for i in range(len(joints))]
        times = np.arange(clip.num_frames) / clip.fps
        out.append(plot_finger_curves(times, before.values[:, cols], after.values[:, cols],
                                      [after.names[c] for c in cols], folder / f"{side}_fingers.png",
                                      h.bounds[1:-1] / db.fps))
    return out

"""``usdhands db build`` / ``usdhands db info``: finger-motion databases for ``synthesize``.

``db build INPUTS... -o DB`` reads clips with fingers in any supported format and
writes a database folder (manifest.json + .npy arrays, see docs/synthesis.md):
per hand, wrist features, finger DOF curves, segments, labels and where each came
from. ``--samples`` builds from the generated gesture set instead of files (this is
how the database bundled in the package is made). ``db info DB`` prints what a
database holds.
"""

from __future__ import annotations

import sys
from pathlib import Path

from usdhands.commands._common import Progress, add_prop_arguments, print_json, print_table
from usdhands.jobs.option_checks import check_fps
from usdhands.jobs.props import check_prop_options
from usdhands.jobs.outputs import MAIN_INPUT, check_paths
from usdhands.errors import UsdHandsError


def register(sub) -> None:
    p = sub.add_parser("db", help="build or inspect a finger-motion database for 'synthesize'",
                       description="Finger-motion databases (Jorg, Hodgins, Safonova 2012).")
    dsub = p.add_subparsers(dest="db_command", metavar="ACTION")
    b = dsub.add_parser("build", help="build a database from clips with fingers",
                        description="Build a finger-motion database folder from clips with finger animation.")
    b.add_argument("inputs", type=Path, nargs="*", help="animation files or folders (.usd*, .gltf/.glb, .bvh)")
    b.add_argument("-o", "--output", type=Path, required=True, help="database folder to write")
    b.add_argument("--labels", default=None, metavar="REGEX",
                   help="label of a clip: the first group of REGEX searched in its file name")
    b.add_argument("--labels-file", type=Path, default=None, metavar="CSV", help="rows 'file,label'")
    b.add_argument("--mirror", action="store_true", help="add left<->right mirrored copies of every hand")
    b.add_argument("--fps", type=float, default=30.0, help="frame rate of the database (default 30)")
    b.add_argument("--config", type=Path, default=None, help="synthesis configuration JSON (segmentation values)")
    b.add_argument("--handmap", type=Path, default=None, help="hand map JSON overriding detection (all inputs)")
    b.add_argument("--animation", default=None,
                   help="animation name or index in each file (default the first), or 'all': every animation "
                        "of every file, each a clip labelled like its file")
    b.add_argument("--samples", action="store_true",
                   help="build from the generated gesture set (usdhands.samples) instead of files")
    b.add_argument("--json", action="store_true", help="print the manifest's counts as JSON")
    add_prop_arguments(b, required=False)
    b.set_defaults(func=run_build)
    i = dsub.add_parser("info", help="print what a database holds",
                        description="Print what a finger-motion database holds: clips, hand tracks, segments, "
                                    "frames and frame rate, finger DOFs and arm reach, then the segments of "
                                    "each gesture label per hand (--json: the whole manifest). Without a "
                                    "folder, the database bundled in the package (the one synthesize uses "
                                    "without --db).")
    i.add_argument("database", type=Path, nargs="?", default=None, help="database folder (default: the bundled one)")
    i.add_argument("--json", action="store_true", help="print the manifest as JSON")
    i.set_defaults(func=run_info)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def run_build(args) -> int:
    check_fps(args.fps)
    from usdhands.algorithms.synthesis.database import DatabaseClip, build_database, save_database
    from usdhands.jobs.inputs import (
        expand_inputs, labeller, load_config, read_labelled, sample_database_items, still_hands,
    )

    if args.samples and args.inputs:
        raise UsdHandsError("give input files or --samples, not both")
    if not args.samples and not args.inputs:
        raise UsdHandsError("no input files given (or use --samples)")
    paths = [] if args.samples else expand_inputs(args.inputs)
    check_paths({MAIN_INPUT: [*args.inputs, *paths], "--labels-file": args.labels_file, "--config": args.config,
                 "--handmap": args.handmap, "--props": args.props, "--interaction-config": args.interaction_config},
                replaced_folders={"-o": args.output})
    cfg = load_config(args.config)
    if args.props:
        check_prop_options(args)
    if args.props and args.samples:
        raise UsdHandsError("--props corrects input files; --samples has none")
    if args.samples:
        items = sample_database_items()
    else:
        label_of = labeller(args.labels, args.labels_file)
        if args.animation == "all":
            read = _read_all_animations(paths, label_of, args.handmap, Progress("reading"))
        else:
            read = read_labelled(paths, label_of, None, args.handmap, args.animation, Progress("reading"))
        items = []
        for p, label, clip, handmap in read:
            if not any(h.finger_joints for h in handmap.sides):
                raise UsdHandsError("no finger joints found: a database needs clips with finger animation", path=p)
            if args.props:  # interaction clips: the database holds their corrected fingers
                from usdhands.jobs.props import corrected_for_props

                clip, summary = corrected_for_props(args, p, clip, handmap)
                after = summary["penetration_after_mm"]
                print(f"usdhands: note: {p}: corrected against the props, {summary['frames_corrected']} frames "
                      f"(penetration {summary['penetration_before_mm']['max']:.2f} -> {after['max']:.2f} mm)",
                      file=sys.stderr)
            items.append(DatabaseClip(clip, handmap, label, str(p)))
            still = still_hands(clip, handmap)
            if still and len(still) == sum(1 for h in handmap.sides if h.finger_joints):  # one idle hand is normal
                where = f"{p} (animation {clip.name!r})" if args.animation == "all" else str(p)
                print(f"usdhands: warning: {where}: the {' and '.join(still)} hand's fingers never move (a body-only "
                      f"clip?); its frozen fingers go into the database as they are", file=sys.stderr)
    db = build_database(items, fps=args.fps, mirror=args.mirror, segmentation=cfg.segmentation,
                        progress=Progress("building"))
    path = save_database(db, args.output)
    m = db.manifest()
    if args.json:
        print_json({"path": str(path), **m["counts"], "labels": m["labels"], "dofs": len(m["dofs"])})
    else:
        _print_summary(db, path)
    return 0


def _read_all_animations(paths, label_of, handmap_path, progress):
    """``(path, label, clip, handmap)`` for every animation of every file."""
    from usdhands.jobs.inputs import handmap_for
    from usdhands.formats.io import read_asset

    out = []
    for i, p in enumerate(paths):
        label = label_of(p)
        asset = read_asset(p)
        if not asset.clips:
            raise UsdHandsError("no animation in file", path=p)
        handmap = handmap_for(asset.clips[0], p, handmap_path)
        for clip in asset.clips:
            out.append((p, label, clip, handmap if clip.skeleton is asset.clips[0].skeleton
                        else handmap_for(clip, p, handmap_path)))
        progress(i + 1, len(paths), p.name)
    return out


def _print_summary(db, path) -> None:
    import numpy as np

    from usdhands.model.handmap import SIDES

    m = db.manifest()
    print(f"database {path}: {m['counts']['clips']} clips, {m['counts']['tracks']} hand tracks, "
          f"{m['counts']['segments']} segments, {m['counts']['frames']} frames at {db.fps:g} fps "
          f"({m['counts']['frames'] / db.fps / 60:.1f} min), {len(m['dofs'])} finger DOFs, reach {db.reach_cm:.1f} cm")
    labels = db.segment_labels()
    side = db.segment_side()
    rows = []
    names = ["(no label)" if x is None else str(x) for x in labels]
    for lab in sorted(set(names)):
        sel = np.array([x == lab for x in names])
        rows.append([lab, int((sel & (side == 0)).sum()), int((sel & (side == 1)).sum())])
    print_table(rows, ["label", f"{SIDES[0]} segments", f"{SIDES[1]} segments"])


def run_info(args) -> int:
    from usdhands.algorithms.synthesis.database import load_database
    from usdhands.jobs.inputs import bundled_database_path

    path = args.database or bundled_database_path()
    db = load_database(path)
    if args.json:
        print_json(db.manifest())
    else:
        _print_summary(db, path)
    return 0

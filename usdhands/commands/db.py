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


def options_from(args):
    """The build job's options from parsed arguments."""
    from usdhands.jobs.database import BuildDbOptions

    return BuildDbOptions(labels=args.labels, labels_file=args.labels_file, mirror=args.mirror, fps=args.fps,
                          config=args.config, handmap=args.handmap, animation=args.animation, samples=args.samples,
                          props=tuple(args.props), margin=args.margin, self_collision=args.self_collision,
                          attach=tuple(args.attach), prop_units=args.prop_units, prop_up=args.prop_up,
                          interaction_config=args.interaction_config)


def run_build(args) -> int:
    from usdhands.jobs.database import build_db

    summary = build_db(args.inputs, args.output, options_from(args), progress=Progress("db build"))
    for level, text in summary.messages:
        print(f"usdhands: {level}: {text}", file=sys.stderr)
    if args.json:
        print_json(summary.to_json())
    else:
        _print_summary(summary)
    return 0


def _print_summary(summary) -> None:
    from usdhands.model.handmap import SIDES

    m, fps = summary.manifest, summary.fps
    print(f"database {summary.path}: {m['counts']['clips']} clips, {m['counts']['tracks']} hand tracks, "
          f"{m['counts']['segments']} segments, {m['counts']['frames']} frames at {fps:g} fps "
          f"({m['counts']['frames'] / fps / 60:.1f} min), {len(m['dofs'])} finger DOFs, "
          f"reach {summary.reach_cm:.1f} cm")
    print_table([list(row) for row in summary.segments_by_label],
                ["label", f"{SIDES[0]} segments", f"{SIDES[1]} segments"])


def run_info(args) -> int:
    from usdhands.jobs.database import database_info

    summary = database_info(args.database)
    if args.json:
        print_json(summary.manifest)
    else:
        _print_summary(summary)
    return 0

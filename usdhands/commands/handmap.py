"""``usdhands handmap FILE [-o MAP.json] [--json] [--write-schema OUT [--as-layer]]``: the detected hands of a
skeleton, as a table or JSON, or authored on a USD Skeleton as ``UsdHandsHandMapAPI``."""

from __future__ import annotations

import sys
from pathlib import Path

from usdhands.commands._common import add_layer_argument, print_json, print_table
from usdhands.model.handmap import FINGERS, SIDES, HandMap
from usdhands.model.skeleton import display_joint_names, short_joint_name


def register(sub) -> None:
    p = sub.add_parser("handmap", help="show the detected hands of a skeleton; write them as a hand map JSON",
                       description="Detect the wrist, forearm, shoulder, root and five finger chains of each "
                                   "hand of a skeleton and print them. With -o, write them as a hand map JSON "
                                   "(schemas/handmap.schema.json) to edit and pass back with --handmap.")
    p.add_argument("file", type=Path, help="a .usd/.usda/.usdc/.usdz, .gltf/.glb or .bvh file")
    p.add_argument("-o", "--output", type=Path, default=None, help="write the hand map JSON here")
    p.add_argument("--animation", default=None,
                   help="use the skeleton of this animation (name or 0-based index); default the first skeleton")
    p.add_argument("--skeleton", default=None, help="skeleton name or 0-based index (files with several)")
    p.add_argument("--side", choices=SIDES, default=None,
                   help="side of a single hand whose joint names give none (WebXR); default: from the file name")
    p.add_argument("--handmap", type=Path, default=None,
                   help="check this hand map JSON against the skeleton instead of detecting "
                        "(default: the map a USD file records with UsdHandsHandMapAPI, else detection)")
    p.add_argument("--write-schema", type=Path, default=None, metavar="OUT",
                   help="USD: write the hands onto the Skeleton prim as UsdHandsHandMapAPI, in a copy of FILE "
                        "(or, with --as-layer, a sparse layer over it) at OUT (.usd, .usda, .usdc)")
    add_layer_argument(p, "FILE (with --write-schema)")
    p.add_argument("--json", action="store_true",
                   help="print the hand map as JSON (the -o file's content, with the file and where the map came from)")
    p.set_defaults(func=run)


def handmap_rows(hm: HandMap, joint_names=()) -> list[tuple]:
    """Table rows ``(side, part, joints)`` with short joint names where they are unambiguous among ``joint_names``."""
    shown = display_joint_names(joint_names)
    short = lambda j: shown.get(j, short_joint_name(j))  # noqa: E731
    rows = []
    for side in SIDES:
        h = hm[side]
        if h is None:
            rows.append((side, "-", "(no hand found)"))
            continue
        for part in ("wrist", "forearm", "shoulder", "root"):
            j = getattr(h, part)
            rows.append((side, part, "-" if j is None else short(j)))
        for f in FINGERS:
            rows.append((side, f, " ".join(short(j) for j in h.fingers[f]) or "(absent)"))
    return rows


def run(args) -> int:
    from usdhands.jobs.hand_mapping import HandMapOptions, map_hands

    options = HandMapOptions(animation=args.animation, skeleton=args.skeleton, side=args.side, handmap=args.handmap,
                             as_layer=args.layer)
    result = map_hands(args.file, args.output, options, schema_output=args.write_schema)
    origin = {"override": f"from {args.handmap}", "file": "recorded in the file (UsdHandsHandMapAPI)",
              "detected": "detected"}[result.source]
    if args.json:
        print_json(result.to_json())
    else:
        print(f"{args.file}: skeleton {result.skeleton!r}, {result.num_joints} joints; hands {origin}")
        print_table(handmap_rows(result.handmap, result.joint_names), ["side", "part", "joints (proximal to distal)"])
    if args.output is not None:
        print(f"wrote {args.output}", file=sys.stderr)
    if args.write_schema is not None:
        print(f"wrote {args.write_schema}: UsdHandsHandMapAPI on {result.skeleton}"
              f"{' (a layer over ' + str(args.file) + ')' if args.layer else ''}", file=sys.stderr)
    return 0

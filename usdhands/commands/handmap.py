"""``usdhands handmap FILE [-o MAP.json] [--json] [--write-schema OUT [--as-layer]]``: the detected hands of a
skeleton, as a table or JSON, or authored on a USD Skeleton as ``UsdHandsHandMapAPI``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from usdhands.commands._common import print_json, print_table
from usdhands.commands._common import add_layer_argument
from usdhands.jobs.outputs import MAIN_INPUT, USD_LAYER_SUFFIXES, check_paths, layer_options
from usdhands.errors import AssetReadError, NoSkeletonError, UsdHandsError
from usdhands.formats.hands import hands_for
from usdhands.formats.io import read_asset
from usdhands.formats.registry import atomic_output
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


def _pick_skeleton(asset, path: Path, animation, skeleton):
    if not asset.skeletons:
        raise NoSkeletonError("no skeleton in file", path=path)
    if animation is not None:
        try:
            return asset.clip(animation).skeleton
        except KeyError as e:
            raise AssetReadError(str(e.args[0]).split(": ", 1)[-1], path=path) from None
    if skeleton is None:
        return asset.skeletons[0]
    for i, sk in enumerate(asset.skeletons):
        if sk.name == skeleton or short_joint_name(sk.name) == skeleton or str(i) == str(skeleton):
            return sk
    names = ", ".join(repr(s.name) for s in asset.skeletons)
    raise AssetReadError(f"no skeleton named {skeleton!r}; there are {names}", path=path)


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
    check_paths({MAIN_INPUT: args.file, "--handmap": args.handmap},
                {"-o": args.output, "--write-schema": args.write_schema})
    if args.write_schema is not None:
        _check_schema_output(args)
    elif args.layer:
        raise UsdHandsError("--as-layer goes with --write-schema OUT", path=args.file)
    asset = read_asset(args.file)
    sk = _pick_skeleton(asset, args.file, args.animation, args.skeleton)
    hm, source = hands_for(args.file, sk, args.handmap, side_hint=args.side)
    origin = {"override": f"from {args.handmap}", "file": "recorded in the file (UsdHandsHandMapAPI)",
              "detected": "detected"}[source]
    data = {"skeleton": sk.name, **hm.to_dict()}
    if args.output is not None:
        with atomic_output(args.output) as tmp:
            tmp.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    if args.json:
        print_json({"file": str(args.file), "source": source, "num_joints": sk.num_joints, **data})
    else:
        print(f"{args.file}: skeleton {sk.name!r}, {sk.num_joints} joints; hands {origin}")
        print_table(handmap_rows(hm, sk.joint_names), ["side", "part", "joints (proximal to distal)"])
    if args.output is not None:
        print(f"wrote {args.output}", file=sys.stderr)
    if args.write_schema is not None:
        from usdhands.formats.usd_write import write_usd_hand_map

        with atomic_output(args.write_schema) as tmp:
            write_usd_hand_map(args.file, sk.name, hm, tmp, final_path=args.write_schema, as_layer=args.layer)
        print(f"wrote {args.write_schema}: UsdHandsHandMapAPI on {sk.name}"
              f"{' (a layer over ' + str(args.file) + ')' if args.layer else ''}", file=sys.stderr)
    return 0


def _check_schema_output(args) -> None:
    """``--write-schema`` needs USD in and out (checked before any work)."""
    if args.file.suffix.lower() not in USD_LAYER_SUFFIXES + (".usdz",):
        raise UsdHandsError("--write-schema needs a USD input (the schema is authored on its Skeleton prim)",
                            path=args.file)
    if args.write_schema.suffix.lower() not in USD_LAYER_SUFFIXES:
        raise UsdHandsError("--write-schema needs a USD output (.usd, .usda, .usdc)", path=args.write_schema)
    layer_options(args.layer, args.file, args.write_schema)

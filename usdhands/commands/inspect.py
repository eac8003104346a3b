"""``usdhands inspect FILE [--json]``: skeletons, joints, animations and hands of a file."""

from __future__ import annotations

from pathlib import Path

from usdhands.commands._common import print_json, print_table
from usdhands.model.handmap import FINGERS, SIDES
from usdhands.model.skeleton import display_joint_names


def register(sub) -> None:
    p = sub.add_parser("inspect", help="list skeletons, joints, animations and detected hands",
                       description="List the skeletons, joints, animations and detected hands of a USD, "
                                   "glTF or BVH file.")
    p.add_argument("file", type=Path, help="a .usd/.usda/.usdc/.usdz, .gltf/.glb or .bvh file")
    p.add_argument("--json", action="store_true", help="print JSON instead of tables")
    p.add_argument("--handmap", type=Path, default=None, help="hand map JSON overriding detection")
    p.set_defaults(func=run)


def run(args) -> int:
    from usdhands.jobs.inspection import InspectOptions, inspect_file

    report = inspect_file(args.file, InspectOptions(handmap=args.handmap)).to_json()
    if args.json:
        print_json(report)
        return 0
    print(f"{report['file']}")
    if not report["skeletons"]:
        print("no skeleton")
        if report["meshes"]:
            print()
            print_table([(m["name"], m["points"], m["faces"], m["influences"]) for m in report["meshes"]],
                        ["mesh", "points", "faces", "influences"])
        return 0
    print_table([(s["name"], s["num_joints"], s["meters_per_unit"], s["up_axis"]) for s in report["skeletons"]],
                ["skeleton", "joints", "m/unit", "up"])
    print()
    if report["animations"]:
        print_table([(a["name"], a["frames"], a["fps"], round(a["duration"], 3)) for a in report["animations"]],
                    ["animation", "frames", "fps", "seconds"])
    else:
        print("no animation")
    print()
    shown = {}  # short joint names where unambiguous in their skeleton (the JSON keeps full paths)
    for s in reversed(report["skeletons"]):
        shown.update(display_joint_names(s["joints"]))
    rows = []
    for side in SIDES:
        h = report["hands"][side]
        if h is None:
            rows.append((side, "-", "(none)", ""))
            continue
        for f in FINGERS:
            rows.append((side, shown.get(h["wrist"], h["wrist"]), f,
                         " ".join(shown.get(j, j) for j in h["fingers"][f]) or "(absent)"))
    print_table(rows, ["side", "wrist", "finger", "joints (proximal to distal)"])
    if report["meshes"]:
        print()
        print_table([(m["name"], m["points"], m["faces"], m["influences"]) for m in report["meshes"]],
                    ["mesh", "points", "faces", "influences"])
    return 0

"""``usdhands inspect FILE [--json]``: skeletons, joints, animations and hands of a file."""

from __future__ import annotations

from pathlib import Path

from usdhands.commands._common import print_json, print_table
from usdhands.jobs.outputs import MAIN_INPUT, check_paths
from usdhands.errors import NoHandsError
from usdhands.formats.hands import hands_for
from usdhands.formats.io import read_asset
from usdhands.model.handmap import FINGERS, SIDES, HandMap
from usdhands.model.skeleton import display_joint_names


def register(sub) -> None:
    p = sub.add_parser("inspect", help="list skeletons, joints, animations and detected hands",
                       description="List the skeletons, joints, animations and detected hands of a USD, "
                                   "glTF or BVH file.")
    p.add_argument("file", type=Path, help="a .usd/.usda/.usdc/.usdz, .gltf/.glb or .bvh file")
    p.add_argument("--json", action="store_true", help="print JSON instead of tables")
    p.add_argument("--handmap", type=Path, default=None, help="hand map JSON overriding detection")
    p.set_defaults(func=run)


def _hands(path: Path, skeleton, override) -> HandMap:
    try:
        return hands_for(path, skeleton, override)[0]
    except NoHandsError:
        return HandMap()


def inspect_asset(path: Path, handmap_path: Path | None = None) -> dict:
    """The report ``usdhands inspect --json`` prints, as a dict."""
    asset = read_asset(path)
    skeletons = []
    hands = HandMap()
    for sk in asset.skeletons:
        hm = _hands(path, sk, handmap_path)
        if hands.left is None and hands.right is None:
            hands = hm
        skeletons.append({
            "name": sk.name,
            "joints": list(sk.joint_names),
            "num_joints": sk.num_joints,
            "meters_per_unit": sk.meters_per_unit,
            "up_axis": sk.up_axis,
            "hands": hm.to_dict(),
        })
    animations = []
    for clip in asset.clips:
        animations.append({
            "name": clip.name,
            "skeleton": asset.skeletons.index(clip.skeleton) if clip.skeleton in asset.skeletons else None,
            "frames": clip.num_frames,
            "fps": clip.fps,
            "duration": clip.duration,
        })
    meshes = [{"name": m.name, "points": int(len(m.points)), "faces": int(len(m.face_vertex_counts)),
               "influences": None if m.joint_indices is None else int(m.joint_indices.shape[1])}
              for m in asset.meshes]
    return {"file": str(path), "skeletons": skeletons, "animations": animations, "meshes": meshes,
            "hands": hands.to_dict()}


def run(args) -> int:
    check_paths({MAIN_INPUT: args.file, "--handmap": args.handmap})
    report = inspect_asset(args.file, args.handmap)
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

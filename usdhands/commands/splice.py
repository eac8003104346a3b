"""``usdhands splice BODY HANDS -o OUT``: put separately captured hand motion onto a body clip.

Majkowska, Zordan and Faloutsos 2006: two-pass DTW (phases by the signs of marker
derivatives, then the forearm-aligned hand angle inside a narrow band), user
constraints ``--match BODY_FRAME:HAND_FRAME[:TOLERANCE]`` (0-based, in each file's own
frames), then the hand's finger rotations, relative to rest, written onto BODY's
finger joints. See docs/splicing.md.
"""

from __future__ import annotations

import sys
from pathlib import Path

from usdhands.commands._common import Progress, add_layer_argument, print_json, print_table


def register(sub) -> None:
    p = sub.add_parser(
        "splice", help="splice separately captured hand motion onto a body clip (two-pass DTW)",
        description="Align a hand capture (HANDS: forearm, wrist and fingers; a partial skeleton is fine) "
                    "to a full-body clip (BODY) in time with two-pass dynamic time warping (Majkowska et al. "
                    "2006) and write BODY with the hand capture's finger motion. Frame numbers are 0-based.")
    p.add_argument("body", type=Path, help="full-body animation (.usd/.usda/.usdc/.usdz, .gltf/.glb, .bvh)")
    p.add_argument("hands", type=Path, help="hand animation with forearm, wrist and fingers")
    p.add_argument("-o", "--output", type=Path, required=True, help="output file (same format as BODY)")
    p.add_argument("--side", choices=("left", "right", "both"), default="both",
                   help="hands to splice (default both: every hand found in both files)")
    p.add_argument("--match", action="append", default=[], metavar="BODY_FRAME:HAND_FRAME[:TOLERANCE]",
                   help="make body frame and hand frame match, exactly or within TOLERANCE hand frames; repeatable, "
                        "in increasing order")
    p.add_argument("--band", default="0.3,0.1", metavar="W1,W2",
                   help="band half-widths of the two passes as fractions of the body length (default 0.3,0.1)")
    p.add_argument("--yaw", choices=("window", "trunk", "none"), default="window",
                   help="turn about the vertical axis: eq. 7 over 5-frame windows (default), trunk headings, or none")
    p.add_argument("--hand-yaw", type=float, default=0.0, metavar="DEG",
                   help="with --yaw trunk: heading of the hand capture when HANDS has no trunk (default 0)")
    p.add_argument("--forearm-align", choices=("frame", "vector"), default="frame",
                   help="second pass: align forearm joint frames (default) or forearm marker vectors as in the paper")
    p.add_argument("--transfer", choices=("auto", "local", "copy", "hand"), default="auto",
                   help="finger rotations relative to rest copied joint to joint (local), local rotations as they "
                        "are (copy: same joint frames, other rest rotations), or relative to rest through the "
                        "hands' rest axes (hand: other joint axes); auto picks by comparing the rigs (default)")
    p.add_argument("--blend", type=int, default=4, metavar="N",
                   help="frames on each side of a jump in hand timing to cross-fade (default 4)")
    p.add_argument("--json", action="store_true", help="print the alignment, phases and costs as JSON")
    p.add_argument("--plot", type=Path, default=None, metavar="DIR",
                   help="draw the cost matrices with band and path (splice_<side>.png) into DIR")
    p.add_argument("--animation", default=None, help="BODY animation name or index (default the first)")
    p.add_argument("--hands-animation", default=None, help="HANDS animation name or index (default the first)")
    p.add_argument("--body-markers", type=Path, default=None, metavar="CSV",
                   help="real marker positions for BODY instead of markers placed on the joints: one row per "
                        "frame, columns <side>.<marker>.<x|y|z> with marker wrist_a, wrist_b, forearm, hand "
                        "(centimetres, Y up; an optional first column 'frame')")
    p.add_argument("--hands-markers", type=Path, default=None, metavar="CSV",
                   help="real marker positions for HANDS, as --body-markers (HANDS's own frames)")
    p.add_argument("--body-handmap", type=Path, default=None, help="hand map JSON for BODY (overrides detection)")
    p.add_argument("--hands-handmap", type=Path, default=None, help="hand map JSON for HANDS (overrides detection)")
    add_layer_argument(p, "BODY")
    p.set_defaults(func=run)


def run(args) -> int:
    from usdhands.jobs.splicing import SpliceOptions, parse_band, splice

    options = SpliceOptions(side=args.side, match=tuple(args.match), band=parse_band(args.band), yaw=args.yaw,
                            hand_yaw=args.hand_yaw, forearm_align=args.forearm_align, transfer=args.transfer,
                            blend=args.blend, animation=args.animation, hands_animation=args.hands_animation,
                            body_markers=args.body_markers, hands_markers=args.hands_markers,
                            body_handmap=args.body_handmap, hands_handmap=args.hands_handmap, as_layer=args.layer,
                            plot=args.plot)
    result = splice(args.body, args.hands, args.output, options, progress=Progress("splice"))
    for note in result.notes:
        print(f"usdhands: note: {note}", file=sys.stderr)
    if args.json:
        print_json(result.to_json())
        return 0
    report = result.report
    rows = []
    for s in result.sides:
        c = report["costs"][s]
        rows.append([s, report["body_frames"], report["hand_frames"], len(report["phases"][s]), c["first_pass"],
                     c["second_pass_mean_deg"], len(report["seams"][s]), len(report["pairs"][s])])
    print_table(rows, ["hand", "body frames", "hand frames", "phases", "pass-1 cost", "pass-2 mean deg",
                       "blended jumps", "finger joints"])
    print(f"wrote {args.output}")
    return 0

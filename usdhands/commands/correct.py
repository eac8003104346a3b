"""``usdhands correct IN --props P... -o OUT``: push fingers out of props (and the body), smoothly.

Reads the animation and the props, detects where finger capsules penetrate, opens each
penetrating finger chain by the least amount that clears every collider (IK within the
joint limits), smooths the correction with the contact as a bound and writes the result
into a copy of IN (or a USD layer over it). Nothing penetrates deeper than 0.25 mm
afterwards (half the clearance search's resolution); fingers that were clear are left
bit-for-bit unchanged and body joints are never touched.
"""

from __future__ import annotations

import sys
from pathlib import Path

from usdhands.commands._common import Progress, add_layer_argument, add_prop_arguments, print_json, print_table


def register(sub) -> None:
    p = sub.add_parser("correct", help="push fingers out of props and the body (IK + bounded smoothing)",
                       description="Correct finger penetration of props (and, with --self, of the body): "
                                   "the least opening of each finger chain that clears every collider, "
                                   "smoothed without letting any contact back in.")
    p.add_argument("file", type=Path, help="input animation (.usd/.usda/.usdc/.usdz, .gltf/.glb, .bvh)")
    p.add_argument("-o", "--output", type=Path, required=True, help="output file (same format as the input)")
    add_prop_arguments(p, required=True)
    add_layer_argument(p)
    p.add_argument("--handmap", type=Path, default=None, help="hand map JSON overriding detection")
    p.add_argument("--animation", default=None, help="animation name or index in the file (default the first)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--plot", type=Path, default=None, metavar="DIR",
                   help="write penetration_depth.png and worst_frame.png into DIR")
    p.set_defaults(func=run)


def options_from(args):
    """The job's options from parsed arguments."""
    from usdhands.jobs.correction import CorrectOptions

    return CorrectOptions(props=tuple(args.props), margin=args.margin, self_collision=args.self_collision,
                          attach=tuple(args.attach), prop_units=args.prop_units, prop_up=args.prop_up,
                          interaction_config=args.interaction_config, as_layer=args.layer, handmap=args.handmap,
                          animation=args.animation, plot=args.plot)


def run(args) -> int:
    from usdhands.jobs.correction import correct

    result = correct(args.file, args.output, options_from(args), progress=Progress("correct"))
    for w in result.warnings:
        print(f"usdhands: note: {w}", file=sys.stderr)
    summary = result.to_json()
    if args.json:
        print_json(summary)
        return 0
    rows = []
    for key in ("penetration_before_mm", "penetration_after_mm"):
        s = summary[key]
        rows.append((key, f"max {s['max']:.3f}  mean {s['mean']:.3f}  frames {s['frames']}"))
    rows += [("frames_corrected", summary["frames_corrected"]),
             ("jitter_before", f"{summary['jitter_before']:.1f} deg/s^2"),
             ("jitter_after", f"{summary['jitter_after']:.1f} deg/s^2"),
             ("max_change_deg", f"{summary['max_change_deg']:.2f}"),
             ("chains_corrected", ", ".join(result.chains_corrected) or "none")]
    print_table(rows, ("measure", "value"))
    print(f"wrote {result.output}")
    return 0

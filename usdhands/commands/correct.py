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
import time
from pathlib import Path

from usdhands.commands._common import add_layer_argument, add_prop_arguments, print_json, print_table
from usdhands.jobs.outputs import MAIN_INPUT, check_paths, layer_options
from usdhands.jobs.props import build_colliders, check_prop_options, read_scene_props


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


def run(args) -> int:
    from usdhands.algorithms.interaction.correction import correct_clip
    from usdhands.algorithms.interaction.finger_geometry import InteractionConfig, load_interaction_config
    from usdhands.jobs.inputs import check_plot_folder, handmap_for
    from usdhands.formats.io import read_clip, write_clip

    check_paths({MAIN_INPUT: args.file, "--props": args.props, "--handmap": args.handmap,
                 "--interaction-config": args.interaction_config}, {"-o": args.output})
    write_opts = layer_options(args.layer, args.file, args.output)
    check_prop_options(args)
    check_plot_folder(args.plot)
    config = load_interaction_config(args.interaction_config) if args.interaction_config else InteractionConfig()
    clip = read_clip(args.file, animation=args.animation)
    handmap = handmap_for(clip, args.file, args.handmap)
    props = read_scene_props(args, clip)
    colliders, _ = build_colliders(args, clip, handmap, props, path=args.file)
    start = time.perf_counter()
    out, report = correct_clip(clip, handmap, colliders, margin_mm=args.margin, config=config)
    seconds = time.perf_counter() - start
    from dataclasses import asdict

    from usdhands.model.provenance import provenance_record

    record = provenance_record("interaction", parameters={
        "props": [str(p) for p in args.props], "margin_mm": args.margin, "config": asdict(config)})
    written = write_clip(args.file, out, args.output, provenance=record, **write_opts)
    if report.unresolved:
        chains = sorted({c for c, _ in report.unresolved})
        print(f"usdhands: note: {len(report.unresolved)} chain frames touch even with the finger open "
              f"({', '.join(chains)}): the palm or wrist is in a prop there and only body motion could clear it",
              file=sys.stderr)
    if args.plot is not None:
        from usdhands.commands._interaction_plots import plot_correction

        plot_correction(args.plot, clip, out, handmap, colliders, report, config)
    summary = {"file": str(args.file), "output": str(written), "frames": int(clip.num_frames),
               "props": [str(p) for p in args.props], **report.to_dict(),
               "chains_corrected": report.chains_corrected, "unresolved_frames": len(report.unresolved),
               "seconds": round(seconds, 3)}
    if args.json:
        print_json(summary)
    else:
        rows = []
        for key in ("penetration_before_mm", "penetration_after_mm"):
            s = summary[key]
            rows.append((key, f"max {s['max']:.3f}  mean {s['mean']:.3f}  frames {s['frames']}"))
        rows += [("frames_corrected", summary["frames_corrected"]),
                 ("jitter_before", f"{summary['jitter_before']:.1f} deg/s^2"),
                 ("jitter_after", f"{summary['jitter_after']:.1f} deg/s^2"),
                 ("max_change_deg", f"{summary['max_change_deg']:.2f}"),
                 ("chains_corrected", ", ".join(report.chains_corrected) or "none")]
        print_table(rows, ("measure", "value"))
        print(f"wrote {written}")
    return 0

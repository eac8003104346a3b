"""``usdhands splice BODY HANDS -o OUT``: put separately captured hand motion onto a body clip.

Majkowska, Zordan and Faloutsos 2006: two-pass DTW (phases by the signs of marker
derivatives, then the forearm-aligned hand angle inside a narrow band), user
constraints ``--match BODY_FRAME:HAND_FRAME[:TOLERANCE]`` (0-based, in each file's own
frames), then the hand's finger rotations, relative to rest, written onto BODY's
finger joints. See docs/splicing.md.
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

from usdhands.commands._common import Progress, print_json, print_table
from usdhands.commands._output import MAIN_INPUT, add_layer_argument, check_paths, layer_options
from usdhands.errors import UsdHandsError

DURATION_RATIO_NOTE = 1.5
"""A note when one clip lasts this many times longer than the other."""
MATCH_RE = re.compile(r"^(\d+):(\d+)(?::(\d+))?$")


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


def parse_match(text: str):
    """``"12:30"`` or ``"12:30:2"`` → Constraint; UsdHandsError otherwise."""
    from usdhands.algorithms.dtw import Constraint

    mt = MATCH_RE.match(text.strip())
    if not mt:
        raise UsdHandsError(f"bad --match {text!r}: expected BODY_FRAME:HAND_FRAME[:TOLERANCE] "
                            "with 0-based frame numbers")
    return Constraint(int(mt.group(1)), int(mt.group(2)), int(mt.group(3) or 0))


def parse_band(text: str) -> tuple[float, float]:
    """``"0.3,0.1"`` → (0.3, 0.1); UsdHandsError otherwise."""
    parts = text.split(",")
    try:
        vals = tuple(float(p) for p in parts)
    except ValueError:
        vals = ()
    if len(vals) != 2 or not all(0 < v and math.isfinite(v) for v in vals):
        raise UsdHandsError(f"bad --band {text!r}: expected two positive fractions W1,W2 such as 0.3,0.1")
    return vals


MARKER_NAMES = ("wrist_a", "wrist_b", "forearm", "hand")


def read_markers_csv(path: Path, frames: int) -> dict:
    """Marker positions from a CSV file: ``{side: (frames, 4, 3) float}``, centimetres, Y up.

    The header names the columns ``<side>.<marker>.<axis>`` (``right.wrist_a.x``), markers
    :data:`MARKER_NAMES` in the paper's order p1, p2, p3, p4; every marker of a side must
    be there. An optional first column ``frame`` must count 0, 1, 2, ... One row per frame.

    Raises
    ------
    UsdHandsError
        Unreadable file, unknown or missing columns, a wrong number of rows, a value
        that is not a finite number (with the row and column).
    """
    import csv

    import numpy as np

    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
    except FileNotFoundError:
        raise UsdHandsError("no such marker file", path=path) from None
    except (OSError, UnicodeDecodeError) as e:
        raise UsdHandsError(f"cannot read marker file: {e}", path=path) from None
    if not rows:
        raise UsdHandsError("empty marker file: expected a header of <side>.<marker>.<axis> columns", path=path)
    header = [h.strip() for h in rows[0]]
    has_frame = header[0].lower() == "frame"
    cols = {}
    for k, h in enumerate(header[1:] if has_frame else header, start=1 if has_frame else 0):
        parts = h.split(".")
        if len(parts) != 3 or parts[0] not in ("left", "right") or parts[1] not in MARKER_NAMES \
                or parts[2] not in ("x", "y", "z"):
            raise UsdHandsError(f"unknown column {h!r}: expected <side>.<marker>.<axis> with side left or right, "
                                f"marker {', '.join(MARKER_NAMES)}, axis x, y or z", path=path, location="row 1")
        cols[(parts[0], MARKER_NAMES.index(parts[1]), "xyz".index(parts[2]))] = k
    data = rows[1:]
    if len(data) != frames:
        raise UsdHandsError(f"{len(data)} rows of markers for a clip of {frames} frames", path=path)
    out = {}
    for side in ("left", "right"):
        have = [key for key in cols if key[0] == side]
        if not have:
            continue
        missing = [f"{side}.{MARKER_NAMES[mk]}.{'xyz'[ax]}" for mk in range(4) for ax in range(3)
                   if (side, mk, ax) not in cols]
        if missing:
            raise UsdHandsError(f"the {side} hand's markers lack columns {', '.join(missing)}", path=path)
        out[side] = np.zeros((frames, 4, 3))
    for r, row in enumerate(data):
        if has_frame and row[0].strip() != str(r):
            raise UsdHandsError(f"frame column: expected {r}, got {row[0].strip()!r}", path=path,
                                location=f"row {r + 2}")
        for (side, mk, ax), k in cols.items():
            try:
                v = float(row[k])
            except (IndexError, ValueError):
                v = float("nan")
            if not math.isfinite(v):
                cell = row[k] if k < len(row) else ""
                raise UsdHandsError(f"column {header[k]!r}: expected a finite number, got {cell!r}", path=path,
                                    location=f"row {r + 2}")
            out[side][r, mk, ax] = v
    return out


def _resample_markers(markers: dict, fps_from: float, fps_to: float, frames_to: int) -> dict:
    """Markers sampled at the frames of a clip resampled from ``fps_from`` to ``fps_to`` (linear)."""
    import numpy as np

    out = {}
    for side, m in markers.items():
        src = np.minimum(np.arange(frames_to) / fps_to * fps_from, m.shape[0] - 1)
        i0 = np.clip(np.floor(src).astype(int), 0, max(m.shape[0] - 2, 0))
        i1 = np.minimum(i0 + 1, m.shape[0] - 1)
        w = (src - i0)[:, None, None]
        out[side] = (1 - w) * m[i0] + w * m[i1]
    return out


def _sides(args, body_map, hand_map, notes: list[str]) -> list[str]:
    have_b = [h.side for h in body_map.sides]
    have_h = [h.side for h in hand_map.sides]
    if args.side != "both":
        if args.side not in have_b:
            raise UsdHandsError(f"BODY has no {args.side} hand (found: {', '.join(have_b) or 'none'})",
                                path=args.body)
        if args.side not in have_h:
            raise UsdHandsError(f"HANDS has no {args.side} hand (found: {', '.join(have_h) or 'none'})",
                                path=args.hands)
        return [args.side]
    common = [s for s in have_b if s in have_h]
    if not common:
        raise UsdHandsError(f"no hand in common: BODY has {', '.join(have_b) or 'none'}, "
                            f"HANDS has {', '.join(have_h) or 'none'}")
    for s in have_b:
        if s not in common:
            notes.append(f"HANDS has no {s} hand: BODY's {s} hand keeps its own motion")
    return common


def _handmap(skeleton, override, path, role: str):
    """Hand map of one input (override, map recorded in the file, or detection); errors name the input."""
    from usdhands.formats.hands import hands_for

    try:
        return hands_for(path, skeleton, override)[0]
    except UsdHandsError as e:
        raise type(e)(f"{role}: {e.message}", path=e.path or path, location=e.location) from None


def _check_side(side, path, role: str) -> None:
    if side.forearm is None:
        raise UsdHandsError(f"{role}: the {side.side} hand (wrist {side.wrist!r}) has no forearm joint; "
                            "splicing needs a forearm and a wrist", path=path)
    if not side.finger_joints:
        raise UsdHandsError(f"{role}: the {side.side} hand has no finger joints", path=path)


def run(args) -> int:
    import numpy as np

    from usdhands.algorithms.dtw import Constraint, check_constraints
    from usdhands.algorithms.splicing.markers import default_marker_offsets
    from usdhands.algorithms.splicing.splice import SpliceOptions, splice_clips
    from usdhands.formats.io import read_clip, write_clip
    from usdhands.commands._synthesis_common import check_plot_folder

    constraints = [parse_match(t) for t in args.match]
    band1, band2 = parse_band(args.band)
    if args.blend < 0:
        raise UsdHandsError(f"bad --blend {args.blend}: expected a number of frames >= 0")
    if not math.isfinite(args.hand_yaw):
        raise UsdHandsError(f"bad --hand-yaw {args.hand_yaw}: expected a finite angle in degrees")
    check_paths({MAIN_INPUT: (args.body, args.hands), "--body-markers": args.body_markers,
                 "--hands-markers": args.hands_markers, "--body-handmap": args.body_handmap,
                 "--hands-handmap": args.hands_handmap}, {"-o": args.output})
    check_plot_folder(args.plot)
    opts = layer_options(args.layer, args.body, args.output)
    body = read_clip(args.body, animation=args.animation)
    hands = read_clip(args.hands, animation=args.hands_animation)
    n, m0, hand_fps = body.num_frames, hands.num_frames, hands.fps
    for clip, path, role in ((body, args.body, "BODY"), (hands, args.hands, "HANDS")):
        if clip.num_frames < 5:
            raise UsdHandsError(f"{role} has {clip.num_frames} frames; splicing needs at least 5", path=path)
    try:
        check_constraints(constraints, n, m0)
    except ValueError as e:
        raise UsdHandsError(f"--match: {e} (BODY has {n} frames, HANDS {m0})") from None

    body_map = _handmap(body.skeleton, args.body_handmap, args.body, "BODY")
    hand_map = _handmap(hands.skeleton, args.hands_handmap, args.hands, "HANDS")
    notes: list[str] = []  # printed once every input has been checked: an error stays the only line
    sides = _sides(args, body_map, hand_map, notes)
    for s in sides:
        _check_side(body_map[s], args.body, "BODY")
        _check_side(hand_map[s], args.hands, "HANDS")
        for clip, side, path, role in ((body, body_map[s], args.body, "BODY"),
                                       (hands, hand_map[s], args.hands, "HANDS")):
            try:
                default_marker_offsets(clip.skeleton, side)
            except ValueError as e:
                raise UsdHandsError(f"{role}: {e}", path=path) from None

    body_markers = read_markers_csv(args.body_markers, n) if args.body_markers is not None else None
    hand_markers = read_markers_csv(args.hands_markers, m0) if args.hands_markers is not None else None
    for markers, path, role in ((body_markers, args.body_markers, "BODY"), (hand_markers, args.hands_markers, "HANDS")):
        if markers is not None and not set(sides) & set(markers):
            raise UsdHandsError(f"no markers for the {' or '.join(sides)} hand spliced from {role}", path=path)
    for note in notes:
        print(f"usdhands: note: {note}", file=sys.stderr)

    ratio = 1.0
    resampled = abs(hand_fps - body.fps) > 1e-6 * body.fps
    if resampled:
        ratio = body.fps / hand_fps
        hands = hands.resample(body.fps)
        print(f"usdhands: note: HANDS is at {hand_fps:.4g} fps and BODY at {body.fps:.4g} fps: HANDS resampled "
              f"to {body.fps:.4g} fps ({m0} -> {hands.num_frames} frames); --match and the reported alignment "
              "use HANDS's own frame numbers (constraints hold to within one resampled frame)", file=sys.stderr)
        m = hands.num_frames
        if hand_markers is not None:
            hand_markers = _resample_markers(hand_markers, hand_fps, body.fps, m)
        conv = [Constraint(c.body, min(int(round(c.hand * ratio)), m - 1), int(math.floor(c.tolerance * ratio)))
                for c in constraints]
        try:
            check_constraints(conv, n, m)
        except ValueError as e:
            raise UsdHandsError(f"--match after resampling HANDS to {body.fps:.4g} fps: {e}") from None
        constraints = conv

    long_, short_ = max(body.duration, hands.duration), min(body.duration, hands.duration)
    if short_ > 0 and long_ / short_ > DURATION_RATIO_NOTE:
        print(f"usdhands: note: BODY lasts {body.duration:.3g} s and HANDS {hands.duration:.3g} s: the path runs from "
              "the first to the last frames of both (fixed ends), so both clips should hold the same performance; "
              "trim them first", file=sys.stderr)
    options = SpliceOptions(band1=band1, band2=band2, yaw=args.yaw, hand_trunk_yaw_deg=args.hand_yaw,
                            forearm_align=args.forearm_align, blend_window=args.blend, transfer=args.transfer)
    progress = Progress("splice")
    try:
        result = splice_clips(body, hands, {s: body_map[s] for s in sides}, {s: hand_map[s] for s in sides},
                              constraints=constraints, options=options, progress=progress,
                              body_markers=body_markers, hand_markers=hand_markers)
    except ValueError as e:  # a band without a path and the like: the user's numbers
        raise UsdHandsError(str(e)) from None
    from dataclasses import asdict

    from usdhands.model.provenance import provenance_record

    record = provenance_record("splicing", database=args.hands, parameters={
        **asdict(options), "sides": list(sides), "constraints": [list(asdict(c).values()) for c in constraints]})
    write_clip(args.body, result.clip, args.output, provenance=record, **opts)

    for s in sides:
        rb, rh = result.wrist_range_cm[s]
        if result.timing_from.get(s, s) != s:
            print(f"usdhands: note: {s} hand: its wrist barely moves (range {rb:.2g} cm in BODY, {rh:.2g} cm in "
                  f"HANDS): it takes the {result.timing_from[s]} hand's alignment (both hands share one timing)",
                  file=sys.stderr)
        elif min(rb, rh) < options.still_range_cm:
            print(f"usdhands: note: {s} hand: its wrist barely moves (range {rb:.2g} cm in BODY, {rh:.2g} cm in "
                  "HANDS): the alignment has little to go on; splice both hands, or add --match constraints",
                  file=sys.stderr)
        if args.transfer == "auto" and result.transfer_modes.get(s) == "hand":
            print(f"usdhands: note: {s} hand: the finger joints of BODY and HANDS have other axis conventions; "
                  "rotations carried through the hands' rest axes (--transfer hand)", file=sys.stderr)
        if args.transfer == "auto" and result.transfer_modes.get(s) == "copy":
            print(f"usdhands: note: {s} hand: the finger joints of BODY and HANDS have the same axes but other "
                  "rest rotations; local rotations copied as they are (--transfer copy)", file=sys.stderr)
        if result.body_unmatched[s]:
            print(f"usdhands: note: {s} hand: BODY finger joints without a counterpart in HANDS keep their "
                  f"own motion: {', '.join(result.body_unmatched[s])}", file=sys.stderr)
        if result.hand_unmatched[s]:
            print(f"usdhands: note: {s} hand: HANDS finger joints without a counterpart in BODY are not used: "
                  f"{', '.join(result.hand_unmatched[s])}", file=sys.stderr)

    to_hand = lambda a: np.asarray(a, dtype=float) / ratio  # back to HANDS's own frame numbers
    if args.plot is not None:
        from usdhands.commands._splice_plots import plot_alignment

        for s in sides:
            plot_alignment(result.sides[s], args.plot / f"splice_{s}.png", constraints=constraints,
                           title=f"{args.body.name} + {args.hands.name}: {s} hand",
                           hand_label=f"hand frame (resampled to {body.fps:g} fps)" if resampled else "hand frame")
    if args.json:
        out = {
            "body": str(args.body), "hands": str(args.hands), "output": str(args.output),
            "body_frames": n, "hand_frames": m0, "fps": body.fps, "hand_fps": hand_fps, "resampled": resampled,
            "alignment": {s: [round(float(v), 3) for v in to_hand(result.sides[s].alignment)] for s in sides},
            "phases": {s: [{"body_frame": int(b), "hand_frame": round(float(to_hand(h)), 3)}
                           for b, h in result.sides[s].phases] for s in sides},
            "costs": {s: _costs(result.sides[s]) for s in sides},
            "seams": {s: [int(v) for v in result.transfers[s].seams] for s in sides},
            "pairs": {s: [list(p) for p in result.pairs[s]] for s in sides},
            "body_unmatched": result.body_unmatched, "hands_unmatched": result.hand_unmatched,
            "transfer": result.transfer_modes,
            "timing_from": result.timing_from,
            "markers": {"body": str(args.body_markers) if args.body_markers else "joints",
                        "hands": str(args.hands_markers) if args.hands_markers else "joints"},
            "constraints": [str(c) for c in (parse_match(t) for t in args.match)],
        }
        print_json(out)
        return 0
    rows = []
    for s in sides:
        a = result.sides[s]
        c = _costs(a)
        rows.append([s, n, m0, len(a.phases), c["first_pass"], c["second_pass_mean_deg"],
                     len(result.transfers[s].seams), len(result.pairs[s])])
    print_table(rows, ["hand", "body frames", "hand frames", "phases", "pass-1 cost", "pass-2 mean deg",
                       "blended jumps", "finger joints"])
    print(f"wrote {args.output}")
    return 0


def _costs(a) -> dict:
    k1 = len(a.first.path)
    k2 = len(a.second.path)
    return {"first_pass": round(a.first.cost, 3), "first_pass_mean": round(a.first.cost / k1, 4),
            "second_pass_deg": round(a.second.cost, 3), "second_pass_mean_deg": round(a.second.cost / k2, 4),
            "first_band_cells": a.first.band.num_cells, "second_band_cells": a.second.band.num_cells}

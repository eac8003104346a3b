"""The splice job: put separately captured hand motion onto a body clip (Majkowska, Zordan, Faloutsos 2006).

Two-pass DTW (phases by the signs of marker derivatives, then the forearm-aligned hand
angle inside a narrow band), user constraints ``BODY_FRAME:HAND_FRAME[:TOLERANCE]``
(0-based, in each file's own frames), then the hand's finger rotations, relative to rest,
written onto the body's finger joints. See docs/splicing.md.

::

    import usdhands
    result = usdhands.splice("body.usda", "hands.bvh", "spliced.usda", usdhands.SpliceOptions(match=("0:12",)))
    print(result.report["costs"]["right"]["second_pass_mean_deg"], result.notes)
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from usdhands.errors import UsdHandsError
from usdhands.jobs.outputs import MAIN_INPUT, check_paths, layer_options

DURATION_RATIO_NOTE = 1.5
"""A note when one clip lasts this many times longer than the other."""
MATCH_RE = re.compile(r"^(\d+):(\d+)(?::(\d+))?$")


@dataclass(frozen=True)
class SpliceOptions:
    """Options of :func:`splice`; the defaults are the command line's.

    Attributes
    ----------
    side : str
        ``"left"``, ``"right"`` or ``"both"`` (every hand found in both files).
    match : tuple of str
        Constraints ``"BODY_FRAME:HAND_FRAME[:TOLERANCE]"`` (0-based, increasing).
    band : tuple of float
        Band half-widths of the two passes as fractions of the body length.
    yaw : str
        Turn about the vertical axis: ``"window"`` (eq. 7 over 5-frame windows), ``"trunk"`` or ``"none"``.
    hand_yaw : float
        With ``yaw="trunk"``: heading of the hand capture in degrees when it has no trunk.
    forearm_align : str
        Second pass: align forearm joint frames (``"frame"``) or marker vectors (``"vector"``).
    transfer : str
        ``"auto"``, ``"local"``, ``"copy"`` or ``"hand"`` (see ``usdhands splice --help``).
    blend : int
        Frames on each side of a jump in hand timing to cross-fade.
    animation, hands_animation : str or None
        Animation name or index in BODY and HANDS (default the first).
    body_markers, hands_markers : Path or None
        CSV files of real marker positions (see :func:`read_markers_csv`).
    body_handmap, hands_handmap : Path or None
        Hand map JSON overriding detection.
    as_layer : bool
        USD: write a sparse override layer over BODY instead of a full copy.
    plot : Path or None
        Folder for the cost matrices with band and path (``splice_<side>.png``).
    """

    side: str = "both"
    match: tuple[str, ...] = ()
    band: tuple[float, float] = (0.3, 0.1)
    yaw: str = "window"
    hand_yaw: float = 0.0
    forearm_align: str = "frame"
    transfer: str = "auto"
    blend: int = 4
    animation: str | None = None
    hands_animation: str | None = None
    body_markers: Path | None = None
    hands_markers: Path | None = None
    body_handmap: Path | None = None
    hands_handmap: Path | None = None
    as_layer: bool = False
    plot: Path | None = None


@dataclass(frozen=True)
class SpliceResult:
    """What :func:`splice` did.

    Attributes
    ----------
    output : Path
    sides : tuple of str
        The hands spliced.
    report : dict
        The ``--json`` report: frames, rates, per side the alignment (HANDS frame per BODY
        frame), phases, costs (pass 1; pass 2 in degrees), blended seams, joint pairs.
    notes : tuple of str
        Things the caller should know (resampling, a still wrist, unmatched joints).
    plots : tuple of Path
    """

    output: Path
    sides: tuple[str, ...]
    report: dict
    notes: tuple[str, ...] = ()
    plots: tuple[Path, ...] = ()

    def to_json(self) -> dict:
        """The ``usdhands splice --json`` report."""
        return self.report


def splice(body: str | os.PathLike, hands: str | os.PathLike, output: str | os.PathLike,
           options: SpliceOptions = SpliceOptions(),
           progress: Callable[[int, int, str], None] | None = None) -> SpliceResult:
    """Align the hand capture ``hands`` to the body clip ``body`` and write ``body`` with its finger motion.

    Parameters
    ----------
    body : path
        Full-body animation (.usd/.usda/.usdc/.usdz, .gltf/.glb, .bvh).
    hands : path
        Hand animation with forearm, wrist and fingers (a partial skeleton is fine).
    output : path
        File to write (same format as ``body``), atomically; never one of the inputs.
    options : SpliceOptions
    progress : callable, optional
        ``progress(done, total, what)``.

    Returns
    -------
    SpliceResult

    Raises
    ------
    UsdHandsError
        Unreadable inputs, no hand in common, bad constraints or bands, a bad output.
    """
    import numpy as np

    from usdhands.algorithms.dtw import Constraint, check_constraints
    from usdhands.algorithms.splicing.markers import default_marker_offsets
    from usdhands.algorithms.splicing.splice import SpliceOptions as AlignmentOptions
    from usdhands.algorithms.splicing.splice import splice_clips
    from usdhands.formats.io import read_clip, write_clip
    from usdhands.jobs.inputs import check_plot_folder

    body_path, hands_path, output = Path(body), Path(hands), Path(output)
    constraints = [parse_match(t) for t in options.match]
    band1, band2 = check_band(options.band)
    if options.blend < 0:
        raise UsdHandsError(f"bad --blend {options.blend}: expected a number of frames >= 0")
    if not math.isfinite(options.hand_yaw):
        raise UsdHandsError(f"bad --hand-yaw {options.hand_yaw}: expected a finite angle in degrees")
    for name, value, allowed in (("--side", options.side, ("left", "right", "both")),
                                 ("--yaw", options.yaw, ("window", "trunk", "none")),
                                 ("--forearm-align", options.forearm_align, ("frame", "vector")),
                                 ("--transfer", options.transfer, ("auto", "local", "copy", "hand"))):
        if value not in allowed:
            raise UsdHandsError(f"bad {name} {value!r}: expected one of {', '.join(allowed)}")
    from usdhands.jobs.plots.splicing import FILES

    inputs = {MAIN_INPUT: (body_path, hands_path), "--body-markers": options.body_markers,
              "--hands-markers": options.hands_markers, "--body-handmap": options.body_handmap,
              "--hands-handmap": options.hands_handmap}
    check_paths(inputs, {"-o": output})
    check_plot_folder(options.plot, FILES, inputs)
    opts = layer_options(options.as_layer, body_path, output)
    body_clip = read_clip(body_path, animation=options.animation)
    hands_clip = read_clip(hands_path, animation=options.hands_animation)
    n, m0, hand_fps = body_clip.num_frames, hands_clip.num_frames, hands_clip.fps
    for clip, path, role in ((body_clip, body_path, "BODY"), (hands_clip, hands_path, "HANDS")):
        if clip.num_frames < 5:
            raise UsdHandsError(f"{role} has {clip.num_frames} frames; splicing needs at least 5", path=path)
    try:
        check_constraints(constraints, n, m0)
    except ValueError as e:
        raise UsdHandsError(f"--match: {e} (BODY has {n} frames, HANDS {m0})") from None

    body_map = _handmap(body_clip.skeleton, options.body_handmap, body_path, "BODY")
    hand_map = _handmap(hands_clip.skeleton, options.hands_handmap, hands_path, "HANDS")
    notes: list[str] = []
    sides = _sides(options.side, body_path, hands_path, body_map, hand_map, notes)
    for s in sides:
        _check_side(body_map[s], body_path, "BODY")
        _check_side(hand_map[s], hands_path, "HANDS")
        for clip, side, path, role in ((body_clip, body_map[s], body_path, "BODY"),
                                       (hands_clip, hand_map[s], hands_path, "HANDS")):
            try:
                default_marker_offsets(clip.skeleton, side)
            except ValueError as e:
                raise UsdHandsError(f"{role}: {e}", path=path) from None

    body_markers = read_markers_csv(options.body_markers, n) if options.body_markers is not None else None
    hand_markers = read_markers_csv(options.hands_markers, m0) if options.hands_markers is not None else None
    for markers, path, role in ((body_markers, options.body_markers, "BODY"),
                                (hand_markers, options.hands_markers, "HANDS")):
        if markers is not None and not set(sides) & set(markers):
            raise UsdHandsError(f"no markers for the {' or '.join(sides)} hand spliced from {role}", path=path)

    ratio = 1.0
    resampled = abs(hand_fps - body_clip.fps) > 1e-6 * body_clip.fps
    if resampled:
        ratio = body_clip.fps / hand_fps
        hands_clip = hands_clip.resample(body_clip.fps)
        notes.append(f"HANDS is at {hand_fps:.4g} fps and BODY at {body_clip.fps:.4g} fps: HANDS resampled "
                     f"to {body_clip.fps:.4g} fps ({m0} -> {hands_clip.num_frames} frames); --match and the reported "
                     "alignment use HANDS's own frame numbers (constraints hold to within one resampled frame)")
        m = hands_clip.num_frames
        if hand_markers is not None:
            hand_markers = _resample_markers(hand_markers, hand_fps, body_clip.fps, m)
        conv = [Constraint(c.body, min(int(round(c.hand * ratio)), m - 1), int(math.floor(c.tolerance * ratio)))
                for c in constraints]
        try:
            check_constraints(conv, n, m)
        except ValueError as e:
            raise UsdHandsError(f"--match after resampling HANDS to {body_clip.fps:.4g} fps: {e}") from None
        constraints = conv

    long_, short_ = max(body_clip.duration, hands_clip.duration), min(body_clip.duration, hands_clip.duration)
    if short_ > 0 and long_ / short_ > DURATION_RATIO_NOTE:
        notes.append(f"BODY lasts {body_clip.duration:.3g} s and HANDS {hands_clip.duration:.3g} s: the path runs "
                     "from the first to the last frames of both (fixed ends), so both clips should hold the same "
                     "performance; trim them first")
    alignment_options = AlignmentOptions(band1=band1, band2=band2, yaw=options.yaw,
                                         hand_trunk_yaw_deg=options.hand_yaw, forearm_align=options.forearm_align,
                                         blend_window=options.blend, transfer=options.transfer)
    try:
        result = splice_clips(body_clip, hands_clip, {s: body_map[s] for s in sides},
                              {s: hand_map[s] for s in sides}, constraints=constraints, options=alignment_options,
                              progress=progress, body_markers=body_markers, hand_markers=hand_markers)
    except ValueError as e:  # a band without a path and the like: the user's numbers
        raise UsdHandsError(str(e)) from None
    from dataclasses import asdict

    from usdhands.model.provenance import provenance_record

    record = provenance_record("splicing", database=hands_path, parameters={
        **asdict(alignment_options), "sides": list(sides),
        "constraints": [list(asdict(c).values()) for c in constraints]})
    write_clip(body_path, result.clip, output, provenance=record, **opts)

    for s in sides:
        rb, rh = result.wrist_range_cm[s]
        if result.timing_from.get(s, s) != s:
            notes.append(f"{s} hand: its wrist barely moves (range {rb:.2g} cm in BODY, {rh:.2g} cm in HANDS): it "
                         f"takes the {result.timing_from[s]} hand's alignment (both hands share one timing)")
        elif min(rb, rh) < alignment_options.still_range_cm:
            notes.append(f"{s} hand: its wrist barely moves (range {rb:.2g} cm in BODY, {rh:.2g} cm in HANDS): the "
                         "alignment has little to go on; splice both hands, or add --match constraints")
        if options.transfer == "auto" and result.transfer_modes.get(s) == "hand":
            notes.append(f"{s} hand: the finger joints of BODY and HANDS have other axis conventions; rotations "
                         "carried through the hands' rest axes (--transfer hand)")
        if options.transfer == "auto" and result.transfer_modes.get(s) == "copy":
            notes.append(f"{s} hand: the finger joints of BODY and HANDS have the same axes but other rest "
                         "rotations; local rotations copied as they are (--transfer copy)")
        if result.body_unmatched[s]:
            notes.append(f"{s} hand: BODY finger joints without a counterpart in HANDS keep their own motion: "
                         f"{', '.join(result.body_unmatched[s])}")
        if result.hand_unmatched[s]:
            notes.append(f"{s} hand: HANDS finger joints without a counterpart in BODY are not used: "
                         f"{', '.join(result.hand_unmatched[s])}")

    to_hand = lambda a: np.asarray(a, dtype=float) / ratio  # back to HANDS's own frame numbers  # noqa: E731
    plots = []
    if options.plot is not None:
        from usdhands.jobs.plots.splicing import plot_alignment

        for s in sides:
            plots.append(plot_alignment(
                result.sides[s], options.plot / f"splice_{s}.png", constraints=constraints,
                title=f"{body_path.name} + {hands_path.name}: {s} hand",
                hand_label=f"hand frame (resampled to {body_clip.fps:g} fps)" if resampled else "hand frame"))
    report = {
        "body": str(body_path), "hands": str(hands_path), "output": str(output),
        "body_frames": n, "hand_frames": m0, "fps": body_clip.fps, "hand_fps": hand_fps, "resampled": resampled,
        "alignment": {s: [round(float(v), 3) for v in to_hand(result.sides[s].alignment)] for s in sides},
        "phases": {s: [{"body_frame": int(b), "hand_frame": round(float(to_hand(h)), 3)}
                       for b, h in result.sides[s].phases] for s in sides},
        "costs": {s: _costs(result.sides[s]) for s in sides},
        "seams": {s: [int(v) for v in result.transfers[s].seams] for s in sides},
        "pairs": {s: [list(p) for p in result.pairs[s]] for s in sides},
        "body_unmatched": result.body_unmatched, "hands_unmatched": result.hand_unmatched,
        "transfer": result.transfer_modes,
        "timing_from": result.timing_from,
        "markers": {"body": str(options.body_markers) if options.body_markers else "joints",
                    "hands": str(options.hands_markers) if options.hands_markers else "joints"},
        "constraints": [str(c) for c in (parse_match(t) for t in options.match)],
    }
    return SpliceResult(output, tuple(sides), report, tuple(notes), tuple(plots))


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
    return check_band(vals, text)


def check_band(vals, text: str | None = None) -> tuple[float, float]:
    """Two positive finite fractions, as a tuple; UsdHandsError otherwise."""
    vals = tuple(vals)
    if len(vals) != 2 or not all(0 < v and math.isfinite(v) for v in vals):
        shown = text if text is not None else ",".join(str(v) for v in vals)
        raise UsdHandsError(f"bad --band {shown!r}: expected two positive fractions W1,W2 such as 0.3,0.1")
    return (float(vals[0]), float(vals[1]))


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
    import io

    import numpy as np

    from usdhands.input_files import read_text

    text = read_text(path, what="marker file", error=UsdHandsError)  # a pipe or /dev/zero: refused, not read
    rows = [r for r in csv.reader(io.StringIO(text, newline="")) if r and any(c.strip() for c in r)]
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


def _sides(side: str, body_path, hands_path, body_map, hand_map, notes: list[str]) -> list[str]:
    side_ = side
    have_b = [h.side for h in body_map.sides]
    have_h = [h.side for h in hand_map.sides]
    if side_ != "both":
        if side_ not in have_b:
            raise UsdHandsError(f"BODY has no {side_} hand (found: {', '.join(have_b) or 'none'})",
                                path=body_path)
        if side_ not in have_h:
            raise UsdHandsError(f"HANDS has no {side_} hand (found: {', '.join(have_h) or 'none'})",
                                path=hands_path)
        return [side_]
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


def _costs(a) -> dict:
    k1 = len(a.first.path)
    k2 = len(a.second.path)
    return {"first_pass": round(a.first.cost, 3), "first_pass_mean": round(a.first.cost / k1, 4),
            "second_pass_deg": round(a.second.cost, 3), "second_pass_mean_deg": round(a.second.cost / k2, 4),
            "first_band_cells": a.first.band.num_cells, "second_band_cells": a.second.band.num_cells}

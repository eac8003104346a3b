"""The database jobs: build a finger-motion database for ``synthesize``, and say what one holds.

``build_db`` reads clips with fingers in any supported format (or the generated gesture
set) and writes a database folder (manifest.json + .npy arrays, see docs/synthesis.md):
per hand, wrist features, finger DOF curves, segments, labels and where each came from.
``database_info`` loads one (default: the database bundled in the package).

::

    from usdhands.jobs.database import BuildDbOptions, build_db

    summary = build_db(["mocap/"], "fingers_db", BuildDbOptions(labels=r"^([a-z]+)_", mirror=True))
    print(summary.counts["segments"], summary.segments_by_label)
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from usdhands.errors import UsdHandsError

ProgressCallback = Callable[[int, int, str], None]


@dataclass(frozen=True)
class BuildDbOptions:
    """Options of :func:`build_db`; the defaults are ``usdhands db build``'s.

    Attributes
    ----------
    labels : str or None
        Label of a clip: the first group of this regular expression searched in its file name.
    labels_file : Path or None
        CSV with rows ``file,label``.
    mirror : bool
        Add left<->right mirrored copies of every hand.
    fps : float
        Frame rate of the database.
    config : Path or None
        Synthesis configuration JSON (segmentation values).
    handmap : Path or None
        Hand map JSON overriding detection (all inputs).
    animation : str or None
        Animation name or index in each file (default the first), or ``"all"``: every
        animation of every file, each a clip labelled like its file.
    samples : bool
        Build from the generated gesture set (usdhands.samples) instead of files.
    props : tuple of Path
        Interaction clips: their fingers are corrected against these props before they go into
        the database. The other prop options (``margin`` mm, ``self_collision``, ``attach``,
        ``prop_units``, ``prop_up``, ``interaction_config``) are those of
        :class:`usdhands.jobs.correction.CorrectOptions`.
    """

    labels: str | None = None
    labels_file: Path | None = None
    mirror: bool = False
    fps: float = 30.0
    config: Path | None = None
    handmap: Path | None = None
    animation: str | None = None
    samples: bool = False
    props: tuple[Path, ...] = ()
    margin: float = 0.0
    self_collision: bool = False
    attach: tuple[str, ...] = ()
    prop_units: float | None = None
    prop_up: str | None = None
    interaction_config: Path | None = None


@dataclass(frozen=True)
class DatabaseSummary:
    """What a database holds.

    Attributes
    ----------
    path : Path
        The database folder.
    fps : float
        Its frame rate.
    reach_cm : float
        The arm reach its wrist features are scaled by, cm.
    manifest : dict
        The whole ``manifest.json`` (``usdhands db info --json``).
    segments_by_label : tuple of (str, int, int)
        Per label (``"(no label)"`` for none), the segments of the left and of the right hand.
    messages : tuple of (str, str)
        ``(level, text)``, level ``"note"`` or ``"warning"``: what the build noticed
        (clips corrected against props, hands whose fingers never move).
    """

    path: Path
    fps: float
    reach_cm: float
    manifest: dict
    segments_by_label: tuple[tuple[str, int, int], ...]
    messages: tuple[tuple[str, str], ...] = field(default=())

    @property
    def counts(self) -> dict:
        """``{"clips", "tracks", "segments", "frames", ...}``."""
        return dict(self.manifest["counts"])

    def to_json(self) -> dict:
        """The ``usdhands db build --json`` report."""
        m = self.manifest
        return {"path": str(self.path), **m["counts"], "labels": m["labels"], "dofs": len(m["dofs"])}


def build_db(inputs: Sequence[str | os.PathLike], output: str | os.PathLike,
             options: BuildDbOptions = BuildDbOptions(), progress: ProgressCallback | None = None) -> DatabaseSummary:
    """Build a database folder ``output`` from the clips of ``inputs`` (files or folders).

    Raises
    ------
    UsdHandsError
        Bad options, unreadable inputs, clips without finger joints; nothing is written then.
    """
    from usdhands.algorithms.synthesis.database import DatabaseClip, build_database, save_database
    from usdhands.jobs.inputs import (
        expand_inputs, labeller, load_config, read_labelled, sample_database_items, stage_progress, still_hands,
    )
    from usdhands.jobs.option_checks import check_fps
    from usdhands.jobs.outputs import MAIN_INPUT, check_paths

    inputs, output = [Path(p) for p in inputs], Path(output)
    progress = progress or _no_progress
    check_fps(options.fps)
    if options.samples and inputs:
        raise UsdHandsError("give input files or --samples, not both")
    if not options.samples and not inputs:
        raise UsdHandsError("no input files given (or use --samples)")
    paths = [] if options.samples else expand_inputs(inputs)
    check_paths({MAIN_INPUT: [*inputs, *paths], "--labels-file": options.labels_file, "--config": options.config,
                 "--handmap": options.handmap, "--props": options.props,
                 "--interaction-config": options.interaction_config},
                replaced_folders={"-o": output})
    cfg = load_config(options.config)
    from usdhands.jobs.props import refuse_prop_options_without_props

    refuse_prop_options_without_props(options)
    if options.props:
        from usdhands.jobs.props import check_prop_options

        check_prop_options(options)
    if options.props and options.samples:
        raise UsdHandsError("--props corrects input files; --samples has none")
    messages = []
    if options.samples:
        items = sample_database_items()
    else:
        label_of = labeller(options.labels, options.labels_file)
        reading = stage_progress(progress, "reading")
        if options.animation == "all":
            read = _read_all_animations(paths, label_of, options.handmap, reading)
        else:
            read = read_labelled(paths, label_of, None, options.handmap, options.animation, reading)
        items = []
        held = (None, None)  # with --props: the file last read again for its skinned meshes, and its asset
        for p, label, clip, handmap in read:
            if not any(h.finger_joints for h in handmap.sides):
                raise UsdHandsError("no finger joints found: a database needs clips with finger animation", path=p)
            if options.props:  # interaction clips: the database holds their corrected fingers
                from usdhands.formats.io import read_asset
                from usdhands.jobs.props import corrected_for_props, hand_meshes

                # the finger capsules of the hand the file draws, as correct measures them
                if held[0] != p:  # once per file, not per animation
                    held = (p, read_asset(p))
                clip, summary = corrected_for_props(options, p, clip, handmap, hand_meshes(held[1], clip))
                after = summary["penetration_after_mm"]
                messages.append(("note", f"{p}: corrected against the props, {summary['frames_corrected']} frames "
                                         f"(penetration {summary['penetration_before_mm']['max']:.2f} -> "
                                         f"{after['max']:.2f} mm)"))
            items.append(DatabaseClip(clip, handmap, label, str(p)))
            still = still_hands(clip, handmap)
            if still and len(still) == sum(1 for h in handmap.sides if h.finger_joints):  # one idle hand is normal
                where = f"{p} (animation {clip.name!r})" if options.animation == "all" else str(p)
                messages.append(("warning", f"{where}: the {' and '.join(still)} hand's fingers never move (a "
                                            f"body-only clip?); its frozen fingers go into the database as they are"))
    from usdhands.algorithms.synthesis.feature_sets import extra_keys, feature_terms

    try:
        db = build_database(items, fps=options.fps, mirror=options.mirror, segmentation=cfg.segmentation,
                            progress=stage_progress(progress, "building"),
                            arm_features=extra_keys(feature_terms(cfg.segment_cost)))
    except ValueError as e:  # segment_cost.features naming a joint a hand map lacks
        raise UsdHandsError(str(e), path=options.config) from None
    path = save_database(db, output)
    return _summary(db, path, tuple(messages))


def database_info(path: str | os.PathLike | None = None) -> DatabaseSummary:
    """What the database folder ``path`` holds (default: the database bundled in the package)."""
    from usdhands.algorithms.synthesis.database import load_database
    from usdhands.jobs.inputs import bundled_database_path

    path = Path(path) if path is not None else bundled_database_path()
    return _summary(load_database(path), path)


def _no_progress(done: int, total: int, what: str = "") -> None:
    pass


def _summary(db, path, messages=()) -> DatabaseSummary:
    import numpy as np

    labels = db.segment_labels()
    side = db.segment_side()
    names = ["(no label)" if x is None else str(x) for x in labels]
    rows = []
    for lab in sorted(set(names)):
        sel = np.array([x == lab for x in names])
        rows.append((lab, int((sel & (side == 0)).sum()), int((sel & (side == 1)).sum())))
    return DatabaseSummary(Path(path), float(db.fps), float(db.reach_cm), db.manifest(), tuple(rows), messages)


def _read_all_animations(paths, label_of, handmap_path, progress):
    """``(path, label, clip, handmap)`` for every animation of every file."""
    from usdhands.formats.io import read_asset
    from usdhands.jobs.inputs import handmap_for

    out = []
    for i, p in enumerate(paths):
        label = label_of(p)
        asset = read_asset(p)
        if not asset.clips:
            raise UsdHandsError("no animation in file", path=p)
        handmap = handmap_for(asset.clips[0], p, handmap_path)
        for clip in asset.clips:
            out.append((p, label, clip, handmap if clip.skeleton is asset.clips[0].skeleton
                        else handmap_for(clip, p, handmap_path)))
        progress(i + 1, len(paths), p.name)
    return out

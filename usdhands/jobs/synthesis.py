"""The synthesize job: finger motion for a body clip from its wrist motion (Jörg, Hodgins, Safonova 2012).

Segments each hand's wrist motion, finds the k most similar database segments (eq. 1),
picks the least-cost path through the graph of transitions (eq. 2-3), stitches the chosen
finger motion and writes the input file again with the finger animation added; every
other joint and everything else in the file stay as they were.

::

    import usdhands
    result = usdhands.synthesize("take.usda", "take_fingers.usda",
                                 usdhands.SynthesizeOptions(hands=("right",), k=8))
    print(result.output, result.animations[0]["hands"]["right"]["mean_segment_cost"])
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from usdhands.errors import UsdHandsError
from usdhands.jobs.outputs import layer_options

ProgressCallback = Callable[[int, int, str], None]
SIDES_ = ("left", "right")


@dataclass(frozen=True)
class SynthesizeOptions:
    """Options of :func:`synthesize`; the defaults are the command line's.

    Attributes
    ----------
    db : Path or None
        Database folder from ``usdhands db build``; None uses the database bundled in the package.
        Loaded once per process (see :func:`usdhands.jobs.inputs.cached_database`).
    k : int or None
        Candidates per segment (>= 1); None keeps the configuration's (5 by default).
    hands : tuple of str
        ``("left",)``, ``("right",)`` or both; empty: every hand with finger joints.
    config : Path or None
        Synthesis configuration JSON (weights, thresholds).
    handmap : Path or None
        Hand map JSON overriding detection.
    animation : str or None
        Animation name or index in the file (default the first), or ``"all"``: every animation.
    as_layer : bool
        USD: write a sparse override layer on top of the input instead of a full copy.
    graft_hands : bool
        Add finger joints from the database's hands to a skeleton without them
        (skeleton-only files: BVH, USD without skinned meshes).
    finger_reference : str
        ``"rest"``: finger rotations relative to the rig's rest pose; ``"input"``: relative
        to the pose the input's fingers hold at its first frame.
    plot : Path or None
        Folder to write PNGs into (wrist speed with segments, the graph, finger curves).
    props : tuple of Path
        Props the hands touch (mesh files or USD files with Mesh prims): synthesis with the
        interaction terms (proximity cuts, collision term weighted ``collision_weight``) and the
        result corrected against them (see ``usdhands correct``). The other prop options
        (``margin`` mm, ``self_collision``, ``attach`` ``"PROP=JOINT[:FROM-TO]"``, ``prop_units``,
        ``prop_up``, ``interaction_config``) are those of ``usdhands correct``.
    """

    db: Path | None = None
    k: int | None = None
    hands: tuple[str, ...] = ()
    config: Path | None = None
    handmap: Path | None = None
    animation: str | None = None
    as_layer: bool = False
    graft_hands: bool = False
    finger_reference: str = "rest"
    plot: Path | None = None
    props: tuple[Path, ...] = ()
    margin: float = 0.0
    self_collision: bool = False
    attach: tuple[str, ...] = ()
    prop_units: float | None = None
    prop_up: str | None = None
    interaction_config: Path | None = None
    collision_weight: float = 1.0


@dataclass(frozen=True)
class SynthesizeResult:
    """What :func:`synthesize` did.

    Attributes
    ----------
    output : Path
        The file written.
    database : str
        Folder of the database used.
    k : int
        Candidates per segment used.
    animations : tuple of dict
        Per animation synthesized: ``{"database", "k", "hands": {side: {"segments",
        "chosen_labels", "top_labels", "mean_segment_cost" (cm/deg cost), "seams",
        "seams_blended", "pruned_share", "body_scale"}}, "mapping": {side: {...}},
        "animation": name, "plots": [paths] (with ``plot``)}``.
    every_animation : bool
        True for ``animation="all"``.
    animations_in_file : int
        How many animations the input holds.
    grafted_joints : tuple of str
        Finger joints added with ``graft_hands``.
    warnings : tuple of str
        Things the caller should know (the input segmented with other values than the database).
    """

    output: Path
    database: str
    k: int
    animations: tuple[dict, ...]
    every_animation: bool = False
    animations_in_file: int = 1
    grafted_joints: tuple[str, ...] = ()
    warnings: tuple[str, ...] = field(default=())

    def to_json(self) -> dict:
        """The ``usdhands synthesize --json`` report."""
        if self.every_animation:
            return {"database": self.database, "k": self.k, "animations": list(self.animations),
                    "output": str(self.output)}
        report = {key: value for key, value in self.animations[0].items()
                  if key not in ("animation", "plots", "interaction")}
        report["grafted_joints"] = list(self.grafted_joints)
        if "interaction" in self.animations[0]:
            report["interaction"] = self.animations[0]["interaction"]
        report["output"] = str(self.output)
        report["animation"] = self.animations[0]["animation"]
        report["animations_in_file"] = self.animations_in_file
        if "plots" in self.animations[0]:
            report["plots"] = self.animations[0]["plots"]
        return report


def synthesize(source: str | os.PathLike, output: str | os.PathLike, options: SynthesizeOptions = SynthesizeOptions(),
               progress: ProgressCallback | None = None) -> SynthesizeResult:
    """Give the body clip in ``source`` finger motion and write ``output`` (same format as ``source``).

    Parameters
    ----------
    source : path
        Animation file (.usd/.usda/.usdc/.usdz, .gltf/.glb, .bvh) with a skeleton with finger
        joints (or a skeleton-only file with ``options.graft_hands``).
    output : path
        File to write, atomically; never one of the inputs.
    options : SynthesizeOptions
    progress : callable, optional
        Called as ``progress(done, total, what)``.

    Returns
    -------
    SynthesizeResult

    Raises
    ------
    UsdHandsError
        A bad input or option (unreadable file, no hands, an output equal to the input, ...);
        nothing is written then.
    """
    from usdhands.algorithms.synthesis.synthesize import synthesize_clip
    from usdhands.formats.io import read_asset, write_asset, write_clip
    from usdhands.jobs.inputs import cached_database, load_config
    from usdhands.model.asset import Asset

    source, output = Path(source), Path(output)
    progress = progress or _no_progress
    _check_output(source, output, options)
    from usdhands.jobs.props import refuse_prop_options_without_props

    refuse_prop_options_without_props(options)
    if options.props:
        from usdhands.jobs.props import check_prop_options

        check_prop_options(options)
        if options.animation == "all":
            raise UsdHandsError("--props works on one animation; give --animation NAME")
        if not (options.collision_weight >= 0):
            raise UsdHandsError(f"--collision-weight must be 0 or more, got {options.collision_weight:g}")
    cfg = load_config(options.config)
    if options.k is not None:
        if options.k < 1:
            raise UsdHandsError(f"--k must be at least 1, got {options.k}")
        cfg = cfg.with_values(segment_cost={"k": options.k})
    record = _provenance(options, cfg)
    progress(0, 4, "reading")
    db = cached_database(options.db)
    asset = read_asset(source)
    if options.animation == "all" and not any(c.name == "all" for c in asset.clips):
        return _synthesize_all(source, output, options, asset, db, cfg, progress)
    try:
        clip = asset.clip(options.animation)
    except KeyError as e:
        raise UsdHandsError(str(e.args[0]).split(": ", 1)[-1], path=source) from None
    warnings: list[str] = []
    clip, handmap, with_fingers, added = prepare_hands(source, options, asset, clip, db, cfg, warnings)
    progress(1, 4, "synthesizing")
    interaction, colliders, iconfig, world = None, None, None, None
    if options.props:
        from usdhands.algorithms.interaction.finger_geometry import InteractionConfig, load_interaction_config
        from usdhands.jobs.props import read_scene_props, synthesis_interaction

        from usdhands.jobs.props import hand_meshes, with_mesh_radii

        iconfig = load_interaction_config(options.interaction_config) if options.interaction_config \
            else InteractionConfig()
        if not added:  # a grafted hand has no mesh of its own
            iconfig = with_mesh_radii(iconfig, clip, handmap, hand_meshes(asset, clip))
        world = clip.world_xforms()  # the input posed once: props, terms and the correction of the result
        props = read_scene_props(options, clip, world)
        interaction, colliders = synthesis_interaction(options, clip, handmap, db, cfg, props, iconfig, path=source,
                                                       world=world)
    result = synthesize_clip(clip, handmap, db, cfg, tuple(with_fingers), finger_reference=options.finger_reference,
                             interaction=interaction)
    correction = None
    if options.props:
        from dataclasses import replace

        from usdhands.algorithms.interaction.correction import correct_clip
        from usdhands.model.handmap import HandMap

        corrected_hands = HandMap(**{s: handmap[s] for s in with_fingers})
        fixed, correction = correct_clip(result.clip, corrected_hands, colliders, margin_mm=options.margin,
                                         config=iconfig, world=world)
        result = replace(result, clip=fixed)
    progress(2, 4, "writing")
    if added:
        out = write_asset(Asset(str(source), (result.clip.skeleton,), (result.clip,), ()), output, inputs=(source,),
                          provenance=record)
    else:
        out = write_clip(source, result.clip, output, provenance=record,
                         **layer_options(options.as_layer, source, output))
    report = synthesis_report(result, db, cfg)
    if correction is not None:
        report["interaction"] = {**correction.to_dict(), "chains_corrected": correction.chains_corrected}
    report["animation"] = clip.name
    if options.plot is not None:
        report["plots"] = [str(p) for p in _plots(options.plot, clip, result, db, cfg)]
    progress(4, 4, "done")
    return SynthesizeResult(Path(out), str(db.path), cfg.segment_cost.k, (report,), False, len(asset.clips),
                            tuple(added), tuple(warnings))


def import_what_a_clip_needs(extensions=(".bvh",)) -> None:
    """Import now what one :func:`synthesize` of a clip otherwise imports on its way (each function
    imports where it needs, so that one command loads no more than it uses): the synthesis and format
    modules, the format handlers of ``extensions``, NumPy's lazily loaded parts it touches.

    For a process that forks many workers (``usdhands batch``'s warm forkserver), so that each worker's
    first clip costs what the others do. ``tests/test_batch.py`` checks that a synthesize
    of a BVH clip imports nothing more after it.
    """
    import numpy as np

    import usdhands.algorithms.synthesis.synthesize  # noqa: F401
    import usdhands.formats.hands  # noqa: F401
    import usdhands.jobs.plots.synthesis  # noqa: F401
    import usdhands.jobs.props  # noqa: F401
    import usdhands.model.hand_detection  # noqa: F401
    import usdhands.model.provenance  # noqa: F401
    import usdhands.model.units  # noqa: F401
    from usdhands.algorithms.synthesis import _dtw_numpy, feature_sets, segment_cost, stitching  # noqa: F401
    from usdhands.compiled import KERNEL_MODULES, kernel_module
    from usdhands.formats.registry import handler_for

    for name in KERNEL_MODULES:
        kernel_module(name)
    for ext in extensions:
        handler_for(Path("clip" + ext))
    np.ma  # noqa: B018  (np.unique loads it on first use)


def _no_progress(done: int, total: int, what: str = "") -> None:
    pass


def prepare_hands(source, options, asset, clip, db, cfg, warnings, handmap=None):
    """Hand map, hands to synthesize and grafting for one clip: ``(clip, handmap, sides, grafted joints)``.

    ``handmap``: the clip's hand map when the caller has it (a stage hook reads it from the
    stage); by default the override, the map the file records, or detection. Notes for the
    caller are appended to ``warnings``.
    """
    import numpy as np

    from usdhands.errors import NoHandsError
    from usdhands.jobs.inputs import handmap_for
    from usdhands.model.handmap import SIDES, HandMap

    wanted = list(options.hands) or list(SIDES)
    try:
        if handmap is None:
            handmap = handmap_for(clip, source, options.handmap)
    except NoHandsError:
        if not options.graft_hands:
            raise
        handmap = HandMap()
    with_fingers = [s for s in wanted if handmap[s] is not None and handmap[s].finger_joints]
    added = []
    if options.graft_hands and len(with_fingers) < len(wanted):
        clip, handmap, added = _graft(source, asset, clip, handmap, db, [s for s in wanted if s not in with_fingers],
                                      explicit=bool(options.hands))
        with_fingers = [s for s in wanted if handmap[s] is not None and handmap[s].finger_joints]
        if added and options.as_layer:
            raise UsdHandsError("--as-layer cannot add joints to the skeleton it overrides; with --graft-hands "
                                "the output is a new file (drop --as-layer)", path=source)
    if not with_fingers:
        found = ", ".join(f"{h.side} (wrist {h.wrist})" for h in handmap.sides) or "none"
        raise UsdHandsError(f"the skeleton has no finger joints on the {' or '.join(wanted)} hand "
                            f"(hands found: {found}); synthesis needs a rig with finger joints "
                            f"(or --graft-hands on a skeleton-only file)", path=source)
    if options.hands:
        missing = [s for s in wanted if s not in with_fingers]
        if missing:
            raise UsdHandsError(f"no {', '.join(missing)} hand with finger joints in this skeleton", path=source)
    db_sides = {SIDES[s] for s in np.unique(db.tracks[:, 3])}
    for s in with_fingers:
        if s not in db_sides:
            raise UsdHandsError(f"the database has no {s}-hand motion; rebuild it with --mirror", path=db.path)
    _check_features(source, cfg, db, handmap, with_fingers)
    differ = {key: (value, db.segmentation[key]) for key, value in vars(cfg.segmentation).items()
              if key in db.segmentation and abs(float(value) - float(db.segmentation[key])) > 1e-9}
    if differ:
        warnings.append("the input is segmented with other values than the database was ("
                        + ", ".join(f"{key} {a:g} here, {b:g} there" for key, (a, b) in differ.items())
                        + "); rebuild the database with the same --config for like segments")
    return clip, handmap, with_fingers, added


def _check_features(source, cfg, db, handmap, sides) -> None:
    """The database and the rig have what ``segment_cost.features`` names, or a one-line error."""
    from usdhands.algorithms.synthesis.feature_sets import check_keys, extra_keys, feature_terms

    keys = extra_keys(feature_terms(cfg.segment_cost))
    missing = [key for key in keys if key not in db.arm_feature_names]
    if missing:
        raise UsdHandsError(f"the database holds no {', '.join(missing)} features, which segment_cost.features "
                            f"names; build it with this configuration (usdhands db build --config)", path=db.path)
    for side in sides:
        try:
            check_keys(handmap, side, keys)
        except ValueError as e:
            raise UsdHandsError(str(e), path=source) from None


def _synthesize_all(source, output, options, asset, db, cfg, progress) -> SynthesizeResult:
    """``animation="all"``: every animation of the file gets fingers, written in one output."""
    from usdhands.algorithms.synthesis.synthesize import synthesize_clip
    from usdhands.formats.io import write_clip

    if options.graft_hands or options.as_layer:
        raise UsdHandsError("--animation all works without --graft-hands and --as-layer", path=source)
    if not asset.clips:
        raise UsdHandsError("no animation in file", path=source)
    results = []
    warnings: list[str] = []
    for i, clip in enumerate(asset.clips):
        progress(i, len(asset.clips), clip.name)
        clip, handmap, with_fingers, _ = prepare_hands(source, options, asset, clip, db, cfg, warnings)
        results.append((clip, synthesize_clip(clip, handmap, db, cfg, tuple(with_fingers),
                                              finger_reference=options.finger_reference)))
    # one animation per write: each write keeps the file's other animations, so chain them
    temps = []
    try:
        current = source
        for i, (_, res) in enumerate(results):
            if i == len(results) - 1:
                target = output
            else:
                fd, name = tempfile.mkstemp(suffix=output.suffix, prefix=f".{output.stem}.", dir=output.parent)
                os.close(fd)
                os.unlink(name)
                target = Path(name)
                temps.append(target)
            out = write_clip(current, res.clip, target, provenance=_provenance(options, cfg))
            current = target
    finally:
        for t in temps:
            with contextlib.suppress(OSError):
                t.unlink()
    reports = []
    for clip, res in results:
        r = synthesis_report(res, db, cfg)
        r["animation"] = clip.name
        if options.plot is not None:
            r["plots"] = [str(p) for p in _plots(options.plot / _safe_name(clip.name), clip, res, db, cfg)]
        reports.append(r)
    progress(len(asset.clips), len(asset.clips), "done")
    return SynthesizeResult(Path(out), str(db.path), cfg.segment_cost.k, tuple(reports), True, len(asset.clips),
                            (), tuple(dict.fromkeys(warnings)))


def _provenance(options: SynthesizeOptions, cfg) -> dict:
    """The UsdHandsFingerMotionAPI / extras record of a synthesis with these options."""
    from usdhands.jobs.inputs import bundled_database_path
    from usdhands.model.provenance import provenance_record

    return provenance_record("synthesis", database=options.db or bundled_database_path(), parameters={
        "config": cfg.to_dict(), "finger_reference": options.finger_reference, "graft_hands": bool(options.graft_hands),
        **({"props": [str(p) for p in options.props], "margin_mm": options.margin} if options.props else {})})


def _safe_name(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name.rsplit("/", 1)[-1]) or "animation"


def _check_output(source: Path, output: Path, options: SynthesizeOptions) -> None:
    """Refuse a bad output before any work: the input itself, a missing folder, ``as_layer``
    without USD on both sides, or another format than the input's (without ``graft_hands``,
    which writes a new file in any format)."""
    from usdhands.formats.registry import handler_for
    from usdhands.jobs.inputs import check_plot_folder
    from usdhands.jobs.outputs import MAIN_INPUT, check_paths

    from usdhands.jobs.plots.synthesis import FILES

    inputs = {MAIN_INPUT: source, "--db": options.db, "--config": options.config, "--handmap": options.handmap,
              "--props": options.props, "--interaction-config": options.interaction_config}
    check_paths(inputs, {"-o": output})
    layer_options(options.as_layer, source, output)
    check_plot_folder(options.plot, FILES, inputs)
    if options.finger_reference not in ("rest", "input"):
        raise UsdHandsError(f"finger_reference must be 'rest' or 'input', got {options.finger_reference!r}")
    if not options.graft_hands and source.exists():
        if handler_for(output, "write") is not handler_for(source, "read"):
            raise UsdHandsError(f"the output is the input file with fingers added, so it must have the input's "
                                f"format ({source.suffix}); use 'usdhands convert' first or after", path=output)


def _graft(source, asset, clip, handmap, db, sides, explicit):
    """Add finger joints for ``sides`` (those with a wrist) from the database's hand templates."""
    from usdhands.algorithms.synthesis.hand_graft import find_wrists, graft_hands
    from usdhands.model.handmap import HandMap, HandSide

    if asset.meshes:
        raise UsdHandsError("--graft-hands works on skeleton-only files (BVH, USD without skinned meshes): "
                            "this file has skinned meshes, which would need new skin weights", path=source)
    sk = clip.skeleton
    wrists = find_wrists(sk)
    todo = {}
    for side in sides:
        if handmap[side] is not None:
            h = handmap[side]
        elif side in wrists:
            w = wrists[side]
            chain = sk.chain_to_root(w)
            name = lambda i: sk.joint_names[chain[i]] if i < len(chain) else None  # noqa: E731
            h = HandSide(side, name(0), name(1), name(2), sk.joint_names[chain[-1]])
        elif explicit:
            raise UsdHandsError(f"--graft-hands: no {side} wrist joint found (looked for names with hand or wrist "
                                f"and a side: LeftHand, hand_l, Wrist.R, ...)", path=source)
        else:
            continue
        if side not in db.hands:
            raise UsdHandsError(f"the database holds no {side} hand geometry to graft (rebuild it with this "
                                f"version of usdhands, or with --mirror)", path=db.path)
        todo[side] = h
    if not todo:
        raise UsdHandsError("--graft-hands: no wrist joint found (looked for names with hand or wrist and a side: "
                            "LeftHand, hand_l, Wrist.R, ...); give --handmap", path=source)
    clip, grafted, added = graft_hands(clip, todo, db.hands)
    merged = {s: grafted[s] if s in todo else handmap[s] for s in SIDES_}
    return clip, HandMap(**merged), added


def synthesis_report(result, db, cfg) -> dict:
    """The per-animation report of a synthesis (see :attr:`SynthesizeResult.animations`)."""
    import numpy as np

    labels = db.segment_labels()
    hands = {}
    for side, h in result.hands.items():
        chosen = [labels[s] for s in h.chosen]
        counts = Counter("(no label)" if c is None else str(c) for c in chosen)
        hands[side] = {
            "segments": int(len(h.chosen)),
            "chosen_labels": [None if c is None else str(c) for c in chosen],
            "top_labels": ", ".join(f"{lab} {n}" for lab, n in counts.most_common(3)),
            "mean_segment_cost": float(np.mean(h.segment_costs[np.arange(len(h.path)), h.path])),
            "seams": int(len(h.seams.frame)),
            "seams_blended": int(h.seams.blended.sum()),
            "pruned_share": float(h.search.pruned_share),
            "body_scale": float(result.scale[side]),
        }
    return {"database": str(db.path), "k": cfg.segment_cost.k, "hands": hands, "mapping": result.mapping}


def _plots(folder: Path, clip, result, db, cfg) -> list[Path]:
    import numpy as np

    from usdhands.jobs.plots.synthesis import plot_finger_curves, plot_graph, plot_segmentation
    from usdhands.model.finger_dofs import finger_curves

    folder.mkdir(parents=True, exist_ok=True)
    labels = db.segment_labels()
    out = []
    for side, h in result.hands.items():
        out.append(plot_segmentation(h, db.fps, cfg.segmentation.speed_threshold_cm_s, folder / f"{side}_segments.png"))
        out.append(plot_graph(h, labels, folder / f"{side}_graph.png"))
        mapped = result.mapping[side]["mapped"]
        # the most proximal phalanx of each finger (slot d2, else the most proximal mapped)
        pick = []
        for finger in ("thumb", "index", "middle", "ring", "pinky"):
            js = sorted((slot, j) for j, slot in mapped if slot.startswith(finger + ".") and slot[-1] != "3")
            if js:
                pick.append(js[-1][1])
        joints = [clip.skeleton.index(j) for j in pick]
        before = finger_curves(clip, joints)
        after = finger_curves(result.clip, joints)
        # per joint, the axis that moves most (the flexion on most rigs)
        rng = np.ptp(after.values, axis=0).reshape(len(joints), 3)
        cols = [3 * i + int(np.argmax(rng[i])) for i in range(len(joints))]
        times = np.arange(clip.num_frames) / clip.fps
        out.append(plot_finger_curves(times, before.values[:, cols], after.values[:, cols],
                                      [after.names[c] for c in cols], folder / f"{side}_fingers.png",
                                      h.bounds[1:-1] / db.fps))
    return out

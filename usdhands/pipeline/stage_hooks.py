"""The jobs on an open ``Usd.Stage``: for a publish step that has the stage open already.

Each hook reads the stage as it composes now (every layer, the session layer, unsaved
edits), runs the job's method and authors the result sparsely into the stage's current
edit target, or into ``layer`` when given (a layer of the stage's layer stack or its
session layer). Nothing is saved: the caller inspects the stage and saves (or discards)
the layer it chose. Exposed as :mod:`usdhands.usd`::

    from pxr import Sdf, Usd
    import usdhands.usd

    stage = Usd.Stage.Open("shot010_anim.usda")
    fingers = Sdf.Layer.CreateNew("shot010_fingers.usda")
    # an override layer stronger than the root layer: a sublayer of the session layer (a
    # sublayer of the root layer would be weaker than the root's own opinions)
    stage.GetSessionLayer().subLayerPaths.append(fingers.identifier)
    edit = usdhands.usd.synthesize_stage(stage, "/Rig/Skel", layer=fingers)
    print(edit.animation, edit.report["hands"])      # what was authored, the figures
    fingers.Save()                                   # the caller saves

The hooks: :func:`synthesize_stage`, :func:`correct_stage`, :func:`reduce_stage`,
:func:`check_stage`. A hook for another job follows the same shape: read with
:func:`read_stage_clip`, run the job's method, author with ``_author`` inside
``_editing(stage, layer)``, return a :class:`StageEdit`.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path

from pxr import Sdf, Usd, UsdSkel

from usdhands.errors import NoSkeletonError, UsdHandsError
from usdhands.jobs.correction import CorrectOptions
from usdhands.jobs.reduction import ReduceOptions
from usdhands.jobs.synthesis import SynthesizeOptions

__all__ = ["StageEdit", "synthesize_stage", "correct_stage", "reduce_stage", "check_stage", "read_stage_clip"]


@dataclass(frozen=True)
class StageEdit:
    """What a hook authored.

    Attributes
    ----------
    skeleton : str
        Prim path of the Skeleton.
    animation : str
        Prim path of the SkelAnimation whose attributes were authored.
    layer : str
        Identifier of the layer the edits went into (not saved).
    report : dict
        The job's figures (as its ``--json`` report for one animation).
    """

    skeleton: str
    animation: str
    layer: str
    report: dict

    def to_json(self) -> dict:
        return {"skeleton": self.skeleton, "animation": self.animation, "layer": self.layer, "report": self.report}


def read_stage_clip(stage: Usd.Stage, skeleton_path: str | None = None):
    """``(asset, clip, handmap or None)``: the animation of the Skeleton at ``skeleton_path``
    (default: the first Skeleton with an animation) read from the composed stage, with the
    hand map the Skeleton records (``UsdHandsHandMapAPI``), if any.

    Raises
    ------
    NoSkeletonError
        No Skeleton at ``skeleton_path`` or none with an animation.
    """
    from usdhands.formats.usd_read import read_stage
    from usdhands.formats.usd_schema_data import read_hand_map

    where = _stage_name(stage)
    asset = read_stage(stage, path=where)
    clips = [c for c in asset.clips if skeleton_path is None or c.skeleton.name == str(skeleton_path)]
    if not clips:
        what = f"no animated Skeleton at {skeleton_path}" if skeleton_path else "no animated Skeleton"
        raise NoSkeletonError(what, path=where)
    clip = clips[0]
    prim = stage.GetPrimAtPath(clip.skeleton.name)
    handmap = read_hand_map(prim, path=where) if prim and prim.IsA(UsdSkel.Skeleton) else None
    return asset, clip, handmap


def synthesize_stage(stage: Usd.Stage, skeleton_path: str | None = None, db=None,
                     options: SynthesizeOptions = SynthesizeOptions(), *, layer: Sdf.Layer | None = None,
                     progress=None) -> StageEdit:
    """Synthesize finger motion for a Skeleton of an open stage; author it, record provenance.

    Parameters
    ----------
    stage : Usd.Stage
    skeleton_path : str, optional
        Prim path of the Skeleton (default: the first animated one).
    db : path or FingerDatabase, optional
        The database (a folder from ``usdhands db build`` or one already loaded); default
        ``options.db``, else the bundled one.
    options : SynthesizeOptions
        ``k``, ``hands``, ``config``, ``handmap``, ``finger_reference`` apply; ``graft_hands``,
        ``as_layer``, ``animation`` and ``plot`` do not (a hook edits the stage in place).
    layer : Sdf.Layer, optional
        Where to author (default: the stage's current edit target).

    Returns
    -------
    StageEdit
        ``report`` as :attr:`usdhands.jobs.synthesis.SynthesizeResult.animations`'s entries.
        The SkelAnimation gets ``UsdHandsFingerMotionAPI`` with method ``synthesis``, the
        database and the parameters; the Skeleton gets the hand map used.
    """
    from usdhands.algorithms.synthesis.synthesize import synthesize_clip
    from usdhands.jobs.inputs import cached_database, check_frames, load_config
    from usdhands.jobs.synthesis import prepare_hands, synthesis_report
    from usdhands.model.hand_detection import load_handmap

    if options.graft_hands:
        raise UsdHandsError("graft_hands adds joints to a skeleton: not on an open stage (use the synthesize job)")
    asset, clip, handmap = read_stage_clip(stage, skeleton_path)
    where = Path(_stage_name(stage))
    if options.handmap is not None:
        handmap = load_handmap(options.handmap, clip.skeleton)
    handmap = handmap or _detect(clip, where)
    check_frames(handmap, clip.skeleton, where)
    database = db if db is not None and not isinstance(db, (str, os.PathLike)) else cached_database(db or options.db)
    cfg = load_config(options.config)
    if options.k is not None:
        if options.k < 1:
            raise UsdHandsError(f"--k must be at least 1, got {options.k}")
        cfg = cfg.with_values(segment_cost={"k": options.k})
    warnings: list[str] = []
    clip, handmap, sides, _ = prepare_hands(where, options, asset, clip, database, cfg, warnings, handmap)
    if progress:
        progress(1, 2, "synthesizing")
    result = synthesize_clip(clip, handmap, database, cfg, tuple(sides), finger_reference=options.finger_reference)
    report = synthesis_report(result, database, cfg)
    report["warnings"] = warnings
    provenance = {"method": "synthesis", "database": str(database.path),
                  "parameters": {"k": cfg.segment_cost.k, "hands": list(sides),
                                 "finger_reference": options.finger_reference}}
    with _editing(stage, layer) as target:
        skel, anim = _author(stage, result.clip, clip.name, handmap, provenance)
    if progress:
        progress(2, 2, "done")
    return StageEdit(skel, anim, target, report)


def correct_stage(stage: Usd.Stage, props=(), skeleton_path: str | None = None,
                  options: CorrectOptions = CorrectOptions(), *, layer: Sdf.Layer | None = None,
                  progress=None) -> StageEdit:
    """Push the fingers of a Skeleton's animation on an open stage out of props; author the correction.

    Parameters
    ----------
    stage : Usd.Stage
    props : sequence of paths
        The prop files (meshes, or USD files with Mesh prims); when given they replace
        ``options.props``. One of the two must name at least one prop.
    skeleton_path : str, optional
        Prim path of the Skeleton (default: the first animated one).
    options : CorrectOptions
        ``margin``, ``self_collision``, ``attach``, ``prop_units``, ``prop_up``,
        ``interaction_config`` and ``handmap`` apply; ``as_layer``, ``animation`` and ``plot``
        do not (a hook edits the stage in place).
    layer : Sdf.Layer, optional
        Where to author (default: the stage's current edit target).

    Returns
    -------
    StageEdit
        ``report`` as :meth:`usdhands.jobs.correction.CorrectResult.to_json` (``output`` is
        the layer authored into). Only the finger joints that moved are authored; the
        SkelAnimation gets ``UsdHandsFingerMotionAPI`` with method ``interaction``.
    """
    import dataclasses
    import time

    from usdhands.jobs.correction import check_correct_options, correct_loaded, correction_provenance, result_of
    from usdhands.model.hand_detection import load_handmap

    if props:
        options = dataclasses.replace(options, props=tuple(Path(p) for p in props))
    check_correct_options(options)
    asset, clip, handmap = read_stage_clip(stage, skeleton_path)
    where = Path(_stage_name(stage))
    if options.handmap is not None:
        handmap = load_handmap(options.handmap, clip.skeleton)
    handmap = handmap or _detect(clip, where)
    if progress:
        progress(1, 2, "correcting")
    start = time.perf_counter()
    from usdhands.jobs.props import hand_meshes

    fixed, report, _, config = correct_loaded(clip, handmap, options, where, hand_meshes(asset, clip))
    seconds = time.perf_counter() - start
    with _editing(stage, layer) as target:
        skel, anim = _author(stage, fixed, clip.name, None, correction_provenance(options, config))
    if progress:
        progress(2, 2, "done")
    summary = result_of(report, where, Path(target), clip.num_frames, options, seconds).to_json()
    summary["output"] = target
    return StageEdit(skel, anim, target, summary)


def reduce_stage(stage: Usd.Stage, skeleton_path: str | None = None, options: ReduceOptions = ReduceOptions(), *,
                 layer: Sdf.Layer | None = None, progress=None) -> StageEdit:
    """Reduce the finger curves of a Skeleton's animation on an open stage and author the simplified curves.

    Every finger curve is rebuilt from the chosen step's model (constants and relations), as
    the reduce job's output clip. ``report`` is the reduce job's ``--json`` report; the
    SkelAnimation gets ``UsdHandsFingerMotionAPI`` with method ``reduction``.
    ``options.as_layer`` and ``options.plot`` do not apply.
    """
    from usdhands.algorithms.reduction.reduce import expand_clip
    from usdhands.jobs.reduction import ReduceResult, finger_curves_for, reduce_finger_curves
    from usdhands.model.hand_detection import load_handmap

    asset, clip, handmap = read_stage_clip(stage, skeleton_path)
    where = Path(_stage_name(stage))
    if options.handmap is not None:
        handmap = load_handmap(options.handmap, clip.skeleton)
    handmap = handmap or _detect(clip, where)
    curves, sides = finger_curves_for(clip, handmap, options.hands, options.order, where)
    result, k, paper, names = reduce_finger_curves(clip, handmap, curves, sides, options, where)
    chosen = result.steps[k - 1]
    out_clip = expand_clip(clip, curves.joints, chosen.model)
    report = ReduceResult(where, int(clip.num_frames), float(clip.fps), tuple(names), tuple(sides), result, k,
                          paper).to_json()
    provenance = {"method": "reduction", "parameters": {"steps": options.steps, "step": k,
                                                        "free_curves": list(chosen.model.free_curves)}}
    with _editing(stage, layer) as target:
        skel, anim = _author(stage, out_clip, clip.name, None, provenance)
    if progress:
        progress(1, 1, "done")
    return StageEdit(skel, anim, target, report)


def check_stage(stage: Usd.Stage, options=None) -> list:
    """The ``usdhands check`` rules on an open stage as it composes now: a list of findings.

    See :func:`usdhands.jobs.validation.check_usd_stage`; nothing is authored.
    """
    from usdhands.jobs.validation import CheckOptions, check_usd_stage

    return check_usd_stage(stage, options or CheckOptions())


def _detect(clip, where):
    """The hand map detection finds on ``clip``'s skeleton; NoHandsError naming the stage."""
    from usdhands.errors import NoHandsError
    from usdhands.model.hand_detection import detect_hands

    try:
        return detect_hands(clip.skeleton)
    except NoHandsError as e:
        raise NoHandsError(e.message, path=where) from None


def _stage_name(stage: Usd.Stage) -> str:
    return stage.GetRootLayer().identifier


@contextlib.contextmanager
def _editing(stage: Usd.Stage, layer: Sdf.Layer | None):
    """The stage's edit target, or ``layer`` for the duration; yields the layer's identifier.

    A ``layer`` without a ``timeCodesPerSecond`` of its own gets the stage's; so does the edit
    target's layer (the session layer, say) when the target maps times one to one.
    """
    if layer is None:
        target = stage.GetEditTarget()
        if target.GetLayer() != stage.GetRootLayer() and target.GetMapFunction().timeOffset.IsIdentity():
            _own_rate(stage, target.GetLayer())
        yield target.GetLayer().identifier
        return
    if not stage.HasLocalLayer(layer):
        raise UsdHandsError(f"layer {layer.identifier} is not in the stage's layer stack or session layer: add it "
                            "(stage.GetRootLayer().subLayerPaths.insert(0, layer.identifier)) first")
    _own_rate(stage, layer)
    with Usd.EditContext(stage, layer):
        yield layer.identifier


def _own_rate(stage: Usd.Stage, layer: Sdf.Layer) -> None:
    """Give ``layer`` the stage's time codes per second unless it has its own.

    A sublayer (or session layer) without its own rate is read at 24 time codes per second
    and scaled onto the stage's: frames authored at the stage's time codes would land at
    other times.
    """
    if not layer.HasTimeCodesPerSecond():
        layer.timeCodesPerSecond = stage.GetTimeCodesPerSecond()
        layer.framesPerSecond = stage.GetFramesPerSecond()


def _author(stage: Usd.Stage, clip, animation: str, handmap, provenance: dict) -> tuple[str, str]:
    from usdhands.formats.usd_write import author_clip

    skel_prim, anim_prim = author_clip(stage, clip, animation=animation, hand_map=handmap, finger_motion=provenance)
    return str(skel_prim.GetPath()), str(anim_prim.GetPath())

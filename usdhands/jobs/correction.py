"""The correct job: push fingers out of props (and the body), smoothly (Bitan, Jörg, Kraus 2016).

Reads the animation and the props, detects where finger capsules penetrate, opens each
penetrating finger chain by the least amount that clears every collider (IK within the
joint limits), smooths the correction with the contact as a bound and writes the result
into a copy of the input (or a USD layer over it). Nothing penetrates deeper than 0.25 mm
afterwards (half the clearance search's resolution); fingers that were clear are left
bit-for-bit unchanged and body joints are never touched.

::

    import usdhands
    result = usdhands.correct("take.usda", "take_fixed.usda",
                              usdhands.CorrectOptions(props=("cup.obj",), margin=0.5))
    print(result.penetration_after_mm["max"], result.frames_corrected)
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

from usdhands.errors import UsdHandsError
from usdhands.jobs.outputs import MAIN_INPUT, check_paths, layer_options

ProgressCallback = Callable[[int, int, str], None]


@dataclass(frozen=True)
class CorrectOptions:
    """Options of :func:`correct`; the defaults are the command line's.

    Attributes
    ----------
    props : tuple of Path
        Props the hands touch: mesh files (.obj .stl .ply .off .glb .gltf) or USD files with
        Mesh prims (at least one).
    margin : float
        Clearance to keep between fingers and props, millimetres (0 to 100; 0: touching).
    self_collision : bool
        Also keep the fingers out of the character's own body (torso, head, upper arms, thighs).
    attach : tuple of str
        ``"PROP=JOINT[:FROM-TO]"``: the prop moves with JOINT (a hand) from frame FROM to TO
        inclusive (default every frame); PROP is the prop file's name or stem.
    prop_units : float or None
        Metres per unit of the prop files (None: what the file says; OBJ, STL, PLY, OFF: the clip's).
    prop_up : str or None
        ``"Y"`` or ``"Z"``, the up axis of the prop files (None: what the file says; else Y).
    interaction_config : Path or None
        Finger radii, joint limits and smoothing (schemas/interaction_config.schema.json).
    as_layer : bool
        USD: write a sparse override layer over the input instead of a full copy.
    handmap : Path or None
        Hand map JSON overriding detection.
    animation : str or None
        Animation name or index in the file (default the first).
    plot : Path or None
        Folder to write ``penetration_depth.png`` and ``worst_frame.png`` into.
    """

    props: tuple[Path, ...] = ()
    margin: float = 0.0
    self_collision: bool = False
    attach: tuple[str, ...] = ()
    prop_units: float | None = None
    prop_up: str | None = None
    interaction_config: Path | None = None
    as_layer: bool = False
    handmap: Path | None = None
    animation: str | None = None
    plot: Path | None = None


@dataclass(frozen=True)
class CorrectResult:
    """What :func:`correct` did.

    Attributes
    ----------
    file, output : Path
        The input and the file written.
    frames : int
        Frames of the animation.
    props : tuple of str
        The prop files.
    penetration_before_mm, penetration_after_mm : dict
        ``{"max", "mean", "frames"}``: the deepest finger penetration per frame (mm), its
        maximum and mean over the frames, and the number of frames where it is above zero.
    frames_corrected : int
        Frames where a finger chain was opened.
    jitter_before, jitter_after : float
        Mean angular acceleration of the finger joints, degrees per second squared.
    max_change_deg : float
        Largest change of a finger joint's rotation, degrees.
    chains_corrected : tuple of str
        The finger chains that were opened.
    unresolved : tuple of (str, int)
        ``(chain, frame)`` pairs that still touch with the finger fully open (the palm or
        wrist is in a prop there: only body motion could clear it).
    seconds : float
        Time the correction itself took.
    plots : tuple of Path
        PNGs written with ``plot``.
    """

    file: Path
    output: Path
    frames: int
    props: tuple[str, ...]
    penetration_before_mm: dict
    penetration_after_mm: dict
    frames_corrected: int
    jitter_before: float
    jitter_after: float
    max_change_deg: float
    chains_corrected: tuple[str, ...] = ()
    unresolved: tuple[tuple[str, int], ...] = ()
    seconds: float = 0.0
    plots: tuple[Path, ...] = field(default=())

    @property
    def warnings(self) -> tuple[str, ...]:
        """Things the caller should know (chain frames that no finger opening clears)."""
        if not self.unresolved:
            return ()
        chains = sorted({c for c, _ in self.unresolved})
        return (f"{len(self.unresolved)} chain frames touch even with the finger open, or are the palm in a prop "
                f"({', '.join(chains)}): the palm or wrist is in a prop there and only body motion could clear it",)

    def to_json(self) -> dict:
        """The ``usdhands correct --json`` report."""
        return {"file": str(self.file), "output": str(self.output), "frames": self.frames, "props": list(self.props),
                "penetration_before_mm": dict(self.penetration_before_mm),
                "penetration_after_mm": dict(self.penetration_after_mm),
                "frames_corrected": self.frames_corrected, "jitter_before": self.jitter_before,
                "jitter_after": self.jitter_after, "max_change_deg": self.max_change_deg,
                "chains_corrected": list(self.chains_corrected), "unresolved_frames": len(self.unresolved),
                "seconds": round(self.seconds, 3)}


def correct(source: str | os.PathLike, output: str | os.PathLike, options: CorrectOptions = CorrectOptions(),
            progress: ProgressCallback | None = None) -> CorrectResult:
    """Correct finger penetration of ``options.props`` in ``source`` and write ``output`` (same format).

    Parameters
    ----------
    source : path
        Animation file (.usd/.usda/.usdc/.usdz, .gltf/.glb, .bvh) with finger joints.
    output : path
        File to write, atomically; never one of the inputs (nor a prop).
    options : CorrectOptions
        ``props`` must name at least one prop.
    progress : callable, optional
        Called as ``progress(done, total, what)``.

    Returns
    -------
    CorrectResult

    Raises
    ------
    UsdHandsError
        A bad input or option (unreadable file or prop, no hands, a unit slip in a prop, a bad
        ``attach``, an output equal to an input); nothing is written then.
    """
    from usdhands.errors import AssetReadError, NoSkeletonError
    from usdhands.formats.io import read_asset, write_clip
    from usdhands.jobs.inputs import check_plot_folder, handmap_for
    from usdhands.jobs.props import hand_meshes

    source, output = Path(source), Path(output)
    progress = progress or _no_progress
    from usdhands.jobs.plots.interaction import FILES

    inputs = {MAIN_INPUT: source, "--props": options.props, "--handmap": options.handmap,
              "--interaction-config": options.interaction_config}
    check_paths(inputs, {"-o": output})
    write_opts = layer_options(options.as_layer, source, output)
    check_correct_options(options)
    check_plot_folder(options.plot, FILES, inputs)
    progress(0, 3, "reading")
    asset = read_asset(source)
    if not asset.skeletons:
        raise NoSkeletonError("no skeleton in file", path=source)
    try:
        clip = asset.clip(options.animation)
    except KeyError as e:
        raise AssetReadError(str(e.args[0]).split(": ", 1)[-1], path=source) from None
    handmap = handmap_for(clip, source, options.handmap)
    progress(1, 3, "correcting")
    start = time.perf_counter()
    fixed, report, colliders, config = correct_loaded(clip, handmap, options, source, hand_meshes(asset, clip))
    seconds = time.perf_counter() - start
    progress(2, 3, "writing")
    written = write_clip(source, fixed, output, provenance=correction_provenance(options, config), **write_opts)
    plots = ()
    if options.plot is not None:
        from usdhands.jobs.plots.interaction import plot_correction

        plots = tuple(plot_correction(options.plot, clip, fixed, handmap, colliders, report, config))
    progress(3, 3, "done")
    return result_of(report, source, Path(written), clip.num_frames, options, seconds, plots)


def check_correct_options(options: CorrectOptions) -> None:
    """Refuse bad correct options before any work (no props, margin, units, ``attach``)."""
    from usdhands.jobs.props import check_prop_options

    if not options.props:
        raise UsdHandsError("--props: name at least one prop file to correct against")
    check_prop_options(options)


def correct_loaded(clip, handmap, options: CorrectOptions, path, meshes=()):
    """The correction of a clip already read: ``(corrected clip, CorrectionReport, Colliders, InteractionConfig)``.

    ``path`` names the animation in errors (a file, or a stage's root layer); ``meshes``: the
    meshes skinned to the clip's skeleton, whose vertices give the finger capsules' radii.
    """
    from usdhands.algorithms.interaction.correction import correct_clip
    from usdhands.algorithms.interaction.finger_geometry import InteractionConfig, load_interaction_config
    from usdhands.jobs.props import build_colliders, read_scene_props, with_mesh_radii

    config = load_interaction_config(options.interaction_config) if options.interaction_config \
        else InteractionConfig()
    config = with_mesh_radii(config, clip, handmap, meshes)
    props = read_scene_props(options, clip)
    colliders, _ = build_colliders(options, clip, handmap, props, path=path)
    fixed, report = correct_clip(clip, handmap, colliders, margin_mm=options.margin, config=config)
    return fixed, report, colliders, config


def correction_provenance(options: CorrectOptions, config) -> dict:
    """The finger-motion record of a correction with these options (method ``interaction``)."""
    from usdhands.model.provenance import provenance_record

    return provenance_record("interaction", parameters={
        "props": [str(p) for p in options.props], "margin_mm": options.margin, "config": asdict(config)})


def result_of(report, source, output, frames: int, options: CorrectOptions, seconds: float = 0.0,
              plots=()) -> CorrectResult:
    """A :class:`CorrectResult` from the algorithm's ``CorrectionReport``."""
    d = report.to_dict()
    return CorrectResult(Path(source), Path(output), int(frames), tuple(str(p) for p in options.props),
                         d["penetration_before_mm"], d["penetration_after_mm"], d["frames_corrected"],
                         d["jitter_before"], d["jitter_after"], d["max_change_deg"],
                         tuple(report.chains_corrected), tuple((str(c), int(f)) for c, f in report.unresolved),
                         seconds, tuple(Path(p) for p in plots))


def _no_progress(done: int, total: int, what: str = "") -> None:
    pass

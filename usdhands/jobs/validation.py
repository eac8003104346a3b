"""The check job: the ``usdhands check`` rules on USD, glTF and BVH files.

Rules (:data:`usdhands.model.findings.RULES`): ``hands`` (mapped or detectable),
``finger-coverage`` (an animation animates the finger joints of its skeleton),
``quaternions`` (no NaN or zero-length rotation), ``array-lengths`` (joint counts and
array lengths agree), ``provenance`` (finger-motion records well-formed; with
``require_provenance`` present wherever finger joints are animated). Each format's audit
lives beside its reader (:mod:`usdhands.formats.usd_audit`, ``gltf_audit``, ``bvh_audit``).

::

    import usdhands
    result = usdhands.check(["a.usda", "b.glb"])
    for finding in result.findings:
        print(finding)            # file: where: rule: message
    raise SystemExit(result.exit_status)

On an open stage: :func:`usdhands.usd.check_stage`; inside USD's own validation:
:func:`usdhands.pipeline.usd_validation.register_validators` (keyword ``usdhands``).

``props`` (with ``props``): no finger capsule penetrates a prop (or, with
``self_collision``, the body) deeper than ``penetration_tolerance_mm``, measured with the
interaction method's finger geometry; one finding per finger and prop.

Adding a rule: a field on :class:`CheckOptions`, the rule's key in ``RULES``, and a
function ``(path, clip, options) -> list[Finding]`` called from :func:`_check_file` for
every readable file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from usdhands.errors import UsdHandsError
from usdhands.model.findings import Finding


@dataclass(frozen=True)
class CheckOptions:
    """Options of :func:`check`.

    Attributes
    ----------
    require_provenance : bool
        Every animation that animates finger joints must carry a finger-motion record
        (USD ``UsdHandsFingerMotionAPI``, glTF ``extras.usdhands.provenance``); without it,
        only the records that are there are checked.
    props : tuple of Path
        Prop files (meshes, or USD files with Mesh prims): the ``props`` rule, fingers do not
        penetrate them. The other prop options (``attach`` ``"PROP=JOINT[:FROM-TO]"``,
        ``prop_units``, ``prop_up``, ``self_collision``: the body too, ``interaction_config``:
        finger radii) are those of :class:`usdhands.jobs.correction.CorrectOptions`.
    penetration_tolerance_mm : float
        Deepest penetration the ``props`` rule lets through, mm (``usdhands correct``
        guarantees 0.25 mm).
    """

    require_provenance: bool = False
    props: tuple[Path, ...] = ()
    attach: tuple[str, ...] = ()
    prop_units: float | None = None
    prop_up: str | None = None
    self_collision: bool = False
    interaction_config: Path | None = None
    penetration_tolerance_mm: float = 0.5


@dataclass(frozen=True)
class FileCheck:
    """One file's outcome: its findings, or the error that kept it from being read."""

    file: str
    findings: tuple[Finding, ...] = ()
    error: str | None = None

    @property
    def status(self) -> str:
        """``"ok"``, ``"failed"`` (a rule broken) or ``"unreadable"``."""
        return "unreadable" if self.error else ("failed" if self.findings else "ok")


@dataclass(frozen=True)
class CheckResult:
    """What :func:`check` found, per file."""

    files: tuple[FileCheck, ...]

    @property
    def findings(self) -> list[Finding]:
        return [f for fc in self.files for f in fc.findings]

    @property
    def exit_status(self) -> int:
        """2 when a file could not be read, else 1 when a rule failed, else 0."""
        if any(fc.error for fc in self.files):
            return 2
        return 1 if self.findings else 0

    def to_json(self) -> dict:
        """The ``usdhands check --json`` report."""
        return {
            "files": [{"file": fc.file, "status": fc.status, "findings": [f.to_json() for f in fc.findings],
                       **({"error": fc.error} if fc.error else {})} for fc in self.files],
            "checked": len(self.files),
            "failed": sum(fc.status == "failed" for fc in self.files),
            "unreadable": sum(fc.status == "unreadable" for fc in self.files),
            "findings": len(self.findings),
        }


def check(paths: Sequence[str | os.PathLike] | str | os.PathLike, options: CheckOptions = CheckOptions(),
          progress: Callable[[int, int, str], None] | None = None) -> CheckResult:
    """Check files against the rules; never raises for a bad file (it ends as ``unreadable``).

    Parameters
    ----------
    paths : path or sequence of paths
        ``.usd/.usda/.usdc/.usdz``, ``.gltf/.glb``, ``.bvh``.
    options : CheckOptions
    progress : callable, optional
        ``progress(done, total, what)``.

    Raises
    ------
    UsdHandsError
        Bad options: a prop file missing, a bad ``attach`` or tolerance (before any file is read).
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    paths = [Path(p) for p in paths]
    _check_options(options)
    out = []
    for i, p in enumerate(paths):
        try:
            out.append(FileCheck(str(p), tuple(_check_file(p, options))))
        except UsdHandsError as e:
            out.append(FileCheck(str(p), (), str(e)))
        if progress:
            progress(i + 1, len(paths), p.name)
    return CheckResult(tuple(out))


def check_usd_stage(stage, options: CheckOptions = CheckOptions()) -> list[Finding]:
    """The rules on an open ``Usd.Stage`` as it composes now (unsaved edits included)."""
    from usdhands.formats.usd_audit import audit_stage

    _check_options(options)
    findings = audit_stage(stage, require_provenance=options.require_provenance)
    if options.props and not _unsound(findings):
        from usdhands.formats.usd_read import read_stage

        from usdhands.formats.usd_schema_data import read_hand_map
        from usdhands.model.hand_detection import detect_hands

        name = stage.GetRootLayer().identifier

        def recorded_or_detected(clip):
            prim = stage.GetPrimAtPath(clip.skeleton.name)
            return (read_hand_map(prim, path=name) if prim else None) or detect_hands(clip.skeleton)

        asset = read_stage(stage, path=name)
        findings += prop_findings(name, asset.clips, options, recorded_or_detected, asset=asset)
    return findings


def _check_file(path: Path, options: CheckOptions) -> list[Finding]:
    from usdhands.formats.registry import handler_for
    from usdhands.input_files import check_regular_file

    check_regular_file(path)  # missing, a folder, a named pipe, a device: the readers' words
    kind = handler_for(path, "read").name
    findings = _audit(path, kind, options)
    if options.props and not _unsound(findings):
        from usdhands.formats.io import read_asset

        asset = read_asset(path)
        findings += prop_findings(str(path), asset.clips, options, asset=asset)
    return findings


def _audit(path: Path, kind: str, options: CheckOptions) -> list[Finding]:
    if kind == "usd":
        from usdhands.formats.usd_audit import audit_usd

        return audit_usd(path, require_provenance=options.require_provenance)
    if kind == "gltf":
        from usdhands.formats.gltf_audit import audit_gltf

        return audit_gltf(path, require_provenance=options.require_provenance)
    from usdhands.formats.bvh_audit import audit_bvh

    return audit_bvh(path)


def _unsound(findings: list[Finding]) -> bool:
    """Findings that keep the animation from being posed (the props rule is not measured then)."""
    return any(f.rule in ("quaternions", "array-lengths") for f in findings)


def _prop_options(options: CheckOptions):
    """The prop options as the correct job holds them (what :mod:`usdhands.jobs.props` reads)."""
    from usdhands.jobs.correction import CorrectOptions

    return CorrectOptions(props=tuple(options.props), attach=tuple(options.attach), prop_units=options.prop_units,
                          prop_up=options.prop_up, self_collision=options.self_collision,
                          interaction_config=options.interaction_config)


def _check_options(options: CheckOptions) -> None:
    from usdhands.jobs.props import refuse_prop_options_without_props

    refuse_prop_options_without_props(options)
    if not options.props:
        return
    from usdhands.jobs.correction import check_correct_options

    tol = options.penetration_tolerance_mm
    if not (0.0 <= tol <= 100.0):
        raise UsdHandsError(f"--tolerance must be between 0 and 100 mm, got {tol:g}")
    check_correct_options(_prop_options(options))


def prop_findings(name: str, clips, options: CheckOptions, handmap_of=None, asset=None) -> list[Finding]:
    """The ``props`` rule on ``clips`` (of the file or stage ``name``): a finding per finger (and per
    palm) and prop that goes deeper than ``options.penetration_tolerance_mm`` into the prop.

    ``handmap_of(clip)``: the clip's hand map (default: the one the file records, or detection).
    ``asset``: the file read, whose meshes skinned to the hand give the finger capsules' radii
    as ``correct`` takes them.

    ``where`` is the SkelAnimation's prim path for USD, else the finger's first joint (the
    glTF node, the BVH joint). Clips without a detectable hand are left to the ``hands`` rule.
    """
    from usdhands.algorithms.interaction.colliders import Colliders
    from usdhands.algorithms.interaction.correction import chain_posers, penetration_depth_mm
    from usdhands.algorithms.interaction.finger_geometry import InteractionConfig, load_interaction_config
    from usdhands.algorithms.interaction.palm import palm_depth_mm
    from usdhands.errors import NoHandsError
    from usdhands.jobs.inputs import handmap_for
    from usdhands.jobs.props import build_colliders, hand_meshes, read_scene_props, with_mesh_radii

    prop_options = _prop_options(options)
    config = load_interaction_config(options.interaction_config) if options.interaction_config \
        else InteractionConfig()
    out = []
    for clip in clips:
        try:
            handmap = handmap_of(clip) if handmap_of is not None else handmap_for(clip, name, None)
        except NoHandsError:
            continue
        props = read_scene_props(prop_options, clip)
        colliders, _ = build_colliders(prop_options, clip, handmap, props, path=name)
        meshes = hand_meshes(asset, clip) if asset is not None else ()
        measured = with_mesh_radii(config, clip, handmap, meshes)
        world = clip.world_xforms()
        posers = chain_posers(clip, handmap, measured, world)
        # each finger, then each palm (wrist to the long fingers' bases), against each collider
        parts = [(f"the {p.chain.name} finger", p.chain.joints[0], lambda one, p=p: penetration_depth_mm(clip, [p], one))
                 for p in posers]
        parts += [(f"the {hand.side} palm", clip.skeleton.index(hand.wrist),
                   lambda one, hand=hand: palm_depth_mm(world, clip.skeleton, hand, [p.chain for p in posers], one,
                                                        measured))
                  for hand in handmap.sides]
        for what, joint, depth_of in parts:
            for item in colliders.items:
                depth = depth_of(Colliders([item]))
                deep = depth > options.penetration_tolerance_mm
                if not deep.any():
                    continue
                joint_name = clip.skeleton.joint_names[joint]
                where = clip.name if clip.name.startswith("/") else joint_name.rsplit("/", 1)[-1]
                out.append(Finding(name, where, "props",
                                   f"{what} penetrates {item.name} by up to "
                                   f"{depth.max():.2f} mm in {int(deep.sum())} frame(s), deepest at frame "
                                   f"{int(depth.argmax())} (tolerance {options.penetration_tolerance_mm:g} mm)"))
    return out

"""Shared by ``correct`` and the synthesize job's ``props``: checking the prop options, reading props, the colliders.

The functions take ``options``: any object with the prop options as attributes (``props``,
``margin``, ``self_collision``, ``attach``, ``prop_units``, ``prop_up``,
``interaction_config``, and ``collision_weight`` for synthesis), such as
:class:`usdhands.jobs.synthesis.SynthesizeOptions` or :class:`usdhands.jobs.correction.CorrectOptions`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from usdhands.errors import UsdHandsError


@dataclass(frozen=True)
class Attachment:
    """``--attach PROP=JOINT[:FROM-TO]`` parsed."""

    prop: str
    joint: str
    start: int | None
    stop: int | None


_ATTACH = re.compile(r"^(?P<prop>[^=]+)=(?P<joint>[^:]+)(:(?P<a>\d+)-(?P<b>\d+))?$")


def parse_attachments(specs: list[str]) -> list[Attachment]:
    """Parse every ``--attach``; a one-line error for a malformed one."""
    out = []
    for s in specs:
        m = _ATTACH.match(s.strip())
        if m is None:
            raise UsdHandsError(f"--attach {s!r}: expected PROP=JOINT or PROP=JOINT:FROM-TO (frames)")
        a, b = m.group("a"), m.group("b")
        if a is not None and int(a) > int(b):
            raise UsdHandsError(f"--attach {s!r}: frame range {a}-{b} runs backwards")
        out.append(Attachment(m.group("prop").strip(), m.group("joint").strip(),
                              None if a is None else int(a), None if b is None else int(b)))
    return out


def check_margin(margin: float) -> float:
    """``--margin`` if usable (0 to 100 mm)."""
    if not (0.0 <= margin <= 100.0):
        raise UsdHandsError(f"--margin must be between 0 and 100 mm, got {margin:g}")
    return float(margin)


def check_prop_options(options) -> None:
    """Refuse bad prop options before any work."""
    check_margin(options.margin)
    if options.prop_units is not None and not (1e-6 <= options.prop_units <= 1e6):
        raise UsdHandsError(f"--prop-units must be metres per unit between 1e-6 and 1e6, got {options.prop_units:g}")
    for p in options.props:
        if not Path(p).exists():
            raise UsdHandsError("no such prop file", path=p)
    parse_attachments(options.attach)


#: prop option -> (its flag, its value when not given): nothing reads them without ``props``
_NEED_PROPS = {"self_collision": ("--self", False), "interaction_config": ("--interaction-config", None),
               "attach": ("--attach", ()), "prop_units": ("--prop-units", None), "prop_up": ("--prop-up", None),
               "margin": ("--margin", 0.0)}


def refuse_prop_options_without_props(options) -> None:
    """Refuse, before any work, prop options given without ``props`` (nothing would read them).

    A given ``interaction_config`` file is read first, so a missing or broken one is named.

    Raises
    ------
    UsdHandsError
        One line: ``--self needs --props (nothing else reads it)``, or the file's error.
    """
    if options.props:
        return
    if getattr(options, "interaction_config", None) is not None:
        from usdhands.algorithms.interaction.finger_geometry import load_interaction_config

        load_interaction_config(options.interaction_config)
    for name, (flag, unset) in _NEED_PROPS.items():
        value = getattr(options, name, unset)
        if (len(value) > 0 if isinstance(unset, tuple) else value is not None and value != unset):
            raise UsdHandsError(f"{flag} needs --props (nothing else reads it)")


def read_scene_props(options, clip, world=None):
    """Every prop of ``--props`` in the clip's units, checked for unit slips: list of (path, PropMesh).

    ``world``: the clip's world transforms ``(T, J, 4, 4)`` when the caller has them.
    """
    from usdhands.formats.props import USD_SUFFIXES, check_prop_units, read_props

    sk = clip.skeleton
    positions = clip.world_positions() if world is None else world[..., :3, 3]
    bounds = np.array([positions.reshape(-1, 3).min(axis=0), positions.reshape(-1, 3).max(axis=0)])
    out = []
    for path in options.props:
        props = read_props(path, meters_per_unit=sk.meters_per_unit, up_axis=sk.up_axis,
                           prop_meters_per_unit=options.prop_units, prop_up_axis=options.prop_up)
        suffix = Path(path).suffix.lower()
        claimed = options.prop_units
        if claimed is None and suffix in USD_SUFFIXES:
            from usdhands.formats.usd_props import stage_meters_per_unit

            claimed = stage_meters_per_unit(path)
        elif claimed is None:
            claimed = 1.0 if suffix in (".glb", ".gltf") else sk.meters_per_unit
        for prop in props:
            check_prop_units(prop, bounds, sk.meters_per_unit, claimed)
        out.extend((Path(path), prop) for prop in props)
    return out


def build_colliders(options, clip, handmap, props, path=None, world=None, proximities=None):
    """The colliders of the scene: the props (static, animated or attached) and, with ``--self``, the body.

    ``world``: the clip's world transforms ``(T, J, 4, 4)`` when the caller has them; ``proximities``:
    a dict from a prop's index in ``props`` to its ``MeshProximity``, used where it holds one and filled
    where not (the same props placed at two frame rates build their trees once).
    Returns ``(Colliders, attachments)``.
    """
    from usdhands.algorithms.interaction.body import body_collider
    from usdhands.algorithms.interaction.colliders import Colliders, attached_xforms, mesh_collider

    T = clip.num_frames
    path = path if path is not None else getattr(options, "file", None)
    attachments = parse_attachments(options.attach)
    by_prop: dict[int, Attachment] = {}
    for att in attachments:
        hits = [i for i, (path, prop) in enumerate(props)
                if att.prop in (path.name, path.stem, str(path), prop.name)]
        if not hits:
            names = ", ".join(sorted({p.name for p, _ in props}))
            raise UsdHandsError(f"--attach {att.prop}={att.joint}: no prop named {att.prop!r} (the props are {names})")
        if not clip.skeleton.has_joint(att.joint):
            raise UsdHandsError(f"--attach {att.prop}={att.joint}: no joint named {att.joint!r} in the animation "
                                f"(skeleton {clip.skeleton.name!r})", path=path)
        if att.start is not None and att.stop >= T:
            raise UsdHandsError(f"--attach {att.prop}={att.joint}:{att.start}-{att.stop}: the animation has frames "
                                f"0 to {T - 1}", path=path)
        for i in hits:
            by_prop[i] = att
    items = []
    if by_prop and world is None:
        world = clip.world_xforms()
    proximities = {} if proximities is None else proximities
    for i, (path, prop) in enumerate(props):
        att = by_prop.get(i)
        xf = None
        if att is not None:
            start, stop = (0, T - 1) if att.start is None else (att.start, att.stop)
            xf = attached_xforms(prop.xforms_at(clip.times), world[:, clip.skeleton.index(att.joint)], start, stop)
        items.append(mesh_collider(prop, clip.times, world=xf, proximity=proximities.get(i)))
        proximities[i] = items[-1].proximity
    if options.self_collision:
        body = body_collider(clip, handmap)
        if body is not None:
            items.append(body)
    return Colliders(items), attachments


def hand_meshes(asset, clip) -> list:
    """The meshes of ``asset`` skinned to ``clip``'s skeleton (with joint influences)."""
    index = next((i for i, sk in enumerate(asset.skeletons) if sk is clip.skeleton), None)
    if index is None:
        index = next((i for i, sk in enumerate(asset.skeletons)
                      if tuple(sk.joint_names) == tuple(clip.skeleton.joint_names)), None)
    return [m for m in asset.meshes if index is not None and m.skeleton_index == index
            and m.joint_indices is not None and m.joint_weights is not None]


def with_mesh_radii(config, clip, handmap, meshes):
    """``config`` with the finger capsule radii measured on ``meshes`` (the hands' skinned mesh), unless
    the configuration turns that off (``mesh_radii``); joints it names keep their radii."""
    from usdhands.algorithms.interaction.finger_geometry import mesh_radii

    if not config.mesh_radii or not meshes:
        return config
    measured = {}
    for hand in handmap.sides:
        measured.update(mesh_radii(clip.skeleton, hand, meshes, config))
    return config.with_mesh_radii(measured)


def corrected_for_props(options, path, clip, handmap, meshes=()):
    """``clip`` corrected against ``--props`` (``db build --props``): the clip and the report's dict.

    ``meshes``: the meshes of its file skinned to the clip's skeleton, whose vertices give the
    finger capsules' radii as they do for ``correct`` (:func:`hand_meshes`).
    """
    from usdhands.jobs.correction import correct_loaded

    fixed, report, _, _ = correct_loaded(clip, handmap, options, path, meshes)
    return fixed, report.to_dict()


def synthesis_interaction(options, clip, handmap, db, cfg, props, config, path=None, world=None):
    """The ``interaction`` factory for ``synthesize_clip`` (proximity cuts, collision term) and the
    colliders at the clip's own rate for the correction run on the result (``world``: the clip's
    world transforms ``(T, J, 4, 4)`` when the caller has them)."""
    from usdhands.algorithms.interaction.synthesis_terms import InteractionTerms
    from usdhands.algorithms.synthesis.database import same_rate
    from usdhands.algorithms.synthesis.finger_transfer import canonical_to_local, local_to_canonical

    proximities = {}  # each prop's tree, built once for both rates
    colliders, _ = build_colliders(options, clip, handmap, props, path=path, world=world, proximities=proximities)
    at_db = clip if same_rate(clip.fps, db.fps) else clip.resample(db.fps)
    db_colliders = colliders if at_db is clip else \
        build_colliders(options, at_db, handmap, props, path=path, proximities=proximities)[0]
    rest = clip.skeleton.rest_world_positions()
    if at_db is not clip or world is None:
        world = at_db.world_xforms()  # posed once for both hands

    def fingers(segment: int):
        a, b = int(db.segments[segment, 0]), int(db.segments[segment, 1])
        return db.full_curves(slice(a, b))

    def factory(side, hand, rig):
        wrist = rest[clip.skeleton.index(hand.wrist)]
        tips = rest[[clip.skeleton.index(j) for j in hand.finger_joints]]
        reach = 1.5 * float(np.linalg.norm(tips - wrist, axis=1).max(initial=0.0)) + 0.05 / clip.skeleton.meters_per_unit
        return InteractionTerms(at_db, hand, rig, lambda c: canonical_to_local(at_db.skeleton, rig, c),
                                lambda q: local_to_canonical(at_db.skeleton, rig, q), fingers, db_colliders,
                                weight=options.collision_weight, reach=reach,
                                min_frames=max(int(round(cfg.segmentation.min_segment_s * db.fps)), 1),
                                margin_mm=options.margin, config=config, world=world)

    return factory, colliders

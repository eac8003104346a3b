"""Reading UsdSkel skeletons, animations and skinned meshes into the model.

Everything goes through UsdSkel's queries: ``UsdSkel.Cache`` populated from every
SkelRoot, ``SkeletonQuery`` for topology and rest/bind poses, ``AnimQuery`` for the
joint-local components of the animation at each time, ``SkinningQuery`` for the
influences of each bound mesh. Skeletons outside any SkelRoot are read too (the cache
answers ``GetSkelQuery`` for them, with the animation their own
``skel:animationSource`` names).
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdShade, UsdSkel, Vt

from usdhands.errors import AssetReadError, InvalidAnimationError, JointMismatchError
from usdhands.formats.usd_common import (
    DEFAULT_WEIGHT_KEY,
    INTERPOLATION_KEY,
    KEY_TIMES_KEY,
    NODE_KEY,
    NODE_SCALE_KEY,
    SOURCE_MESH_KEY,
    SOURCE_NAME_KEY,
    SOURCE_NODE_KEY,
    SOURCE_SKELETON_KEY,
    all_close,
    bound_animation_path,
    fold_into_roots,
    fold_similarity_into_roots,
    matrices_to_numpy,
    open_stage_quietly,
    quiet_diagnostics,
    skeleton_tokens_and_names,
    skeleton_world_xforms,
    tf_error_reason,
    world_might_vary,
)
from usdhands.formats.usd_schema_data import read_finger_motion
from usdhands.formats.usd_materials import MaterialReader
from usdhands.model.asset import Asset, BlendShape, BlendShapeWeights, RootNode, SkinnedMesh
from usdhands.model.clip import Clip, clip_size_problem
from usdhands.model.rotations import transforms_kernel, xform_to_trs
from usdhands.model.skeleton import Skeleton

__all__ = ["read_usd", "read_stage", "read_skeleton", "frame_times"]

_PREDICATE = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
#: numpy/len() refusing a value that is not an array: "object of type 'Payload' has no len()"
_WRONG_VALUE = re.compile(r"object of type '(\w+)' has no len\(\)")
_log = logging.getLogger(__name__)


def read_usd(path: str | os.PathLike, *, fps: float | None = None) -> Asset:
    """Read every Skeleton, its animations and its skinned meshes.

    Parameters
    ----------
    path : path-like
        ``.usd``, ``.usda``, ``.usdc`` or ``.usdz``.
    fps : float, optional
        Sample the animations at this rate (USD interpolates between time samples);
        by default the rate of the time samples (``timeCodesPerSecond`` for one sample
        per time code).

    Returns
    -------
    Asset
        One Skeleton per Skeleton prim (joint names are the USD joint paths, or the
        original names the writer stored), one Clip per SkelAnimation (bound ones
        first; ``Clip.name`` is the prim path), one SkinnedMesh per skinned Mesh.

    Raises
    ------
    AssetReadError
        Missing or corrupt file, invalid joint topology.
    JointMismatchError
        An animation names joints its skeleton does not have, or an array's length
        does not match its joints.
    """
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"Expected fps > 0, got {fps}")
    path = Path(path)
    with quiet_diagnostics():  # one block for the open and the read
        stage = open_stage_quietly(path)
        try:
            return _read_stage(stage, path, fps)
        except Tf.ErrorException as e:  # a corrupt .usdc fails when its values are read (LZ4), after Open
            raise AssetReadError(f"cannot read as USD: {tf_error_reason(e, path)}", path=path) from None
        except UnicodeDecodeError as e:  # a token or name of a corrupt .usdc that is not UTF-8
            raise AssetReadError(f"cannot read as USD: a name or token is not UTF-8 ({e.reason})", path=path) from None
        except TypeError as e:  # an attribute holding a value of another type where arrays belong
            if "UnregisteredValue" in str(e):  # a type USD does not know (.usda fuzz)
                raise AssetReadError("cannot read as USD: an attribute holds a value of an unknown type",
                                     path=path) from None
            held = _WRONG_VALUE.match(str(e))
            if held is None:
                raise
            # a corrupt .usdc whose array attribute holds a Payload, a Specifier... (.usdc fuzz)
            raise AssetReadError(f"cannot read as USD: an attribute holds a {held.group(1)} where an array belongs",
                                 path=path) from None
        except ValueError as e:  # strings where numbers belong: a mesh's points or rotations typed string[]
            if not str(e).startswith("could not convert"):
                raise
            raise AssetReadError(f"cannot read as USD: an attribute holds values of another type than its schema's "
                                 f"({str(e)[:80]})", path=path) from None


def read_stage(stage: Usd.Stage, *, fps: float | None = None, path: str | os.PathLike | None = None) -> Asset:
    """Read an open stage as it composes now (every layer, the session layer, unsaved edits).

    As :func:`read_usd`; ``path`` names the stage in errors (default: the root layer's identifier).
    """
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"Expected fps > 0, got {fps}")
    path = Path(path if path is not None else stage.GetRootLayer().identifier)
    with quiet_diagnostics():
        return _read_stage(stage, path, fps)


#: Frame rates (and timeCodesPerSecond) read from USD: one frame in 1000 s up to 10000 per second.
MIN_RATE = 1e-3
MAX_RATE = 1e4
#: Most frames one animation is sampled at (a time sample at time code 1e12 asked for 7 TiB).
MAX_FRAMES = 1_000_000


def stage_units(stage: Usd.Stage, path: Path) -> tuple[float, float]:
    """``(timeCodesPerSecond, metersPerUnit)`` of a stage; AssetReadError when usdhands cannot use them."""
    tcps = float(stage.GetTimeCodesPerSecond())
    if not (MIN_RATE <= tcps <= MAX_RATE):  # also NaN; 0 divided by zero, 1e300 collapsed float32 key times
        raise AssetReadError(f"timeCodesPerSecond {tcps:g} is outside {MIN_RATE:g}..{MAX_RATE:g}", path=path)
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    if not (mpu > 0 and np.isfinite(mpu)):  # 0 raised ValueError from the Skeleton
        raise AssetReadError(f"metersPerUnit {mpu:g} is not a positive finite number", path=path)
    return tcps, mpu


def _read_stage(stage: Usd.Stage, path: Path, fps: float | None) -> Asset:
    tcps, mpu = stage_units(stage, path)
    up = str(UsdGeom.GetStageUpAxis(stage)).upper()
    up = up if up in ("Y", "Z") else "Y"
    cache = UsdSkel.Cache()
    roots = []
    skel_prims = []
    anim_prims = []
    mesh_prims = []
    others = {"Camera": 0, "light": 0}  # prims the model has no place for (counted in left_out)
    for prim in stage.Traverse(_PREDICATE):  # the one walk over the stage
        if prim.IsA(UsdSkel.Root):
            roots.append(UsdSkel.Root(prim))
            cache.Populate(roots[-1], _PREDICATE)
        elif prim.IsA(UsdSkel.Skeleton):
            skel_prims.append(prim)
        elif prim.IsA(UsdSkel.Animation):
            anim_prims.append(prim)
        elif prim.IsA(UsdGeom.Mesh):
            mesh_prims.append(prim)
        else:
            kind = str(prim.GetTypeName())
            if kind == "Camera":
                others["Camera"] += 1
            elif kind.endswith("Light"):
                others["light"] += 1

    skeletons: list[Skeleton] = []
    kept_prims: list[Usd.Prim] = []
    worlds: list[np.ndarray | None] = []
    tokens_of: list[list[str]] = []
    clips: list[Clip] = []
    used_anims: set[str] = set()
    index_of_skel: dict[str, int] = {}
    root_nodes: dict[int, tuple] = {}
    for prim in skel_prims:
        skel = UsdSkel.Skeleton(prim)
        query = cache.GetSkelQuery(skel)
        world = skeleton_world_xforms(prim)
        world = None if world is None else world[0]
        sk, tokens = read_skeleton(skel, query, path=path, meters_per_unit=mpu, up_axis=up, world=world)
        if sk is None:
            continue
        if world is not None:
            chain = _node_chain_above(prim, world)
            if chain:
                root_nodes[len(skeletons)] = chain
        index_of_skel[str(prim.GetPath())] = len(skeletons)
        skeletons.append(sk)
        kept_prims.append(prim)
        worlds.append(world)
        tokens_of.append(tokens)
        anim_query = query.GetAnimQuery() if query else None
        if not anim_query:
            anim_path = bound_animation_path(prim)
            anim_prim = stage.GetPrimAtPath(anim_path) if anim_path else None
            if anim_prim and anim_prim.IsA(UsdSkel.Animation):
                anim_query = cache.GetAnimQuery(UsdSkel.Animation(anim_prim))
        if anim_query:
            clips.append(_read_clip(anim_query, sk, tokens, tcps, fps, path, prim if world is not None else None, world))
            used_anims.add(str(anim_query.GetPrim().GetPath()))

    # animations bound to no skeleton: attach each to the skeleton it names or fits
    for prim in anim_prims:
        if str(prim.GetPath()) in used_anims:
            continue
        anim_query = cache.GetAnimQuery(UsdSkel.Animation(prim))
        if not anim_query:
            continue
        joints = [str(t) for t in anim_query.GetJointOrder()]
        target = prim.GetCustomDataByKey(SOURCE_SKELETON_KEY)
        k = index_of_skel.get(str(target)) if target is not None else None
        if k is None:
            k = next((i for i, toks in enumerate(tokens_of) if joints and set(joints) <= set(toks)), None)
        if k is None:
            continue  # animates no skeleton of this file
        clips.append(_read_clip(anim_query, skeletons[k], tokens_of[k], tcps, fps, path,
                                kept_prims[k] if worlds[k] is not None else None, worlds[k]))

    meshes: list[SkinnedMesh] = []
    materials = MaterialReader(path)
    read_prims: set[str] = set()
    for root in roots:
        for binding in cache.ComputeSkelBindings(root, _PREDICATE):
            k = index_of_skel.get(str(binding.GetSkeleton().GetPrim().GetPath()))
            if k is None:
                continue
            for sq in binding.GetSkinningTargets():
                if sq.GetPrim().IsA(UsdGeom.Mesh):
                    mesh = _read_mesh(sq, k, tokens_of[k], path, worlds[k], materials)
                    read_prims.add(mesh.name)
                    meshes.extend(_split_by_material_subsets(mesh, sq.GetPrim(), materials))
    if skeletons:  # meshes on no skeleton (props, static parts) where the file has a character
        for prim in mesh_prims:
            if str(prim.GetPath()) not in read_prims:
                mesh = _read_mesh(None, -1, [], path, None, materials, prim=prim)
                read_prims.add(mesh.name)
                meshes.extend(_split_by_material_subsets(mesh, prim, materials))
    left_out = _left_out(mesh_prims, meshes, read_prims, materials, others)
    for thing in left_out:
        _log.info("%s: not read: %s", path, thing)
    provenance, source_names, weights, interpolation, key_times = {}, {}, {}, {}, {}
    for m in meshes:
        prim = stage.GetPrimAtPath(m.name) if Sdf.Path.IsValidPathString(m.name) else None
        if not prim:
            continue  # a part of a mesh split by its material subsets
        original = prim.GetCustomDataByKey(SOURCE_NAME_KEY)
        if isinstance(original, str) and original:
            source_names[m.name] = original
    for clip in clips:
        prim = stage.GetPrimAtPath(clip.name)
        record = read_finger_motion(prim)
        if record is not None:
            provenance[clip.name] = record
        original = prim.GetCustomDataByKey(SOURCE_NAME_KEY)
        if isinstance(original, str) and original:
            source_names[clip.name] = original
        kind = prim.GetCustomDataByKey(INTERPOLATION_KEY)
        if kind in ("STEP", "CUBICSPLINE"):
            interpolation[clip.name] = kind
        keys = prim.GetCustomDataByKey(KEY_TIMES_KEY)
        if keys is not None and len(keys):
            keys = np.asarray(list(keys), dtype=np.float64)
            if np.isfinite(keys).all():
                key_times[clip.name] = keys
        w = _blend_shape_weights(cache.GetAnimQuery(UsdSkel.Animation(prim)), clip, tcps)
        if w is not None:
            weights[clip.name] = w
    root_nodes = {k: _with_motion(chain, [c for c in clips if c.skeleton is skeletons[k]], tcps)
                  for k, chain in root_nodes.items()}
    return Asset(path=str(path), skeletons=tuple(skeletons), clips=tuple(clips), meshes=tuple(meshes),
                 provenance=provenance, source_names=source_names, left_out=left_out,
                 materials=tuple(materials.materials), images=tuple(materials.images), blend_shape_weights=weights,
                 interpolation=interpolation, root_nodes=root_nodes, key_times=key_times)


def _node_chain_above(skel_prim: Usd.Prim, world: np.ndarray) -> tuple[tuple[Usd.Prim, RootNode], ...]:
    """The Xforms usdhands wrote for source nodes above a skeleton (customData ``usdhands:node``),
    top first, each with its :class:`RootNode` (no motion yet: :func:`_with_motion` samples it),
    when they alone make the Skeleton's ``world`` transform at the earliest time; else ``()``.

    A node's transforms are the source's: its scale times the ``usdhands:nodeScale`` the writer
    moved into the root joints. ``local`` is the earliest time's (what the rest fold used);
    an Xform that moves also gets its default value as ``rest``.
    """
    chain = []
    total = np.eye(4)
    p = skel_prim.GetParent()
    if p and p.IsA(UsdSkel.Root):
        p = p.GetParent()
    while p and not p.IsPseudoRoot() and p.GetCustomDataByKey(NODE_KEY):
        x = UsdGeom.Xformable(p)
        local = matrices_to_numpy([x.GetLocalTransformation(Usd.TimeCode.EarliestTime())])[0]
        total = local @ total
        moved = _moved_scale(p)
        rest = None
        if x.TransformMightBeTimeVarying() and all(op.GetAttr().Get(Usd.TimeCode.Default()) is not None
                                                   for op in x.GetOrderedXformOps()):
            rest = matrices_to_numpy([x.GetLocalTransformation(Usd.TimeCode.Default())])[0] @ moved
        name = p.GetCustomDataByKey(SOURCE_NAME_KEY)
        chain.append((p, RootNode(name if isinstance(name, str) and name else p.GetName(), local @ moved,
                                  rest=rest)))
        p = p.GetParent()
    if not chain:
        return ()
    chain.reverse()
    scale = max(1.0, float(np.abs(world).max()))
    return tuple(chain) if all_close(total, world, rtol=0, atol=1e-9 * scale) else ()


def _moved_scale(prim: Usd.Prim) -> np.ndarray:
    """(4, 4) the uniform scale the writer moved from ``prim`` into the root joints (customData
    ``usdhands:nodeScale``), the identity when there is none."""
    moved = prim.GetCustomDataByKey(NODE_SCALE_KEY)
    ok = isinstance(moved, float) and np.isfinite(moved) and moved > 0
    return np.diag([moved, moved, moved, 1.0]) if ok else np.eye(4)


def _with_motion(chain: tuple[tuple[Usd.Prim, RootNode], ...], clips: Sequence[Clip],
                 tcps: float) -> tuple[RootNode, ...]:
    """The chain's nodes, each that moves with its local transform at every frame of ``clips``
    (the clips of its skeleton: frame ``f`` at time code ``(start_time + f / fps) · tcps``)."""
    out = []
    for prim, node in chain:
        x = UsdGeom.Xformable(prim)
        if not x.TransformMightBeTimeVarying() or not clips:
            out.append(node)
            continue
        moved = _moved_scale(prim)
        motion = {}
        for c in clips:
            codes = (c.start_time + np.arange(c.num_frames) / c.fps) * tcps
            motion[c.name] = matrices_to_numpy([x.GetLocalTransformation(Usd.TimeCode(float(t))) for t in codes]) @ moved
        out.append(node._replace(motion=motion))
    return tuple(out)


def _blend_shape_weights(anim_query, clip: Clip, tcps: float) -> BlendShapeWeights | None:
    """The animation's ``blendShapeWeights`` at the clip's frames (None when it has none)."""
    if not anim_query:
        return None
    names = [str(t) for t in anim_query.GetBlendShapeOrder()]
    if not names:
        return None
    codes = clip.start_time * tcps + np.arange(clip.num_frames) * (tcps / clip.fps)
    out = np.zeros((clip.num_frames, len(names)))
    for f, c in enumerate(codes.tolist()):
        value = anim_query.ComputeBlendShapeWeights(Usd.TimeCode(round(c, 9)))
        if value is not None and len(value) == len(names):
            out[f] = np.asarray(value, dtype=np.float64)
    return BlendShapeWeights(tuple(names), out)


def _left_out(mesh_prims: list[Usd.Prim], meshes: list[SkinnedMesh], read: set[str],
              materials: MaterialReader, others: dict[str, int]) -> tuple[str, ...]:
    """What the stage holds that the model does not, one short phrase each (``mesh_prims``: the
    stage's Mesh prims, ``read``: those read; ``others``: its cameras and lights)."""
    counts = {"mesh": 0, "mesh_points": 0, "Material": len(materials.skipped), **others}
    for prim in mesh_prims:
        if str(prim.GetPath()) not in read:
            counts["mesh"] += 1
            pts = UsdGeom.Mesh(prim).GetPointsAttr().Get()
            counts["mesh_points"] += len(pts) if pts is not None else 0
    out = []
    if counts["mesh"]:
        done = sum(int(np.asarray(m.points).shape[0]) for m in meshes)
        out.append(f"{counts['mesh']} mesh(es) not bound to a skeleton ({counts['mesh_points']} vertices; "
                   f"{done} vertices read)")
    if materials.missing_images:
        out.append(f"{len(materials.missing_images)} texture file(s) not found "
                   f"({', '.join(sorted(materials.missing_images)[:3])})")
    for key, what in (("Material", "material(s) that are not UsdPreviewSurface"), ("Camera", "camera(s)"),
                      ("light", "light(s)")):
        if counts[key]:
            out.append(f"{counts[key]} {what}")
    return tuple(out)


def read_skeleton(skel: UsdSkel.Skeleton, query=None, *, path=None, meters_per_unit: float = 1.0,
                  up_axis: str = "Y", world: np.ndarray | None = None) -> tuple[Skeleton | None, list[str]]:
    """The model Skeleton of a Skeleton prim and its joint tokens (None for no joints).

    Rest transforms come from ``restTransforms``, or are derived from
    ``bindTransforms`` (``local = bind[parent]^-1 · bind[joint]``) where those are missing.

    Parameters
    ----------
    world : (4, 4) float, optional
        The Skeleton prim's local-to-world transform (column vectors), folded into the
        root joints' rest transforms and into every bind transform, so that the model
        skeleton is in stage (world) space. None leaves the joints in skeleton space.

    Raises
    ------
    AssetReadError
        Joint paths that do not form a valid topology (parents first).
    JointMismatchError
        ``restTransforms`` or ``bindTransforms`` with a length other than the joints'.
    """
    prim = skel.GetPrim()
    where = str(prim.GetPath())
    tokens, names = skeleton_tokens_and_names(skel, path)
    J = len(tokens)
    if J == 0:
        return None, []
    if query:
        topology = query.GetTopology()
    else:
        topology = UsdSkel.Topology(tokens)
    ok, reason = topology.Validate()
    if not ok:
        raise AssetReadError(f"invalid joint hierarchy: {' '.join(str(reason).split())}", path=path, location=where)
    parents = np.asarray(topology.GetParentIndices(), dtype=np.int64)
    if len(set(tokens)) != J:
        raise AssetReadError("repeated joint paths in 'joints'", path=path, location=where)

    bind = _matrices(skel.GetBindTransformsAttr(), "bindTransforms", path, where)
    bind = None if bind is None or len(bind) == 0 else bind
    if bind is not None and len(bind) != J:
        raise JointMismatchError(f"bindTransforms has {len(bind)} entries for {J} joints", path=path, location=where)
    bind_np = matrices_to_numpy(bind) if bind is not None else None
    rest = _matrices(skel.GetRestTransformsAttr(), "restTransforms", path, where)
    rest = None if rest is None or len(rest) == 0 else rest
    if rest is not None and len(rest) != J:
        raise JointMismatchError(f"restTransforms has {len(rest)} entries for {J} joints", path=path, location=where)
    authored_bind = bind_np
    if bind_np is not None and rest is None:  # checked before the rest is solved from it
        # all-zero binds passed here and failed as LinAlgError when convert inverted them
        _check_xforms(bind_np, names, "bindTransforms", path, where)
    if world is not None and bind_np is not None:
        bind_np = np.asarray(world, dtype=np.float64) @ bind_np
    if rest is not None:
        local = matrices_to_numpy(rest)
        if world is not None:
            local[parents < 0] = np.asarray(world, dtype=np.float64) @ local[parents < 0]
        # the authored binds and the rest in one pass of the whole-array test; only a failing pair goes
        # through the checks one by one, binds first, which name the joint (as before)
        if authored_bind is None or not _xforms_ok(np.concatenate([authored_bind, local])):
            if authored_bind is not None:
                _check_xforms(authored_bind, names, "bindTransforms", path, where)
            _check_xforms(local, names, "restTransforms", path, where)
    elif bind_np is not None:
        local = np.empty_like(bind_np)
        for j, p in enumerate(parents):
            local[j] = bind_np[j] if p < 0 else np.linalg.solve(bind_np[p], bind_np[j])
    else:
        raise JointMismatchError(f"neither restTransforms nor bindTransforms is authored for its {J} joints",
                                 path=path, location=where)
    if rest is None:
        _check_xforms(local, names, "bindTransforms", path, where)
    t, q, s = xform_to_trs(local)
    sk = Skeleton(names, parents, t, q, s, bind_np, meters_per_unit=meters_per_unit, up_axis=up_axis, name=where)
    return sk, tokens


def _matrices(attr: Usd.Attribute, name: str, path, where: str):
    """The ``matrix4d[]`` value of ``attr`` (None where unauthored), refused when it holds another type:
    a corrupt .usdc's restTransforms held strings (usdc fuzz: ValueError converting them)."""
    value = attr.Get()
    if value is not None and not isinstance(value, Vt.Matrix4dArray):
        kind = type(value[0]).__name__ if isinstance(value, (list, tuple)) and len(value) else type(value).__name__
        raise AssetReadError(f"{name} holds {kind} values, not matrix4d[]", path=path, location=where)
    return value


def _xforms_ok(m: np.ndarray) -> bool:
    """Whether :func:`_check_xforms` finds nothing wrong with ``m``, in its tests' order and numbers
    but on the whole array at once (the usual case: 9 NumPy calls instead of its ~25, half its time
    on a skeleton's joints); False sends ``m`` to the full check, which names the joint. The compiled
    twin (``model._transforms_compiled.xforms_ok``) answers where it is built and can say."""
    kernel = transforms_kernel()
    if kernel is not None:
        ok = kernel.xforms_ok(np.ascontiguousarray(m, dtype=np.float64))
        if ok is not None:
            return ok
    return _numpy_xforms_ok(m)


def _numpy_xforms_ok(m: np.ndarray) -> bool:
    """:func:`_xforms_ok` in NumPy: the reference of the compiled twin."""
    if not np.isfinite(m).all():
        return False
    with np.errstate(all="ignore"):
        scale = np.linalg.norm(m[:, :3, :3], axis=1)
        if not (np.isfinite(scale).all() and (scale > 1e-12).all()):
            return False
        r = m[:, :3, :3] / scale[:, None, :]
        return bool((np.abs(np.linalg.det(r)) >= 1e-6).all() and (np.abs(m[:, 3, :3]) <= 1e-6).all()
                    and (np.abs(m[:, 3, 3] - 1.0) <= 1e-6).all())


def _check_xforms(m: np.ndarray, names: list[str], attr: str, path, where: str) -> None:
    """Refuse non-finite or singular (zero-scale) joint transforms before they are decomposed.

    Parameters
    ----------
    m : (J, 4, 4) float64
        Joint transforms, column vectors.
    """
    if _xforms_ok(m):
        return
    m = np.where(np.isfinite(m), m, np.inf)
    with np.errstate(all="ignore"):
        scale = np.linalg.norm(m[:, :3, :3], axis=1)                  # (J, 3) column lengths
        finite = np.isfinite(m).all(axis=(1, 2)) & np.isfinite(scale).all(axis=1)
        ok_scale = finite & (scale > 1e-12).all(axis=1)
        r = np.where(ok_scale[:, None, None], m[:, :3, :3] / np.where(ok_scale[:, None], scale, 1.0)[:, None, :],
                     np.eye(3))
        singular = ~ok_scale | (np.abs(np.linalg.det(r)) < 1e-6)
        # USD's fourth column (our last row) must be 0 0 0 1: a 0 there (usda fuzz) made the matrix
        # singular past the 3x3 check, a LinAlgError when a child's rest was solved from its bind
        projective = finite & ((np.abs(m[:, 3, :3]).max(axis=1) > 1e-6) | (np.abs(m[:, 3, 3] - 1.0) > 1e-6))
    bad = np.flatnonzero(~finite | singular | projective)
    if len(bad):
        j = int(bad[0])
        what = ("is not finite (or overflows)" if not finite[j] else
                "is singular (a zero scale or collapsed axes)" if singular[j] else
                "is not an affine transform (its fourth column is not 0 0 0 1)")
        raise AssetReadError(f"{attr} of joint '{names[j]}' {what}", path=path, location=where)


def frame_times(samples: list[float], tcps: float, fps: float | None) -> tuple[np.ndarray, float]:
    """Time codes to sample and the frame rate they make.

    Parameters
    ----------
    samples : list of float
        The animation's time samples (time codes), sorted.
    tcps : float
        The stage's time codes per second.
    fps : float, optional
        Wanted rate; by default the rate of evenly spaced samples, else ``tcps``.

    Returns
    -------
    times : (T,) float
        Time codes.
    fps : float
    """
    samples = np.asarray(samples, dtype=np.float64)
    if len(samples) == 0:
        return np.zeros(0), float(fps or tcps)
    first, last = samples[0], samples[-1]
    if fps is None:
        if len(samples) == 1:
            return samples, tcps
        steps = np.diff(samples)
        if all_close(steps, steps[0], rtol=1e-6, atol=1e-9) and steps[0] < 1.0 + 1e-9:
            return samples, tcps / float(steps[0])
        fps = tcps
    step = tcps / float(fps)
    n = np.floor((last - first) / step + 1e-6) + 1
    if not n <= MAX_FRAMES:
        raise InvalidAnimationError(f"time samples from {first:g} to {last:g} make {n:.3g} frames at {fps:g} fps "
                                    f"(more than {MAX_FRAMES:,} are refused)")
    return first + np.arange(int(n)) * step, float(fps)


def _check_authored_rotations(prim: Usd.Prim, joints: list[str], path: Path, where: str) -> None:
    """Raise InvalidAnimationError for a zero-length or NaN quaternion among the authored rotations.

    Used where UsdSkel's query gives no values at all (an animation without
    translations), which would hide them, so the authored samples are checked directly.
    """
    attr = UsdSkel.Animation(prim).GetRotationsAttr()
    if not attr or not attr.HasAuthoredValue():
        return
    times = attr.GetTimeSamples() or [Usd.TimeCode.Default()]
    for k, t in enumerate(times):
        value = attr.Get(t)
        if value is None or len(value) == 0:
            continue
        q = np.asarray(value, dtype=np.float64)
        norms = np.linalg.norm(q, axis=-1)
        bad = ~np.isfinite(norms) | (norms < 1e-6)
        if bad.any():
            j = int(np.argmax(bad))
            name = joints[j] if j < len(joints) else str(j)
            what = "a zero-length quaternion" if np.isfinite(norms[j]) else "a NaN quaternion"
            at = "" if isinstance(t, Usd.TimeCode) else f" at time {t:g}"
            raise InvalidAnimationError(f"rotations hold {what} (joint {name!r}, frame {k}{at})",
                                        path=path, location=where)


def _read_clip(anim_query, sk: Skeleton, tokens: list[str], tcps: float, fps: float | None,
               path: Path, skel_prim: Usd.Prim | None = None, earliest: np.ndarray | None = None) -> Clip:
    """The Clip of an animation; with ``skel_prim``, its local-to-world transform at each
    frame is folded into the root joints (as :func:`read_skeleton` does for the rest);
    ``earliest``: that transform at the earliest time, as the skeleton was read with."""
    prim = anim_query.GetPrim()
    where = str(prim.GetPath())
    joints = [str(t) for t in anim_query.GetJointOrder()]
    index = {t: i for i, t in enumerate(tokens)}
    missing = [t for t in joints if t not in index]
    if missing:
        shown = ", ".join(repr(m) for m in missing[:8]) + (" ..." if len(missing) > 8 else "")
        raise JointMismatchError(
            f"animation names {len(missing)} joint(s) that skeleton {sk.name} does not have: {shown}",
            path=path, location=where)
    if len(set(joints)) != len(joints):
        raise JointMismatchError("animation 'joints' repeats joints", path=path, location=where)
    cols = np.array([index[t] for t in joints], dtype=np.int64)
    K = len(joints)
    samples = list(anim_query.GetJointTransformTimeSamples())
    try:
        times, rate = frame_times(samples, tcps, fps)
    except InvalidAnimationError as e:
        raise InvalidAnimationError(e.message, path=path, location=where) from None
    if not (MIN_RATE <= rate <= MAX_RATE):  # time samples a millionth of a code apart
        raise InvalidAnimationError(f"time samples give {rate:g} frames per second (outside {MIN_RATE:g}..{MAX_RATE:g})",
                                    path=path, location=str(anim_query.GetPrim().GetPath()))
    if len(times) == 0:  # values without time samples: one frame
        codes = [Usd.TimeCode.Default()]
        start = 0.0
    else:
        codes = times.tolist()  # plain floats: USD takes them as time codes (making 10,000 TimeCodes cost ~5 ms)
        start = float(times[0]) / tcps
    T = len(codes)
    J = sk.num_joints
    too_big = clip_size_problem(T, J, max(len(samples), 1) * K)  # each sample holds the K joints' values
    if too_big:  # before any array is allocated
        raise InvalidAnimationError(too_big, path=path, location=where)
    # gather in the animation's joint order, then scatter into the skeleton's
    r_k = np.empty((T, K, 4))
    t_k = np.empty((T, K, 3))
    try:  # every frame all three components, one value per joint: no per-frame checks
        s_k = _copy_components(anim_query, codes, K, (t_k, r_k))
        has = {"translations": True, "rotations": True, "scales": True}
    except (ValueError, TypeError):  # no values at some frame, or a wrong count: the checks say which
        s_k = np.empty((T, K, 3))
        has = {"translations": False, "rotations": False, "scales": False}
        for f, code in enumerate(codes):
            code = code if isinstance(code, Usd.TimeCode) else Usd.TimeCode(code)
            values = anim_query.ComputeJointLocalTransformComponents(code)
            if not values:
                continue
            for label, arr, dst in zip(("translations", "rotations", "scales"), values, (t_k, r_k, s_k)):
                n = len(arr)
                if n == 0:
                    if has[label]:
                        raise JointMismatchError(f"{label} is empty at time {code.GetValue()}", path=path,
                                                 location=where)
                    continue
                if n != K:
                    at = "" if code.IsDefault() else f" at time {code.GetValue():g}"
                    raise JointMismatchError(f"{label} has {n} values for {K} joints{at}", path=path, location=where)
                if f > 0 and not has[label]:
                    raise JointMismatchError(f"{label} is missing before time {code.GetValue():g}", path=path,
                                             location=where)
                has[label] = True
                dst[f] = np.asarray(arr)
    if not has["rotations"]:
        # the query answered nothing (no translations authored): check what is authored.
        # Otherwise it hands the authored quaternions over as they are, and
        # Clip.validate (in read_asset) reports NaN and zero-length ones.
        _check_authored_rotations(prim, joints, path, where)
    if len(times) == 0 and not any(has.values()):
        T = 0  # no value at all: an animation of zero frames (read_asset reports it)
    everyone = K == J and bool((cols == np.arange(J)).all())

    def full(label: str, values: np.ndarray, rest: np.ndarray) -> np.ndarray:
        """Skeleton-order (T, J, n): the animation's values, rest for joints it lacks."""
        if has[label] and everyone:
            kept = values if len(values) == T else values[:T]
            if kept.base is None:  # made here: the Clip keeps it without a copy
                kept.setflags(write=False)
            return kept
        out = np.empty((T, J, rest.shape[-1]))
        out[:] = rest
        if has[label]:
            out[:, cols] = values[:T]
        return out

    rot = full("rotations", r_k, sk.rest_rotations)
    tr = full("translations", t_k, sk.rest_translations)
    sc = full("scales", s_k, sk.rest_scales)
    if skel_prim is not None and T:
        folded = None
        if earliest is not None and (len(times) == 0 or not world_might_vary(skel_prim)):
            # one transform at every frame: as quaternions where it is a rotation and one scale (a
            # Z-up stage's; CesiumMan's fold 0.24 -> 0.05 ms), the same numbers within ~1e-15
            folded = fold_similarity_into_roots(sk.parents, earliest, tr, rot, sc)
        if folded is None:
            world = skeleton_world_xforms(skel_prim, None if len(times) == 0 else times, earliest)
            if world is not None:
                folded = fold_into_roots(sk.parents, world, tr, rot, sc)
        if folded is not None:
            tr, rot, sc = folded
    return Clip(sk, rate if len(times) else float(fps or tcps), rot, tr, sc, name=where, start_time=start)


#: Bytes of float32 rows a read stages before converting them to float64 (they stay in cache).
_STAGE_BYTES = 1 << 18


def _copy_components(anim_query, codes: list, K: int, out: tuple[np.ndarray, ...]) -> np.ndarray:
    """Translations and rotations of every frame into ``out`` ``((T, K, 3), (T, K, 4))`` float64, and
    the scales ``(T, K, 3)`` float64 (one row repeated, a broadcast with no array of T rows, for
    scales without time samples); ValueError when a frame lacks one or has another number of values
    than ``K``.

    The values ``anim_query.ComputeJointLocalTransformComponents`` gives (it reads the
    SkelAnimation's three attributes at the time), read through one ``Usd.AttributeQuery``
    per attribute: scales that have no time samples are read once (the same value at
    every frame). Each frame's arrays are copied as bytes into float32 rows (the numbers
    unchanged; a NumPy assignment from a Vt array parses its buffer's layout every time,
    about 2 us, a quarter of a read of 10,000 frames), a block of rows at a time, each block
    converted into ``out`` while it is in cache (no float32 copy of the whole clip). Time-sampled
    scales (half floats in USD) are copied into a half-float array and converted once.
    """
    anim = UsdSkel.Animation(anim_query.GetPrim())
    attrs = (anim.GetTranslationsAttr(), anim.GetRotationsAttr(), anim.GetScalesAttr())
    if not all(attrs):
        raise ValueError
    queries = [Usd.AttributeQuery(a) for a in attrs]
    tq, rq, sq = queries
    t_out, r_out = out
    T = len(codes)
    step = max(1, min(T, _STAGE_BYTES // max(28 * K, 1)))
    t_rows, r_rows = np.empty((step, K, 3), dtype=np.float32), np.empty((step, K, 4), dtype=np.float32)
    tv, rv = memoryview(t_rows).cast("B"), memoryview(r_rows).cast("B")
    ts, rs = 12 * K, 16 * K
    tshape, rshape = (K, 3), (K, 4)
    for f0 in range(0, T, step):  # translations and rotations: what a read of 10,000 frames spends most in
        block = codes[f0:f0 + step]
        for f, code in enumerate(block):
            tm, rm = memoryview(tq.Get(code)), memoryview(rq.Get(code))  # no value (None): TypeError
            if tm.shape == tshape and rm.shape == rshape and tm.format == "f" and rm.format == "f":
                tv[f * ts:(f + 1) * ts] = tm.cast("B")
                rv[f * rs:(f + 1) * rs] = rm.cast("B")
            else:
                if len(tm.obj) != K or len(rm.obj) != K:  # (one value would broadcast)
                    raise ValueError
                t_rows[f], r_rows[f] = tm.obj, rm.obj
        n = len(block)
        t_out[f0:f0 + n] = t_rows[:n]
        r_out[f0:f0 + n] = r_rows[:n]
    if not sq.ValueMightBeTimeVarying():  # scales without time samples: one value, at every frame
        row = np.zeros((K, 3))
        if T:
            value = sq.Get(codes[0])
            if value is None or len(value) != K:
                raise ValueError
            row = np.asarray(value).astype(np.float32).astype(np.float64)  # as float32 rows held them
        return np.broadcast_to(row, (T, K, 3))
    halves = np.empty((T, K, 3), dtype=np.float16)
    view, size = memoryview(halves).cast("B"), halves[0].nbytes if len(halves) else 0
    for f, code in enumerate(codes):
        value = sq.Get(code)
        if value is None or len(value) != K:
            raise ValueError
        v = memoryview(value)
        if v.format == "e" and v.shape == (K, 3):
            view[f * size:(f + 1) * size] = v.cast("B")
        else:
            halves[f] = value
    return halves.astype(np.float64)


def _flattened(primvar: UsdGeom.Primvar, n_points: int, counts: np.ndarray, where: str, path: Path
               ) -> tuple[np.ndarray, str] | None:
    """A primvar's values expanded to per-vertex (``"vertex"``) or per-corner (``"corner"``)."""
    if not primvar or not primvar.HasValue():
        return None
    value = primvar.ComputeFlattened(Usd.TimeCode.EarliestTime())
    if value is None:
        return None
    a = np.asarray(value, dtype=np.float64)
    if a.size == 0:
        return None
    interp = primvar.GetInterpolation()
    n_corners = int(counts.sum())
    if interp in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
        if len(a) != n_points:
            raise JointMismatchError(f"primvar {primvar.GetPrimvarName()} has {len(a)} values for {n_points} points",
                                     path=path, location=where)
        return a, "vertex"
    if interp == UsdGeom.Tokens.faceVarying:
        if len(a) != n_corners:
            raise JointMismatchError(f"primvar {primvar.GetPrimvarName()} has {len(a)} values for {n_corners} "
                                     "face corners", path=path, location=where)
        return a, "corner"
    if interp == UsdGeom.Tokens.uniform:
        if len(a) != len(counts):
            raise JointMismatchError(f"primvar {primvar.GetPrimvarName()} has {len(a)} values for {len(counts)} faces",
                                     path=path, location=where)
        return np.repeat(a, counts, axis=0), "corner"
    # constant
    return np.broadcast_to(a[:1], (n_points,) + a.shape[1:]).copy(), "vertex"


def _uv_primvar(api: UsdGeom.PrimvarsAPI) -> UsdGeom.Primvar | None:
    pv = api.GetPrimvar("st")
    if pv and pv.HasValue():
        return pv
    for pv in api.GetPrimvarsWithValues():
        tn = pv.GetTypeName()
        if tn.role == "TextureCoordinate" or str(tn) in ("texCoord2f[]", "texCoord2d[]", "texCoord2h[]"):
            return pv
    return None


#: Most influences per point (skel:jointIndices elementSize) read; rigs use 4 to 8.
MAX_INFLUENCES = 256


def _check_influences(prim: Usd.Prim, n_points: int, n_joints: int, path: Path, where: str) -> tuple | None:
    """Refuse joint influences UsdSkel should not be handed: sizes that disagree, indices out of range.

    A mutated .usdc mesh crashed the interpreter (segmentation fault) inside UsdSkel's
    influence computation; inconsistent ones were silently dropped (an unskinned mesh).

    Returns the checked ``(jointIndices, jointWeights)`` values, as ``UsdSkel.SkinningQuery.
    ComputeJointInfluences`` would give them (it flattens the two primvars and checks what this
    function checked), where neither primvar is indexed; None where nothing is authored or one
    is indexed (the caller asks the query).
    """
    binding = UsdSkel.BindingAPI(prim)
    ip, wp = binding.GetJointIndicesPrimvar(), binding.GetJointWeightsPrimvar()
    if not (ip and ip.HasAuthoredValue()) and not (wp and wp.HasAuthoredValue()):
        return None
    if not (ip and ip.HasAuthoredValue() and wp and wp.HasAuthoredValue()):
        raise JointMismatchError("skel:jointIndices and skel:jointWeights must both be authored", path=path,
                                 location=where)
    early = Usd.TimeCode.EarliestTime()
    indices, weights = ip.Get(early), wp.Get(early)
    if indices is None or weights is None:
        raise JointMismatchError("skel:jointIndices or skel:jointWeights has no readable value", path=path,
                                 location=where)
    k_i, k_w = ip.GetElementSize(), wp.GetElementSize()
    if k_i != k_w or not 1 <= k_i <= MAX_INFLUENCES:
        raise JointMismatchError(f"skel:jointIndices / jointWeights elementSize {k_i} / {k_w}: expected the same "
                                 f"size from 1 to {MAX_INFLUENCES}", path=path, location=where)
    interp_i, interp_w = ip.GetInterpolation(), wp.GetInterpolation()
    if interp_i != interp_w or interp_i not in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying,
                                                UsdGeom.Tokens.constant):
        raise JointMismatchError(f"skel:jointIndices / jointWeights interpolation {interp_i} / {interp_w}: expected "
                                 "both vertex or both constant", path=path, location=where)
    expected = k_i if interp_i == UsdGeom.Tokens.constant else k_i * n_points
    if len(indices) != expected or len(weights) != expected:
        raise JointMismatchError(f"skel:jointIndices / jointWeights have {len(indices)} / {len(weights)} values; "
                                 f"{interp_i} influences of size {k_i} need {expected}", path=path, location=where)
    idx = np.asarray(indices, dtype=np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= n_joints):
        raise JointMismatchError(f"skel:jointIndices outside 0..{n_joints - 1}", path=path, location=where)
    if not np.isfinite(np.asarray(weights, dtype=np.float64)).all():
        raise JointMismatchError("skel:jointWeights holds NaN or infinite weights", path=path, location=where)
    return None if ip.IsIndexed() or wp.IsIndexed() else (indices, weights)


def _read_mesh(sq, skel_index: int, tokens: list[str], path: Path, world: np.ndarray | None = None,
               materials: MaterialReader | None = None, prim: Usd.Prim | None = None) -> SkinnedMesh:
    """A Mesh bound to a skeleton (``sq``, its SkinningQuery), or with ``sq`` None a Mesh ``prim`` on
    no skeleton (``skel_index`` -1: no influences, ``geom_bind_xform`` its local-to-world transform)."""
    prim = sq.GetPrim() if sq is not None else prim
    where = str(prim.GetPath())
    mesh = UsdGeom.Mesh(prim)
    early = Usd.TimeCode.EarliestTime()
    points = np.asarray(mesh.GetPointsAttr().Get(early) or [], dtype=np.float64).reshape(-1, 3)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(early) or [], dtype=np.int64)
    fvi = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(early) or [], dtype=np.int64)
    V = len(points)
    if counts.sum() != len(fvi):
        raise JointMismatchError(f"faceVertexIndices has {len(fvi)} entries, faceVertexCounts sum to {counts.sum()}",
                                 path=path, location=where)
    if len(fvi) and (fvi.min() < 0 or fvi.max() >= V):
        raise JointMismatchError(f"faceVertexIndices outside 0..{V - 1}", path=path, location=where)

    joint_indices = joint_weights = None
    if sq is None:
        geom_bind = matrices_to_numpy([UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(early)])[0]
    else:
        # joint influences, in the skeleton's joint order
        # the values the check read where they are the query's (no second read of both primvars)
        idx, w = (_check_influences(prim, V, len(sq.GetJointOrder() or tokens), path, where)
                  or sq.ComputeJointInfluences(early) or (None, None))
        K = int(sq.GetNumInfluencesPerComponent())
        joint_indices = joint_weights = None
        if idx is not None and K > 0:
            idx = np.asarray(idx, dtype=np.int64)
            w = np.asarray(w, dtype=np.float64)
            if sq.IsRigidlyDeformed() or sq.GetInterpolation() == UsdGeom.Tokens.constant:
                idx = np.tile(idx[:K], (V, 1))
                w = np.tile(w[:K], (V, 1))
            if idx.size != V * K or w.size != V * K:
                raise JointMismatchError(f"skel:jointIndices/jointWeights have {idx.size}/{w.size} values for "
                                         f"{V} points x {K} influences", path=path, location=where)
            idx = idx.reshape(V, K)
            w = w.reshape(V, K)
            order = sq.GetJointOrder()
            if order:
                local = [str(t) for t in order]
                index = {t: i for i, t in enumerate(tokens)}
                missing = [t for t in local if t not in index]
                if missing:
                    raise JointMismatchError(f"skel:joints names joints the skeleton does not have: "
                                             f"{', '.join(repr(m) for m in missing[:8])}", path=path, location=where)
                remap = np.array([index[t] for t in local], dtype=np.int64)
                if len(idx) and (idx.min() < 0 or idx.max() >= len(remap)):
                    raise JointMismatchError(f"skel:jointIndices outside 0..{len(remap) - 1}", path=path, location=where)
                idx = remap[idx]
            elif len(idx) and (idx.min() < 0 or idx.max() >= len(tokens)):
                raise JointMismatchError(f"skel:jointIndices outside 0..{len(tokens) - 1}", path=path, location=where)
            joint_indices, joint_weights = idx, w
        gbt = sq.GetGeomBindTransform(early)
        geom_bind = matrices_to_numpy([gbt if gbt is not None else Gf.Matrix4d(1)])[0]
        if world is not None:  # the skeleton's local-to-world, folded into its joints and binds too
            geom_bind = world @ geom_bind

    api = UsdGeom.PrimvarsAPI(prim)
    normals = _flattened(api.GetPrimvar("normals"), V, counts, where, path)
    if normals is None and mesh.GetNormalsAttr().HasValue():
        n = np.asarray(mesh.GetNormalsAttr().Get(early), dtype=np.float64)
        interp = mesh.GetNormalsInterpolation()
        if interp == UsdGeom.Tokens.faceVarying and len(n) == len(fvi):
            normals = (n, "corner")
        elif interp == UsdGeom.Tokens.uniform and len(n) == len(counts):
            normals = (np.repeat(n, counts, axis=0), "corner")
        elif len(n) == V:
            normals = (n, "vertex")
    uvs = _flattened(_uv_primvar(api), V, counts, where, path)

    pts, face_idx = points, fvi
    n_out = None if normals is None else normals[0]
    uv_out = None if uvs is None else uvs[0][:, :2]
    if any(x is not None and x[1] == "corner" for x in (normals, uvs)):
        # split vertices where face corners disagree (seams), keeping the vertex order
        cols = [fvi[:, None].astype(np.float64)]
        for x in (normals, uvs):
            if x is not None:
                cols.append(x[0] if x[1] == "corner" else x[0][fvi])
        keys = np.hstack([c.reshape(len(fvi), -1) for c in cols])
        uniq, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        src = fvi[first]
        pts = points[src]
        face_idx = inverse.reshape(-1).astype(np.int64)
        if normals is not None:
            n_out = normals[0][first] if normals[1] == "corner" else normals[0][src]
        if uvs is not None:
            uv_out = (uvs[0][first] if uvs[1] == "corner" else uvs[0][src])[:, :2]
        if joint_indices is not None:
            joint_indices, joint_weights = joint_indices[src], joint_weights[src]
    else:
        src = None
    shapes = _read_blend_shapes(prim, V, path, where)
    if src is not None:
        shapes = tuple(dataclasses.replace(b, offsets=b.offsets[src], normal_offsets=None if b.normal_offsets is None
                                           else b.normal_offsets[src]) for b in shapes)
    group = prim.GetCustomDataByKey(SOURCE_MESH_KEY)
    node = prim.GetCustomDataByKey(SOURCE_NODE_KEY)
    return SkinnedMesh(
        name=where, points=pts, face_vertex_counts=counts, face_vertex_indices=face_idx,
        normals=n_out, uvs=uv_out, joint_indices=joint_indices, joint_weights=joint_weights,
        geom_bind_xform=geom_bind, skeleton_index=skel_index,
        group=group if isinstance(group, str) else None, node=node if isinstance(node, str) else None,
        material=materials.material_of(prim) if materials is not None else None, blend_shapes=shapes,
    )


def _split_by_material_subsets(mesh: SkinnedMesh, prim: Usd.Prim, materials: MaterialReader) -> list[SkinnedMesh]:
    """``mesh`` as one part per ``materialBind`` GeomSubset with a bound material (faces in no such
    subset form one more part with the mesh's own material), each holding the vertices its faces
    use; the mesh itself when it has no such subsets. The parts share ``group`` (the mesh), so a
    glTF writer makes them the primitives of one mesh."""
    subsets = [s for s in UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
               if s.GetElementTypeAttr().Get() == UsdGeom.Tokens.face]
    bound = [(s, materials.material_of(s.GetPrim())) for s in subsets]
    bound = [(s, m) for s, m in bound if m is not None]
    if not bound:
        return [mesh]
    counts = np.asarray(mesh.face_vertex_counts, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    owner = np.full(len(counts), -1, dtype=np.int64)
    for k, (s, _) in enumerate(bound):
        faces = np.asarray(s.GetIndicesAttr().Get() or [], dtype=np.int64)
        faces = faces[(faces >= 0) & (faces < len(counts))]
        owner[faces[owner[faces] < 0]] = k
    base = mesh.name.rsplit("/", 1)[-1]
    group = mesh.group or base
    parts = []
    for k in sorted(set(owner.tolist())):
        faces = np.flatnonzero(owner == k)
        if not len(faces):
            continue
        corner = np.concatenate([np.arange(starts[f], starts[f] + counts[f]) for f in faces])
        fvi = np.asarray(mesh.face_vertex_indices, dtype=np.int64)[corner]
        used, remap = np.unique(fvi, return_inverse=True)

        def take(a):
            return None if a is None else np.asarray(a)[used]

        name = f"{mesh.name}_{bound[k][0].GetPrim().GetName()}" if k >= 0 else mesh.name
        parts.append(dataclasses.replace(
            mesh, name=name, points=np.asarray(mesh.points)[used], face_vertex_counts=counts[faces],
            face_vertex_indices=remap.reshape(-1), normals=take(mesh.normals), uvs=take(mesh.uvs),
            joint_indices=take(mesh.joint_indices), joint_weights=take(mesh.joint_weights), group=group,
            material=bound[k][1] if k >= 0 else mesh.material,
            blend_shapes=tuple(dataclasses.replace(b, offsets=np.asarray(b.offsets)[used],
                                                   normal_offsets=take(b.normal_offsets)) for b in mesh.blend_shapes)))
    return parts


def _read_blend_shapes(prim: Usd.Prim, V: int, path: Path, where: str) -> tuple[BlendShape, ...]:
    """The mesh's ``skel:blendShapes`` with their ``BlendShape`` targets, offsets made dense (V, 3)."""
    binding = UsdSkel.BindingAPI(prim)
    attr = binding.GetBlendShapesAttr()
    names = [str(t) for t in (attr.Get() or [])] if attr else []
    if not names:
        return ()  # (the targets not forwarded for nothing: 0.08 ms of humanoid.usda's read)
    rel = binding.GetBlendShapeTargetsRel()
    targets = rel.GetForwardedTargets() if rel else []
    if len(targets) != len(names):
        raise JointMismatchError(f"skel:blendShapes has {len(names)} names for {len(targets)} "
                                 "skel:blendShapeTargets", path=path, location=where)
    out = []
    stage = prim.GetStage()
    for name, target in zip(names, targets):
        shape = UsdSkel.BlendShape(stage.GetPrimAtPath(target))
        if not shape:
            raise JointMismatchError(f"skel:blendShapeTargets names {target}, which is not a BlendShape",
                                     path=path, location=where)
        offsets = np.asarray(shape.GetOffsetsAttr().Get() or [], dtype=np.float64).reshape(-1, 3)
        normals = shape.GetNormalOffsetsAttr().Get() if shape.GetNormalOffsetsAttr().HasValue() else None
        normals = None if normals is None else np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        indices = shape.GetPointIndicesAttr().Get() if shape.GetPointIndicesAttr().HasValue() else None
        if indices is not None:
            idx = np.asarray(indices, dtype=np.int64)
            if len(idx) != len(offsets) or (len(idx) and (idx.min() < 0 or idx.max() >= V)):
                raise JointMismatchError(f"{target}: pointIndices do not match its offsets or the {V} points",
                                         path=path, location=where)
            dense = np.zeros((V, 3))
            dense[idx] = offsets
            offsets = dense
            if normals is not None and len(normals) == len(idx):
                dense = np.zeros((V, 3))
                dense[idx] = normals
                normals = dense
        if len(offsets) != V or (normals is not None and len(normals) != V):
            raise JointMismatchError(f"{target}: {len(offsets)} offsets for {V} points", path=path, location=where)
        bs_prim = shape.GetPrim()
        default = bs_prim.GetCustomDataByKey(DEFAULT_WEIGHT_KEY)
        original = bs_prim.GetCustomDataByKey(SOURCE_NAME_KEY)
        out.append(BlendShape(name=name, offsets=offsets, normal_offsets=normals,
                              default_weight=float(default) if isinstance(default, (int, float)) else 0.0,
                              source_name=original if isinstance(original, str) else None))
    return tuple(out)

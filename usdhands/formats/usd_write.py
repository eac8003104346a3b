"""Writing the model to USD: standalone stages, and a clip put back into its source.

Animation values are written as UsdSkel requires them: rotations ``quatf[]``,
translations ``float3[]``, scales ``half3[]``, one time sample per frame, moved in bulk
with ``Vt.*Array.FromNumpy``.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from pathlib import Path
from typing import Sequence

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, UsdUtils, Vt

from usdhands.errors import AssetReadError, JointMismatchError
from usdhands.formats.usd_common import (
    DEFAULT_WEIGHT_KEY,
    INTERPOLATION_KEY,
    KEY_TIMES_KEY,
    NODE_KEY,
    NODE_SCALE_KEY,
    SOURCE_JOINT_NAMES_KEY,
    SOURCE_MESH_KEY,
    SOURCE_NAME_KEY,
    SOURCE_NODE_KEY,
    SOURCE_SKELETON_KEY,
    bound_animation_path,
    fold_into_roots,
    joint_tokens_for,
    numpy_to_matrices,
    open_stage,
    quiet_diagnostics,
    skeleton_tokens_and_names,
    skeleton_world_xforms,
    unique_name,
    valid_identifier,
)
from usdhands.formats.usd_materials import bind_material, write_materials
from usdhands.formats.usd_read import read_skeleton
from usdhands.formats.usd_schema_data import write_finger_motion, write_hand_map
from usdhands.model.asset import Asset, SkinnedMesh
from usdhands.model.clip import Clip
from usdhands.model.handmap import HandMap
from usdhands.model.provenance import provenance_record
from usdhands.model.rotations import quat_angle_deg
from usdhands.model.skeleton import Skeleton

_log = logging.getLogger(__name__)

__all__ = ["write_usd", "write_usd_clip", "write_usd_hand_map", "author_clip", "author_animation", "frame_time_codes"]

# a joint absent from an animation's `joints` is added when the clip moves it this much
_ROT_TOL_DEG = 1e-3
_LIN_TOL = 1e-6


def _f32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)


def author_animation(anim: UsdSkel.Animation, clip: Clip, cols: Sequence[int], tokens: Sequence[str],
                     time_codes: np.ndarray, *, only_changed: bool = False) -> None:
    """Author ``joints``, rotations, translations and scales of ``anim`` from ``clip``.

    Existing values of the three transform attributes (default and every time sample)
    are replaced in the edit target. Rotations and translations get one time sample per
    frame; scales too, unless they are the same at every frame (then a default value).

    Parameters
    ----------
    anim : UsdSkel.Animation
    clip : Clip
    cols : sequence of int, length K
        The clip's joint index for each animation joint, in the animation's order.
    tokens : sequence of str, length K
        The animation's joint tokens.
    time_codes : (T,) float
        Time code of each frame.
    only_changed : bool
        Leave an attribute unauthored when the stage already resolves it to the new
        values at every frame (for sparse override layers).
    """
    cols = np.asarray(cols, dtype=np.int64)
    every = np.array_equal(cols, np.arange(clip.num_joints))  # the clip's joints in its order: no gather
    rot = _f32(clip.rotations if every else clip.rotations[:, cols])
    tr = _f32(clip.translations if every else clip.translations[:, cols])
    scales = clip.scales if every else clip.scales[:, cols]
    # the same half floats at every frame (a default value): the same numbers make the same half floats
    # (checked before converting 2 million of them); numbers that differ may still round alike
    constant_scales = bool(len(scales)) and (bool((scales == scales[:1]).all()) or bool(
        (scales.astype(np.float16) == scales[:1].astype(np.float16)).all()))
    sc = np.ascontiguousarray(scales[:1] if constant_scales else scales, dtype=np.float16)
    if constant_scales:
        sc = np.broadcast_to(sc, scales.shape)  # (T, K, 3), one row in memory
    joints_attr = anim.GetJointsAttr()
    old_tokens = [str(t) for t in (joints_attr.Get() or [])] if joints_attr else []
    same_joints = old_tokens == list(tokens)
    if not same_joints:
        anim.CreateJointsAttr().Set(Vt.TokenArray(list(tokens)))
    codes = time_codes.tolist()  # plain floats: USD takes them as time codes (10,000 TimeCodes: ~5 ms)
    jobs = [
        (anim.GetRotationsAttr, anim.CreateRotationsAttr, rot, Vt.QuatfArray.FromNumpy, False),
        (anim.GetTranslationsAttr, anim.CreateTranslationsAttr, tr, Vt.Vec3fArray.FromNumpy, False),
        (anim.GetScalesAttr, anim.CreateScalesAttr, sc, Vt.Vec3hArray.FromNumpy, constant_scales),
    ]
    if only_changed and same_joints:
        jobs = [j for j in jobs if not _resolves_to(j[0](), j[2], codes)]
    with Sdf.ChangeBlock():
        for _, create, values, convert, constant in jobs:
            attr = create()
            attr.Clear()
            if constant:
                attr.Set(convert(np.ascontiguousarray(values[0])))
                continue
            for f, tc in enumerate(codes):
                attr.Set(convert(values[f]), tc)


def _resolves_to(attr: Usd.Attribute, values: np.ndarray, codes: list) -> bool:
    """Whether ``attr`` already gives ``values`` (T, K, n) at exactly these time codes.

    The attribute's time samples must be the codes themselves (or, for one constant
    value, none), so a clip that is shorter or sampled at another rate is written.
    """
    if not attr or not attr.HasValue():
        return False
    samples = attr.GetTimeSamples()
    if samples or len(codes) != 1 or len(values) != 1:
        wanted = list(codes)
        if len(samples) != len(wanted) or not np.allclose(samples, wanted, rtol=0, atol=1e-9):
            if not (not samples and len(values) and (values == values[:1]).all()):
                return False
    tol = 1e-3 if values.dtype == np.float16 else 1e-6
    for f, tc in enumerate(codes):
        old = attr.Get(tc)
        if old is None or len(old) != values.shape[1]:
            return False
        old = np.asarray(old, dtype=np.float64)
        new = values[f].astype(np.float64)
        if values.shape[-1] == 4:  # q and -q are the same rotation
            diff = np.minimum(np.abs(old - new).max(axis=-1), np.abs(old + new).max(axis=-1))
            if (diff > tol).any():
                return False
        elif not np.allclose(old, new, rtol=tol, atol=tol):
            return False
    return True


def frame_time_codes(clip: Clip, tcps: float) -> np.ndarray:
    """Time code of each frame of ``clip`` on a stage of ``tcps`` time codes per second, ``(T,)``.

    Codes within 1e-6 of an integer are snapped to it (``start_time`` is a float in
    seconds, so ``0.4 * 30`` would otherwise give 11.999999999999998).
    """
    start = clip.start_time * float(tcps)
    if abs(start - round(start)) < 1e-6:
        start = float(round(start))
    codes = start + np.arange(clip.num_frames) * (float(tcps) / clip.fps)
    near = np.round(codes)
    return np.where(np.abs(codes - near) < 1e-6, near, codes)


def _set_time_range(layer: Sdf.Layer, codes: np.ndarray, *, extend: bool) -> None:
    if not len(codes):
        return
    lo, hi = float(codes.min()), float(codes.max())
    if extend and layer.HasStartTimeCode():
        lo = min(lo, layer.startTimeCode)
    if extend and layer.HasEndTimeCode():
        hi = max(hi, layer.endTimeCode)
    layer.startTimeCode = lo
    layer.endTimeCode = hi


# --------------------------------------------------------------------------- standalone
def write_usd(asset: Asset, path: str | os.PathLike, *, provenance: dict | None = None,
              final_path: str | os.PathLike | None = None) -> None:
    """Write ``asset`` as a standalone stage.

    Layout: ``/Root`` is the default prim, a SkelRoot holding the Skeleton, its
    SkelAnimations (the first bound through ``skel:animationSource``) and its skinned
    Meshes; with several skeletons ``/Root`` is an Xform with one SkelRoot per skeleton.
    The static root joints that no skin lists (``asset.non_skin_joints``: Mixamo's
    ``Character`` › ``Armature``) become ``Xform`` prims between ``/Root`` and the
    SkelRoot (see :func:`_node_chain`); bind transforms and ``geomBindTransform`` are then
    in the space below them.
    ``timeCodesPerSecond`` is the first clip's frame rate, ``metersPerUnit`` and
    ``upAxis`` the first skeleton's (other skeletons' clips are rescaled to its units).
    Joint names that are not USD identifiers are sanitised and the originals kept in
    the Skeleton prim's customData ``usdhands:sourceJointNames``, which the reader
    restores.

    Every SkelAnimation whose clip has a provenance record (``provenance``, else the
    asset's record for that clip) gets ``UsdHandsFingerMotionAPI``.

    Parameters
    ----------
    asset : Asset
    path : path-like
        ``.usd`` (binary), ``.usda`` or ``.usdc``.
    provenance : dict, optional
        How the finger motion of every clip was made
        (:func:`usdhands.model.provenance.provenance_record`).
    final_path : path-like, optional
        Where ``path`` will be renamed to (texture images are written beside it, see
        :mod:`usdhands.formats.usd_materials`); defaults to ``path``.
    """
    path = Path(path)
    final_path = Path(final_path) if final_path is not None else path
    records = [provenance_record(provenance) if provenance is not None else asset.provenance.get(c.name)
               for c in asset.clips]
    if not asset.skeletons:
        raise ValueError("Expected an asset with at least one skeleton, got none")
    owner = [_owner(asset.skeletons, c) for c in asset.clips]
    with quiet_diagnostics():
        stage = Usd.Stage.CreateInMemory()
        layer = stage.GetRootLayer()
        first = asset.skeletons[0]
        mpu = first.meters_per_unit
        UsdGeom.SetStageMetersPerUnit(stage, mpu)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if first.up_axis == "Z" else UsdGeom.Tokens.y)
        tcps = asset.clips[0].fps if asset.clips else 24.0
        stage.SetTimeCodesPerSecond(tcps)
        stage.SetFramesPerSecond(tcps)
        chains = [_node_chain(sk, asset.non_skin_joints.get(k, ()), [c for c, o in zip(asset.clips, owner) if o == k],
                              [m for m in asset.meshes if m.skeleton_index == k])
                  for k, sk in enumerate(asset.skeletons)]
        single = len(asset.skeletons) == 1 and not chains[0][0]
        root_path = Sdf.Path("/Root")
        if single:
            UsdSkel.Root.Define(stage, root_path)
        else:
            UsdGeom.Xform.Define(stage, root_path)
        stage.SetDefaultPrim(stage.GetPrimAtPath(root_path))
        material_paths = write_materials(stage, root_path.AppendChild("Materials"), asset.materials, asset.images,
                                         final_path, (asset.path,))
        all_codes = []
        used_roots: set[str] = set()
        for k, sk in enumerate(asset.skeletons):
            chain, keep = chains[k]
            lifted, unit = sk, 1.0
            if chain:
                sk, to_skel, unit = _without_chain(sk, chain, keep)
            if single:
                parent = root_path
            else:
                above = root_path
                own = [c for c, o in zip(asset.clips, owner) if o == k]
                for j in chain:
                    above = _define_node_xform(stage, above, lifted, j, used_roots if above == root_path else set(),
                                               unit if j == chain[-1] else 1.0,
                                               (own[0], frame_time_codes(own[0], tcps)) if len(own) == 1 else None)
                leaf = valid_identifier(sk.name.rsplit("/", 1)[-1]) + "Root"
                parent = above.AppendChild(unique_name(leaf, used_roots if above == root_path else set()))
                UsdSkel.Root.Define(stage, parent)
            used: set[str] = set()
            skel_path = parent.AppendChild(unique_name(valid_identifier(sk.name.rsplit("/", 1)[-1] or "Skeleton"),
                                                       used))
            skel = UsdSkel.Skeleton.Define(stage, skel_path)
            tokens = joint_tokens_for(sk.joint_names, sk.parents)
            skel.CreateJointsAttr().Set(Vt.TokenArray(tokens))
            if list(tokens) != list(sk.joint_names):
                skel.GetPrim().SetCustomDataByKey(SOURCE_JOINT_NAMES_KEY, Vt.StringArray(list(sk.joint_names)))
                # UsdSkel's own place for names joint paths cannot hold (mixamorig:Hips)
                skel.CreateJointNamesAttr().Set(Vt.TokenArray([n.rsplit("/", 1)[-1] for n in sk.joint_names]))
            skel.CreateRestTransformsAttr().Set(numpy_to_matrices(sk.rest_local_xforms()))
            bind = sk.bind_xforms if sk.bind_xforms is not None else sk.rest_world_xforms()
            skel.CreateBindTransformsAttr().Set(numpy_to_matrices(bind))
            binding = UsdSkel.BindingAPI.Apply(skel.GetPrim())
            bound = False
            for clip, o, record in zip(asset.clips, owner, records):
                if o != k:
                    continue
                if chain:
                    roots = (np.asarray(sk.parents) < 0)[None, :, None]
                    clip = clip.replace(skeleton=sk, rotations=clip.rotations[:, keep],
                                        translations=np.where(roots, unit, 1.0) * clip.translations[:, keep],
                                        scales=np.where(roots, unit, 1.0) * clip.scales[:, keep])
                if abs(clip.skeleton.meters_per_unit - mpu) > 1e-12:
                    clip = clip.with_meters_per_unit(mpu)
                original = asset.source_names.get(clip.name) or clip.name.rsplit("/", 1)[-1] or "Animation"
                anim_name = unique_name(valid_identifier(original), used)
                anim = UsdSkel.Animation.Define(stage, parent.AppendChild(anim_name))
                if anim_name != original:
                    anim.GetPrim().SetCustomDataByKey(SOURCE_NAME_KEY, original)
                codes = frame_time_codes(clip, tcps)
                all_codes.append(codes)
                author_animation(anim, clip, np.arange(sk.num_joints), tokens, codes)
                shapes = asset.blend_shape_weights.get(clip.name)
                if shapes is not None and len(shapes.names):
                    _author_blend_shape_weights(anim, shapes.names, shapes.weights, codes)
                kind = asset.interpolation.get(clip.name)
                if kind is not None:
                    anim.GetPrim().SetCustomDataByKey(INTERPOLATION_KEY, kind)
                keys = asset.key_times.get(clip.name)
                if keys is not None:
                    anim.GetPrim().SetCustomDataByKey(KEY_TIMES_KEY, Vt.DoubleArray([float(t) for t in keys]))
                if record is not None:
                    write_finger_motion(anim.GetPrim(), **provenance_record(record))
                if not bound:
                    binding.CreateAnimationSourceRel().SetTargets([anim.GetPath()])
                    bound = True
                else:
                    anim.GetPrim().SetCustomDataByKey(SOURCE_SKELETON_KEY, str(skel_path))
            for m in asset.meshes:
                if m.skeleton_index == k:
                    if chain:
                        m = _mesh_without_chain(m, lifted.num_joints, keep, to_skel)
                    _write_mesh(stage, parent, used, m, skel_path, sk.num_joints, asset.source_names.get(m.name),
                                material_paths, asset.materials)
        static = [m for m in asset.meshes if m.skeleton_index < 0]
        if static:
            used_top = {c.GetName() for c in stage.GetPrimAtPath(root_path).GetChildren()}
            for m in static:
                _write_mesh(stage, root_path, used_top, m, None, 0, asset.source_names.get(m.name), material_paths,
                            asset.materials)
        if all_codes:
            _set_time_range(layer, np.concatenate(all_codes), extend=False)
        layer.Export(str(path))


def _node_chain(sk: Skeleton, non_skin: Sequence[str], clips: Sequence[Clip],
                meshes: Sequence[SkinnedMesh]) -> tuple[list[int], np.ndarray]:
    """The joints to author as ``Xform`` prims above the SkelRoot, and the joints kept.

    The chain starts at the single root joint and goes down while each joint is one that
    no skin lists (``non_skin``), carries no mesh weight, and (but for the last) has one
    child, and either does not move in any of ``clips`` or ``clips`` is one clip: an Xform
    holds one set of time samples, which the skeleton's only animation can have (with
    several, a moving node stays a joint, which every SkelAnimation moves). Returns
    ``(chain, keep)``: joint indices root first (empty when nothing can be lifted) and the
    sorted indices of the other joints.
    """
    names = set(non_skin)
    parents = np.asarray(sk.parents)
    roots = np.flatnonzero(parents < 0)
    if not names or len(roots) != 1 or sk.joint_names[int(roots[0])] not in names:
        return [], np.arange(sk.num_joints, dtype=np.int64)  # no chain: the meshes' weights are not needed
    weighted = set()
    for m in meshes:
        if m.joint_indices is not None:
            w = np.asarray(m.joint_weights).reshape(np.asarray(m.joint_indices).shape)
            weighted.update(np.unique(np.asarray(m.joint_indices)[w != 0]).tolist())

    def still(j: int) -> bool:
        for c in clips:
            if (quat_angle_deg(c.rotations[:, j], sk.rest_rotations[j]).max(initial=0.0) > _ROT_TOL_DEG
                    or not np.allclose(c.translations[:, j], sk.rest_translations[j], rtol=1e-6, atol=_LIN_TOL)
                    or not np.allclose(c.scales[:, j], sk.rest_scales[j], rtol=1e-6, atol=_LIN_TOL)):
                return False
        return True

    chain: list[int] = []
    j = int(roots[0])
    while j >= 0 and sk.joint_names[j] in names and j not in weighted and (len(clips) == 1 or still(j)):
        chain.append(j)
        kids = np.flatnonzero(parents == j)
        j = int(kids[0]) if len(kids) == 1 else -1
    if len(chain) == sk.num_joints:
        chain = []
    keep = np.array([j for j in range(sk.num_joints) if j not in set(chain)], dtype=np.int64)
    return chain, keep


def _define_node_xform(stage: Usd.Stage, above: Sdf.Path, sk: Skeleton, j: int, used: set[str],
                       moved: float = 1.0, motion: tuple[Clip, np.ndarray] | None = None) -> Sdf.Path:
    """An ``Xform`` prim under ``above`` with joint ``j``'s rest transform (translate, orient, scale),
    its scale divided by ``moved``, the uniform scale :func:`_without_chain` moves into the root
    joints (recorded in customData ``usdhands:nodeScale`` when it is not 1).

    ``motion`` is the skeleton's only clip and its frames' time codes: each xformOp the clip
    changes also gets a time sample per frame (the rest stays the op's default value).
    """
    original = sk.joint_names[j].rsplit("/", 1)[-1]
    path = above.AppendChild(unique_name(valid_identifier(original), used))
    xf = UsdGeom.Xform.Define(stage, path)
    ops = (xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble), xf.AddOrientOp(UsdGeom.XformOp.PrecisionDouble),
           xf.AddScaleOp(UsdGeom.XformOp.PrecisionDouble))
    t, q, s = sk.rest_translations[j], sk.rest_rotations[j], sk.rest_scales[j] / moved
    ops[0].Set(Gf.Vec3d(*map(float, t)))
    ops[1].Set(Gf.Quatd(float(q[3]), *map(float, q[:3])))
    ops[2].Set(Gf.Vec3d(*map(float, s)))
    if motion is not None:
        clip, codes = motion
        rot = clip.rotations[:, j]
        moving = (not np.allclose(clip.translations[:, j], sk.rest_translations[j], rtol=1e-6, atol=_LIN_TOL),
                  quat_angle_deg(clip.rotations[:, j], sk.rest_rotations[j]).max(initial=0.0) > _ROT_TOL_DEG,
                  not np.allclose(clip.scales[:, j], sk.rest_scales[j], rtol=1e-6, atol=_LIN_TOL))
        for f, code in enumerate(codes):
            if moving[0]:
                ops[0].Set(Gf.Vec3d(*map(float, clip.translations[f, j])), float(code))
            if moving[1]:
                ops[1].Set(Gf.Quatd(float(rot[f, 3]), *map(float, rot[f, :3])), float(code))
            if moving[2]:
                ops[2].Set(Gf.Vec3d(*map(float, clip.scales[f, j] / moved)), float(code))
    if path.name != original:
        xf.GetPrim().SetCustomDataByKey(SOURCE_NAME_KEY, original)
    xf.GetPrim().SetCustomDataByKey(NODE_KEY, True)
    if moved != 1.0:
        xf.GetPrim().SetCustomDataByKey(NODE_SCALE_KEY, float(moved))
    return path


def _without_chain(sk: Skeleton, chain: list[int], keep: np.ndarray) -> tuple[Skeleton, np.ndarray, float]:
    """The skeleton of the ``keep`` joints in the space below ``chain``, the (4, 4) transform
    from the model's world space into that space, and the uniform scale ``unit`` moved from
    the chain's last node into the root joints.

    A skin bound at another scale than its nodes' rest (RobotExpressive: ``RobotArmature``
    scales by 100, the inverse bind matrices do not) has bind transforms of scale 1/100 in
    the space below the chain. UsdSkel evaluates that correctly, but Blender's USD importer
    makes its bones from the bind transforms without their scale and then poses them by
    ``inverse(local bind) · local`` against those unscaled bones: the robot came out 48 m
    away. When every bind has one uniform scale ``c`` there, the root joints take
    ``unit = 1/c`` (their rest and animated translations and scales) and the last node's
    Xform keeps its scale divided by ``unit``, so the binds have scale 1 and every world
    transform and skinned point is unchanged. ``unit`` is that node's own scale when it is
    within 1e-4 of ``1/c`` (the Xform's scale is then exactly 1), 1 when ``c`` is 1 or the
    binds' scales differ.
    """
    to_skel = np.linalg.inv(sk.rest_world_xforms()[chain[-1]])
    sub = sk.subset(list(keep))
    unit = 1.0
    if sub.bind_xforms is not None:
        lengths = np.linalg.norm((to_skel @ sub.bind_xforms)[:, :3, :3], axis=1)  # (J, 3) column lengths
        c = float(np.median(lengths))
        if c > 0 and abs(c - 1.0) > 1e-6 and np.allclose(lengths, c, rtol=1e-4):
            unit = 1.0 / c
            node_scale = sk.rest_scales[chain[-1]]
            if np.allclose(node_scale, node_scale[0], rtol=1e-9) and abs(node_scale[0] * c - 1.0) < 1e-4:
                unit = float(node_scale[0])
    to_skel = np.diag([unit, unit, unit, 1.0]) @ to_skel
    roots = (np.asarray(sub.parents) < 0)[:, None]
    bind = None if sub.bind_xforms is None else to_skel @ sub.bind_xforms
    return Skeleton(sub.joint_names, sub.parents, np.where(roots, unit, 1.0) * sub.rest_translations,
                    sub.rest_rotations, np.where(roots, unit, 1.0) * sub.rest_scales,
                    bind, sub.meters_per_unit, sub.up_axis, sub.name), to_skel, unit


def _mesh_without_chain(m: SkinnedMesh, num_joints: int, keep: np.ndarray, to_skel: np.ndarray) -> SkinnedMesh:
    """``m`` bound to the skeleton of :func:`_without_chain` (joint indices renumbered)."""
    remap = np.zeros(num_joints, dtype=np.int64)
    remap[keep] = np.arange(len(keep))
    idx = None if m.joint_indices is None else remap[np.asarray(m.joint_indices)]
    return dataclasses.replace(m, joint_indices=idx, geom_bind_xform=to_skel @ m.geom_bind_xform)


def _owner(skeletons: Sequence[Skeleton], clip: Clip) -> int:
    """Index of the skeleton a clip animates: the same object, else the same joint names."""
    for k, sk in enumerate(skeletons):
        if clip.skeleton is sk:
            return k
    for k, sk in enumerate(skeletons):
        if sk.joint_names == clip.skeleton.joint_names:
            return k
    raise ValueError(f"Expected clip {clip.name!r} to animate one of the asset's skeletons, "
                     f"got skeleton {clip.skeleton.name!r}")


def _author_blend_shape_weights(anim: UsdSkel.Animation, names: Sequence[str], weights: np.ndarray,
                                time_codes: np.ndarray) -> None:
    """``blendShapes`` and one ``blendShapeWeights`` sample per frame (``weights`` (T, B))."""
    anim.CreateBlendShapesAttr().Set(Vt.TokenArray(list(names)))
    attr = anim.CreateBlendShapeWeightsAttr()
    w = _f32(weights).reshape(len(time_codes), len(names))
    with Sdf.ChangeBlock():
        for f, tc in enumerate(time_codes.tolist()):
            attr.Set(Vt.FloatArray.FromNumpy(w[f]), Usd.TimeCode(tc))


def _write_blend_shapes(stage: Usd.Stage, mesh: UsdGeom.Mesh, binding: UsdSkel.BindingAPI, m: SkinnedMesh) -> None:
    """One ``BlendShape`` prim below the mesh per shape, bound through ``skel:blendShapes`` /
    ``skel:blendShapeTargets``."""
    used: set[str] = set()
    targets = []
    for shape in m.blend_shapes:
        path = mesh.GetPath().AppendChild(unique_name(valid_identifier(shape.name), used))
        bs = UsdSkel.BlendShape.Define(stage, path)
        bs.CreateOffsetsAttr().Set(Vt.Vec3fArray.FromNumpy(_f32(shape.offsets).reshape(-1, 3)))
        if shape.normal_offsets is not None:
            bs.CreateNormalOffsetsAttr().Set(Vt.Vec3fArray.FromNumpy(_f32(shape.normal_offsets).reshape(-1, 3)))
        if shape.default_weight:
            bs.GetPrim().SetCustomDataByKey(DEFAULT_WEIGHT_KEY, float(shape.default_weight))
        if shape.source_name:
            bs.GetPrim().SetCustomDataByKey(SOURCE_NAME_KEY, shape.source_name)
        targets.append(path)
    binding.CreateBlendShapesAttr().Set(Vt.TokenArray([s.name for s in m.blend_shapes]))
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)


def _ties_go_to_the_last_zero() -> bool:
    """Whether NumPy's ``min(axis=0)`` / ``max(axis=0)`` of ``(N, 3)`` floats whose bound is zero give
    the sign of the column's last zero (+0 and -0 compare equal: the order they are met in decides);
    probed on rows that hold both signs in several orders."""
    probe = np.zeros((20, 3), dtype=np.float32)
    probe[[0, 3, 9], 0] = -0.0
    probe[[1, 19], 1] = -0.0
    probe[[19], 2] = 1.0
    probe[[2, 18], 2] = -0.0
    last = np.signbit([probe[19, 0], probe[19, 1], probe[18, 2]])  # each column's last zero
    return bool((np.signbit(probe.min(axis=0)) == last).all() and (np.signbit((-probe).max(axis=0)) == ~last).all())


_LAST_ZERO = _ties_go_to_the_last_zero()


def _extent(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``pts.min(axis=0), pts.max(axis=0)`` of ``(N, 3)`` points, taken along each coordinate's own
    contiguous column: NumPy's reduction down the first axis of 3 columns ran a 3-element loop per
    row (CesiumMan's 3,273 points: 135 us for both against 6). A bound of zero gets the sign of its
    column's last zero, as NumPy's reduction gives it (+0 and -0 tie; :func:`_ties_go_to_the_last_zero`);
    non-finite bounds, or a NumPy that breaks ties otherwise, are taken as before."""
    columns = np.ascontiguousarray(pts.T)
    lo, hi = columns.min(axis=1), columns.max(axis=1)
    if not (_LAST_ZERO and np.isfinite(lo).all() and np.isfinite(hi).all()):
        return pts.min(axis=0), pts.max(axis=0)
    for bound in (lo, hi):
        for j in np.flatnonzero(bound == 0).tolist():
            column = columns[j]
            bound[j] = column[np.flatnonzero(column == 0)[-1]]
    return lo, hi


def _write_mesh(stage: Usd.Stage, parent: Sdf.Path, used: set[str], m: SkinnedMesh, skel_path: Sdf.Path | None,
                num_joints: int, source_name: str | None = None, material_paths: Sequence[Sdf.Path] = (),
                materials: Sequence = ()) -> None:
    original = source_name or m.name.rsplit("/", 1)[-1] or "Mesh"
    name = unique_name(valid_identifier(original), used)
    mesh = UsdGeom.Mesh.Define(stage, parent.AppendChild(name))
    if name != original:
        mesh.GetPrim().SetCustomDataByKey(SOURCE_NAME_KEY, original)
    if m.group is not None:
        mesh.GetPrim().SetCustomDataByKey(SOURCE_MESH_KEY, m.group)
    if m.node is not None:
        mesh.GetPrim().SetCustomDataByKey(SOURCE_NODE_KEY, m.node)
    if m.material is not None and 0 <= m.material < len(material_paths):
        bind_material(mesh.GetPrim(), material_paths[m.material])
        if materials[m.material].double_sided:
            mesh.CreateDoubleSidedAttr().Set(True)
    pts = _f32(m.points).reshape(-1, 3)
    mesh.CreatePointsAttr().Set(Vt.Vec3fArray.FromNumpy(pts))
    mesh.CreateFaceVertexCountsAttr().Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(m.face_vertex_counts,
                                                                                       dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr().Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(m.face_vertex_indices,
                                                                                        dtype=np.int32)))
    mesh.CreateSubdivisionSchemeAttr().Set(UsdGeom.Tokens.none)
    if len(pts):
        lo, hi = _extent(pts)
        mesh.CreateExtentAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))]))
    if m.normals is not None:
        mesh.CreateNormalsAttr().Set(Vt.Vec3fArray.FromNumpy(_f32(m.normals).reshape(-1, 3)))
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    if m.uvs is not None:
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                     UsdGeom.Tokens.vertex)
        st.Set(Vt.Vec2fArray.FromNumpy(_f32(m.uvs).reshape(-1, 2)))
    if skel_path is None:  # on no skeleton: placed by its own transform
        mesh.AddTransformOp().Set(numpy_to_matrices(np.asarray(m.geom_bind_xform)[None])[0])
        if m.blend_shapes:
            _log.warning("not written to USD: %d blend shape(s) of mesh %r, which is on no skeleton (UsdSkel "
                         "blend shapes need one)", len(m.blend_shapes), original)
        return
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel_path])
    if m.joint_indices is not None:
        idx = np.asarray(m.joint_indices).reshape(len(pts), -1)
        w = np.asarray(m.joint_weights, dtype=np.float64).reshape(len(pts), -1)
        K = idx.shape[1]
        if len(idx) and (idx.min() < 0 or idx.max() >= num_joints):
            raise ValueError(f"Expected joint indices in 0..{num_joints - 1} for mesh {m.name!r}, "
                             f"got {idx.min()}..{idx.max()}")
        binding.CreateJointIndicesPrimvar(False, K).Set(
            Vt.IntArray.FromNumpy(np.ascontiguousarray(idx, dtype=np.int32).reshape(-1)))
        binding.CreateJointWeightsPrimvar(False, K).Set(Vt.FloatArray.FromNumpy(_f32(w).reshape(-1)))
    binding.CreateGeomBindTransformAttr().Set(numpy_to_matrices(m.geom_bind_xform[None])[0])
    if m.blend_shapes:
        _write_blend_shapes(stage, mesh, binding, m)


# --------------------------------------------------------------------------- into a source
def write_usd_clip(source: str | os.PathLike, clip: Clip, path: str | os.PathLike, *,
                   final_path: str | os.PathLike | None = None, animation: str | None = None,
                   as_layer: bool = False, hand_map: HandMap | None = None,
                   finger_motion: dict | None = None) -> None:
    """Write ``source`` with ``clip``'s animation values put into one of its SkelAnimations.

    Which animation: ``animation`` (a prim path) if given, else the prim ``clip.name``
    names, else the one bound to the clip's skeleton (a new SkelAnimation, bound, when
    the skeleton has none). Joints the clip moves away from rest that the animation's
    ``joints`` lacks (fingers, typically) are appended to it.

    Parameters
    ----------
    source : path-like
        The USD file the clip was read from (never modified).
    clip : Clip
        Joint names must be the source skeleton's (as the reader gives them).
    path : path-like
        Where to write (``.usd``, ``.usda``, ``.usdc``).
    final_path : path-like, optional
        Where ``path`` will be renamed to; relative sublayer paths are computed from its
        folder. Defaults to ``path``.
    animation : str, optional
        Prim path (or unique prim name) of the SkelAnimation to replace.
    as_layer : bool
        False: a copy of the source with the animation replaced (meshes, materials
        and every other prim kept): the root layer as it is when it composes nothing
        from other files (variants, instancing and layout kept; relative asset paths
        re-anchored to the output's folder), else the flattened stage. True: a sparse layer that
        sublayers ``source`` and holds only ``over``s of the changed animation
        attributes (plus a new SkelAnimation where the skeleton had none).
    hand_map : HandMap, optional
        Recorded on the Skeleton prim with ``UsdHandsHandMapAPI`` (joint names as the
        clip's skeleton has them).
    finger_motion : dict, optional
        ``{"method": ..., "database": ..., "parameters": {...}}`` recorded on the
        SkelAnimation with ``UsdHandsFingerMotionAPI``
        (:func:`usdhands.formats.usd_schema_data.write_finger_motion`).

    Raises
    ------
    AssetReadError
        The source cannot be read, or holds no skeleton for the clip.
    JointMismatchError
        The clip has joints the skeleton lacks, or lacks joints the animation has.
    """
    source = Path(source)
    path = Path(path)
    final_path = Path(final_path) if final_path is not None else path
    with quiet_diagnostics():
        layer, stage = _output_stage(source, final_path, as_layer)
        codes, skel_prim, anim_prim = _put_clip(stage, clip, animation, source, only_changed=as_layer)
        if hand_map is not None:
            write_hand_map(skel_prim, hand_map)
        if finger_motion is not None:
            write_finger_motion(anim_prim, **provenance_record(finger_motion))
        _set_time_range(layer, codes, extend=True)
        _export_output(layer, source, path, final_path, as_layer)


def write_usd_hand_map(source: str | os.PathLike, skeleton: str, hand_map: HandMap, path: str | os.PathLike, *,
                       final_path: str | os.PathLike | None = None, as_layer: bool = False) -> None:
    """Write ``source`` with ``UsdHandsHandMapAPI`` authored on one Skeleton prim.

    Parameters
    ----------
    source : path-like
        A USD file (never modified).
    skeleton : str
        Prim path of the Skeleton (``Skeleton.name`` as :func:`read_usd` gives it).
    hand_map : HandMap
        Joint names as the reader gives them for that skeleton.
    path, final_path, as_layer
        As :func:`write_usd_clip`: a copy of the source, or a sparse layer sublayering it.

    Raises
    ------
    AssetReadError
        No Skeleton prim at ``skeleton``.
    """
    source = Path(source)
    path = Path(path)
    final_path = Path(final_path) if final_path is not None else path
    with quiet_diagnostics():
        layer, stage = _output_stage(source, final_path, as_layer)
        prim = stage.GetPrimAtPath(skeleton) if Sdf.Path.IsValidPathString(skeleton) else None
        if not prim or not prim.IsA(UsdSkel.Skeleton):
            raise AssetReadError(f"no Skeleton prim at {skeleton!r}", path=source)
        write_hand_map(prim, hand_map)
        _export_output(layer, source, path, final_path, as_layer)


def _output_stage(source: Path, final_path: Path, as_layer: bool) -> tuple[Sdf.Layer, Usd.Stage]:
    """The layer an edited copy of ``source`` is authored in, and a stage editing it.

    ``as_layer``: an anonymous layer sublayering the source (its stage metadata copied);
    else a copy of the source's root layer when it alone is the asset, or the
    flattened stage.
    """
    src_stage = open_stage(source)
    if as_layer:
        layer = Sdf.Layer.CreateAnonymous(".usda")
        src_root = src_stage.GetRootLayer()
        for key in ("timeCodesPerSecond", "framesPerSecond", "metersPerUnit", "upAxis", "defaultPrim",
                    "startTimeCode", "endTimeCode"):
            if src_root.pseudoRoot.HasInfo(key):
                layer.pseudoRoot.SetInfo(key, src_root.pseudoRoot.GetInfo(key))
        layer.subLayerPaths.append(os.path.abspath(source))
    else:
        layer = _copy_self_contained_root(src_stage, source, final_path.parent)
        if layer is None:
            layer = src_stage.Flatten()
    stage = Usd.Stage.Open(layer, Usd.Stage.LoadAll)
    stage.SetEditTarget(Usd.EditTarget(layer))
    return layer, stage


def _export_output(layer: Sdf.Layer, source: Path, path: Path, final_path: Path, as_layer: bool) -> None:
    """Save ``layer`` to ``path``; a layer's sublayer path becomes relative to ``final_path``'s folder."""
    if as_layer:
        rel = _relative_asset_path(source, final_path.parent)
        layer.subLayerPaths.clear()
        layer.subLayerPaths.append(rel)
    layer.Export(str(path))


def author_clip(stage: Usd.Stage, clip: Clip, *, animation: str | None = None, hand_map: HandMap | None = None,
                finger_motion: dict | None = None) -> tuple[Usd.Prim, Usd.Prim]:
    """Author ``clip``'s animation into an open stage's current edit target, sparsely.

    Only the attributes whose values change are authored (as ``over``s when the edit
    target is not where the prims are defined); joints the clip moves away from rest that
    the animation lacks are appended to its ``joints``. Nothing is saved. Which
    SkelAnimation, ``hand_map`` and ``finger_motion``: as :func:`write_usd_clip`.

    Returns
    -------
    (skeleton prim, SkelAnimation prim)
    """
    source = Path(stage.GetRootLayer().identifier)
    with quiet_diagnostics():
        _, skel_prim, anim_prim = _put_clip(stage, clip, animation, source, only_changed=True)
        if hand_map is not None:
            write_hand_map(skel_prim, hand_map)
        if finger_motion is not None:
            write_finger_motion(anim_prim, **provenance_record(finger_motion))
    return skel_prim, anim_prim


def _copy_self_contained_root(stage: Usd.Stage, source: Path, out_folder: Path) -> Sdf.Layer | None:
    """A copy of the root layer when it alone is the asset (no sublayers, references or
    payloads to other files, not inside a package), relative asset paths re-anchored to
    ``out_folder``; None otherwise."""
    root = stage.GetRootLayer()
    if root.subLayerPaths or root.GetCompositionAssetDependencies() or source.suffix.lower() == ".usdz":
        return None
    layer = Sdf.Layer.CreateAnonymous(source.suffix or ".usda")
    layer.TransferContent(root)
    src_dir = os.path.dirname(os.path.abspath(source))
    out_dir = os.path.abspath(out_folder)
    if src_dir != out_dir:
        def reanchor(asset_path: str) -> str:
            if not asset_path or os.path.isabs(asset_path) or "://" in asset_path or asset_path.startswith("@"):
                return asset_path
            package, bracket, inner = asset_path.partition("[")
            target = os.path.normpath(os.path.join(src_dir, package))
            explicit = package.startswith(("./", "../"))
            if not explicit and not os.path.exists(target):
                return asset_path  # a search path, not found beside the source: leave it to the resolver
            return _relative_asset_path(Path(target), Path(out_dir)) + bracket + inner

        UsdUtils.ModifyAssetPaths(layer, reanchor)
    return layer


def _relative_asset_path(target: Path, folder: Path) -> str:
    """``target`` relative to ``folder`` as a USD asset path (``./x.usd``, ``../a/x.usd``).

    Symbolic links are not resolved, so the path follows the folders as the user sees them.
    """
    target = Path(os.path.abspath(target))
    folder = Path(os.path.abspath(folder))
    try:
        rel = os.path.relpath(target, folder)
    except ValueError:  # another drive
        return target.as_posix()
    rel = Path(rel).as_posix()
    return rel if rel.startswith("../") else f"./{rel}"


def _find_skeleton(stage: Usd.Stage, clip: Clip, anim_path: Sdf.Path | None) -> Usd.Prim:
    skels = [p for p in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate))
             if p.IsA(UsdSkel.Skeleton)]
    by_path = {str(p.GetPath()): p for p in skels}
    if clip.skeleton.name in by_path:
        return by_path[clip.skeleton.name]
    if anim_path is not None:
        for p in skels:
            if bound_animation_path(p) == anim_path:
                return p
    names = set(clip.skeleton.joint_names)
    for p in skels:
        if names <= set(skeleton_tokens_and_names(UsdSkel.Skeleton(p))[1]):
            return p
    raise AssetReadError(f"no Skeleton for the clip's skeleton {clip.skeleton.name!r}")


def _differs_from_rest(clip: Clip, rest: Skeleton, j: int, rj: int) -> bool:
    if quat_angle_deg(clip.rotations[:, j], rest.rest_rotations[rj]).max(initial=0.0) > _ROT_TOL_DEG:
        return True
    scale = 1.0 + np.abs(rest.rest_translations[rj]).max()
    if np.abs(clip.translations[:, j] - rest.rest_translations[rj]).max(initial=0.0) > _LIN_TOL * scale:
        return True
    return bool(np.abs(clip.scales[:, j] - rest.rest_scales[rj]).max(initial=0.0) > _LIN_TOL)


def _put_clip(stage: Usd.Stage, clip: Clip, animation: str | None, source: Path, *,
              only_changed: bool = False) -> tuple[np.ndarray, Usd.Prim, Usd.Prim]:
    wanted = animation if animation is not None else clip.name
    anim_prim = None
    if isinstance(wanted, str) and wanted.startswith("/") and Sdf.Path.IsValidPathString(wanted):
        p = stage.GetPrimAtPath(wanted)
        if p and p.IsA(UsdSkel.Animation):
            anim_prim = p
        elif animation is not None:
            raise AssetReadError(f"no SkelAnimation at {animation}", path=source)
    elif animation is not None:
        named = [p for p in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate))
                 if p.IsA(UsdSkel.Animation) and p.GetName() == str(animation)]
        if len(named) != 1:
            what = "no" if not named else f"{len(named)}"
            raise AssetReadError(f"{what} SkelAnimation named {animation!r}; give its prim path", path=source)
        anim_prim = named[0]
    try:
        skel_prim = _find_skeleton(stage, clip, anim_prim.GetPath() if anim_prim else None)
    except AssetReadError as e:
        raise AssetReadError(e.message, path=source) from None
    skel = UsdSkel.Skeleton(skel_prim)
    tokens, names = skeleton_tokens_and_names(skel)
    usd_sk, _ = read_skeleton(skel, path=source)
    name_to_skel = {n: i for i, n in enumerate(names)}
    missing = [n for n in clip.skeleton.joint_names if n not in name_to_skel]
    if missing:
        raise JointMismatchError(f"the clip has {len(missing)} joint(s) that skeleton {skel_prim.GetPath()} lacks: "
                                 f"{', '.join(repr(m) for m in missing[:8])}", path=source)
    clip_index = {n: i for i, n in enumerate(clip.skeleton.joint_names)}
    if anim_prim is None:
        bound = bound_animation_path(skel_prim)
        p = stage.GetPrimAtPath(bound) if bound else None
        if p and p.IsA(UsdSkel.Animation):
            anim_prim = p
    if anim_prim is None:  # the skeleton has no animation: make one beside it and bind it
        parent = skel_prim.GetPath().GetParentPath()
        used = {c.GetName() for c in stage.GetPrimAtPath(parent).GetAllChildren()}
        anim_prim = UsdSkel.Animation.Define(stage, parent.AppendChild(unique_name("Animation", used))).GetPrim()
        UsdSkel.BindingAPI.Apply(skel_prim).CreateAnimationSourceRel().SetTargets([anim_prim.GetPath()])
        anim_tokens: list[str] = []
    else:
        anim_tokens = [str(t) for t in (UsdSkel.Animation(anim_prim).GetJointsAttr().Get() or [])]
    token_to_skel = {t: i for i, t in enumerate(tokens)}
    bad = [t for t in anim_tokens if t not in token_to_skel]
    if bad:
        raise JointMismatchError(f"animation names joint(s) that skeleton {skel_prim.GetPath()} does not have: "
                                 f"{', '.join(repr(b) for b in bad[:8])}", path=source, location=str(anim_prim.GetPath()))
    lacking = [names[token_to_skel[t]] for t in anim_tokens if names[token_to_skel[t]] not in clip_index]
    if lacking:
        raise JointMismatchError(f"the clip lacks {len(lacking)} joint(s) the animation has: "
                                 f"{', '.join(repr(m) for m in lacking[:8])}", path=source,
                                 location=str(anim_prim.GetPath()))
    tcps = float(stage.GetTimeCodesPerSecond())
    codes = frame_time_codes(clip, tcps)
    world = skeleton_world_xforms(skel_prim, codes)
    if world is not None and clip.num_frames:
        # the reader folds the Skeleton prim's local-to-world into the roots: unfold it
        t, q, sc = fold_into_roots(clip.skeleton.parents, np.linalg.inv(world), clip.translations, clip.rotations,
                                   clip.scales)
        clip = clip.replace(translations=t, rotations=q, scales=sc)
    new_tokens = list(anim_tokens)
    have = set(anim_tokens)
    for i, t in enumerate(tokens):
        if t in have or names[i] not in clip_index:
            continue
        if _differs_from_rest(clip, usd_sk, clip_index[names[i]], i):
            new_tokens.append(t)
    cols = [clip_index[names[token_to_skel[t]]] for t in new_tokens]
    author_animation(UsdSkel.Animation(anim_prim), clip, cols, new_tokens, codes, only_changed=only_changed)
    return codes, skel_prim, anim_prim

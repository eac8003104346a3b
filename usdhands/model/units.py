"""Changing an asset's units (metres per unit) and up axis.

Z-up to Y-up maps a point ``(x, y, z)`` to ``(x, z, -y)``: a rotation of -90° about
+X applied in front of every root joint (and of the bind and mesh transforms).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from usdhands.model.asset import Asset, SkinnedMesh
from usdhands.model.clip import Clip
from usdhands.model.rotations import quat_multiply
from usdhands.model.skeleton import Skeleton

__all__ = ["up_axis_xform", "skeleton_to", "clip_to", "asset_to"]

_S = np.sqrt(0.5)
# rotation taking Z-up coordinates to Y-up coordinates: -90° about X (xyzw)
_Z_TO_Y = np.array([-_S, 0.0, 0.0, _S])


def up_axis_xform(src: str, dst: str) -> np.ndarray:
    """The ``(4, 4)`` transform taking ``src``-up coordinates to ``dst``-up ones."""
    m = np.eye(4)
    if src == dst:
        return m
    if (src, dst) == ("Z", "Y"):
        m[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]
    elif (src, dst) == ("Y", "Z"):
        m[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    else:
        raise ValueError(f"Expected up axes 'Y' or 'Z', got {src!r} -> {dst!r}")
    return m


def _axis_quat(src: str, dst: str) -> np.ndarray:
    if src == dst:
        return np.array([0.0, 0.0, 0.0, 1.0])
    return _Z_TO_Y if (src, dst) == ("Z", "Y") else _Z_TO_Y * np.array([-1, -1, -1, 1.0])


def skeleton_to(sk: Skeleton, meters_per_unit: float | None = None, up_axis: str | None = None) -> Skeleton:
    """``sk`` expressed in other units and/or up axis (roots re-oriented)."""
    mpu = sk.meters_per_unit if meters_per_unit is None else float(meters_per_unit)
    up = sk.up_axis if up_axis is None else up_axis
    f = sk.meters_per_unit / mpu
    m = up_axis_xform(sk.up_axis, up)
    q = _axis_quat(sk.up_axis, up)
    roots = sk.parents < 0
    t = sk.rest_translations * f
    t[roots] = t[roots] @ m[:3, :3].T
    r = np.array(sk.rest_rotations)
    r[roots] = quat_multiply(q, r[roots])
    bind = None
    if sk.bind_xforms is not None:
        bind = np.array(sk.bind_xforms)
        bind[:, :3, 3] *= f
        bind = m @ bind
    return Skeleton(sk.joint_names, sk.parents, t, r, sk.rest_scales, bind, mpu, up, sk.name)


def clip_to(clip: Clip, skeleton: Skeleton) -> Clip:
    """``clip`` moved onto ``skeleton``, a :func:`skeleton_to` copy of its own skeleton."""
    src = clip.skeleton
    f = src.meters_per_unit / skeleton.meters_per_unit
    m = up_axis_xform(src.up_axis, skeleton.up_axis)
    q = _axis_quat(src.up_axis, skeleton.up_axis)
    roots = src.parents < 0
    t = clip.translations * f
    t[:, roots] = t[:, roots] @ m[:3, :3].T
    turned = quat_multiply(q, clip.rotations[:, roots])
    r = clip.rotations
    if not np.array_equal(turned.view(np.uint64), r[:, roots].view(np.uint64)):  # the same up axis: nothing turns
        r = np.array(r)
        r[:, roots] = turned
    for a in (r, t):  # made here and handed over: the clip keeps them without a copy
        a.setflags(write=False)
    return clip.replace(skeleton=skeleton, rotations=r, translations=t)


def _mesh_to(mesh: SkinnedMesh, src: Skeleton, dst: Skeleton) -> SkinnedMesh:
    f = src.meters_per_unit / dst.meters_per_unit
    m = up_axis_xform(src.up_axis, dst.up_axis)
    scale = np.diag([f, f, f, 1.0])
    return replace(mesh, geom_bind_xform=m @ scale @ np.asarray(mesh.geom_bind_xform))


def asset_to(asset: Asset, meters_per_unit: float | None = None, up_axis: str | None = None) -> Asset:
    """Every skeleton, clip and mesh of ``asset`` in other units and/or up axis."""
    new = {id(sk): skeleton_to(sk, meters_per_unit, up_axis) for sk in asset.skeletons}
    skeletons = tuple(new[id(sk)] for sk in asset.skeletons)
    clips = tuple(clip_to(c, new[id(c.skeleton)]) if id(c.skeleton) in new
                  else clip_to(c, skeleton_to(c.skeleton, meters_per_unit, up_axis)) for c in asset.clips)
    meshes = tuple(_mesh_to(m, asset.skeletons[max(m.skeleton_index, 0)], skeletons[max(m.skeleton_index, 0)])
                   for m in asset.meshes)  # a mesh on no skeleton (-1) is in the units of the first
    same = all(sk.meters_per_unit == new.meters_per_unit and sk.up_axis == new.up_axis
               for sk, new in zip(asset.skeletons, skeletons))
    # the nodes folded into the roots are in the old units: without them the roots still hold everything
    return replace(asset, skeletons=skeletons, clips=clips, meshes=meshes,
                   root_nodes=asset.root_nodes if same else {})

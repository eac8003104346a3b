"""glTF -> USD gives the conventional UsdSkel shape: scaled nodes above the skin's joints
(Mixamo's ``Character`` 0.1 > ``Armature`` 0.01) become ``Xform`` prims above the SkelRoot,
joints are the skin's, and the world joints and skinned mesh are where the glTF puts them."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pygltflib
import pytest
from pxr import Gf, Usd, UsdGeom, UsdSkel
from scipy.spatial.transform import Rotation

from tests.cli_helpers import run
from usdhands.jobs.conversion import convert
from usdhands.formats.io import read_asset, write_asset
from usdhands.formats.usd_common import matrices_to_numpy
from usdhands.formats.usd_validate import usd_compliance_errors
from usdhands.model.rotations import trs_to_xform

SKIN = ["mixamorig:Hips", "mixamorig:Spine", "mixamorig:LeftArm", "mixamorig:RightArm"]
FPS = 30.0
KEYS = 11


def _mixamo_like(path, nodes_move=False):
    """Character (scale 0.1, turned 30° about y) > Armature (scale 0.01, 90° about x) > Hips >
    Spine > LeftArm, RightArm; a skinned box per joint; Hips moves and Spine turns; with
    ``nodes_move``, the animation also moves Character (x 5 -> 7) and turns Armature (0 -> 45°
    about its z after its 90° about x).

    Returns (rest TRS per node, animated TRS per node per key, inverse bind matrices,
    mesh points, joint indices, weights) for the independent skinning below."""
    rx = Rotation.from_euler("x", 90, degrees=True).as_quat()
    ry = Rotation.from_euler("y", 30, degrees=True).as_quat()
    one = np.array([0.0, 0, 0, 1])
    nodes = [  # name, t, q, s, children
        ("Character", [5.0, 0, 0], ry, [0.1] * 3, [1]),
        ("Armature", [0.0, 0, 0], rx, [0.01] * 3, [2]),
        ("mixamorig:Hips", [0.0, 100, 0], one, [1.0] * 3, [3]),
        ("mixamorig:Spine", [0.0, 20, 0], one, [1.0] * 3, [4, 5]),
        ("mixamorig:LeftArm", [15.0, 30, 0], one, [1.0] * 3, []),
        ("mixamorig:RightArm", [-15.0, 30, 0], one, [1.0] * 3, []),
        ("Body", [0.0, 0, 0], one, [1.0] * 3, []),
    ]
    parents = [-1, 0, 1, 2, 3, 3, -1]
    rest = [trs_to_xform(np.array(t), np.array(q), np.array(s)) for _, t, q, s, _ in nodes]

    def world(locals_):
        out = []
        for i, m in enumerate(locals_):
            out.append(m if parents[i] < 0 else out[parents[i]] @ m)
        return out

    rest_world = world(rest)
    joints = [2, 3, 4, 5]
    ibm = np.array([np.linalg.inv(rest_world[n]) for n in joints])
    # a box of 8 points around each joint (in world space, the mesh's bind space)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64) * 0.004
    pts, ji, jw, tris = [], [], [], []
    faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
             [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    for k, n in enumerate(joints):
        base = len(pts)
        pts += list(rest_world[n][:3, 3] + corners)
        tris += [[base + a for a in f] for f in faces]
        other = (k + 1) % len(joints)
        ji += [[k, other, 0, 0]] * 8
        jw += [[0.75, 0.25, 0, 0]] * 8
    pts = np.array(pts, np.float32)
    ji = np.array(ji, np.uint16)
    jw = np.array(jw, np.float32)
    tris = np.array(tris, np.uint16).reshape(-1)
    times = np.arange(KEYS) / FPS
    hips_t = np.array([[0.0, 100 + 10 * np.sin(f / 3), 5.0 * f] for f in range(KEYS)])
    spine_q = Rotation.from_euler("z", np.linspace(0, 60, KEYS)[:, None], degrees=True).as_quat()
    char_t = np.c_[np.linspace(5, 7, KEYS), np.zeros(KEYS), np.zeros(KEYS)]
    arm_q = (Rotation.from_quat(rx) * Rotation.from_euler("z", np.linspace(0, 45, KEYS)[:, None], degrees=True)).as_quat()

    g = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"))
    data = bytearray()

    def accessor(arr, type_, comp=pygltflib.FLOAT, target=None, min_max=False):
        nonlocal data
        arr = np.ascontiguousarray(arr)
        data += b"\0" * (-len(data) % 4)
        raw = arr.tobytes()
        g.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(data), byteLength=len(raw), target=target))
        data += raw
        acc = pygltflib.Accessor(bufferView=len(g.bufferViews) - 1, componentType=comp, count=arr.shape[0], type=type_)
        if min_max:
            acc.min = arr.reshape(arr.shape[0], -1).min(0).tolist()
            acc.max = arr.reshape(arr.shape[0], -1).max(0).tolist()
        g.accessors.append(acc)
        return len(g.accessors) - 1

    for i, (name, t, q, s, kids) in enumerate(nodes):
        g.nodes.append(pygltflib.Node(name=name, translation=list(t), rotation=list(map(float, q)), scale=list(s),
                                      children=kids or None))
    g.nodes[6].mesh, g.nodes[6].skin = 0, 0
    attrs = pygltflib.Attributes(POSITION=accessor(pts, "VEC3", target=pygltflib.ARRAY_BUFFER, min_max=True),
                                 JOINTS_0=accessor(ji, "VEC4", pygltflib.UNSIGNED_SHORT, pygltflib.ARRAY_BUFFER),
                                 WEIGHTS_0=accessor(jw, "VEC4", target=pygltflib.ARRAY_BUFFER))
    g.meshes = [pygltflib.Mesh(name="Body", primitives=[pygltflib.Primitive(
        attributes=attrs, indices=accessor(tris, "SCALAR", pygltflib.UNSIGNED_SHORT, pygltflib.ELEMENT_ARRAY_BUFFER))])]
    g.skins = [pygltflib.Skin(name="Rig", joints=joints,
                              inverseBindMatrices=accessor(np.swapaxes(ibm, 1, 2).astype(np.float32).reshape(-1, 16),
                                                           "MAT4"))]
    tin = accessor(times.astype(np.float32), "SCALAR", min_max=True)
    smp = [pygltflib.AnimationSampler(input=tin, output=accessor(hips_t.astype(np.float32), "VEC3")),
           pygltflib.AnimationSampler(input=tin, output=accessor(spine_q.astype(np.float32), "VEC4"))]
    tgt = pygltflib.AnimationChannelTarget
    g.animations = [pygltflib.Animation(name="Take 001", samplers=smp, channels=[
        pygltflib.AnimationChannel(sampler=0, target=tgt(node=2, path="translation")),
        pygltflib.AnimationChannel(sampler=1, target=tgt(node=3, path="rotation"))])]
    if nodes_move:
        smp += [pygltflib.AnimationSampler(input=tin, output=accessor(char_t.astype(np.float32), "VEC3")),
                pygltflib.AnimationSampler(input=tin, output=accessor(arm_q.astype(np.float32), "VEC4"))]
        g.animations[0].channels += [pygltflib.AnimationChannel(sampler=2, target=tgt(node=0, path="translation")),
                                     pygltflib.AnimationChannel(sampler=3, target=tgt(node=1, path="rotation"))]
    g.scenes = [pygltflib.Scene(nodes=[0, 6])]
    g.scene = 0
    g.buffers = [pygltflib.Buffer(byteLength=len(data))]
    g.set_binary_blob(bytes(data))
    g.save_binary(str(path))

    # independent truth: world joints and skinned points per key, from the node TRS
    worlds, skinned = [], []
    for f in range(KEYS):
        local = list(rest)
        local[2] = trs_to_xform(hips_t[f].astype(np.float32).astype(np.float64), one, np.ones(3))
        local[3] = trs_to_xform(np.array(nodes[3][1]), spine_q[f].astype(np.float32).astype(np.float64), np.ones(3))
        if nodes_move:
            local[0] = trs_to_xform(char_t[f].astype(np.float32).astype(np.float64), ry, np.full(3, 0.1))
            local[1] = trs_to_xform(np.zeros(3), arm_q[f].astype(np.float32).astype(np.float64), np.full(3, 0.01))
        w = world(local)
        wj = np.array([w[n] for n in joints])
        worlds.append(wj[:, :3, 3])
        skin_m = wj @ ibm.astype(np.float32).astype(np.float64)
        p = np.c_[pts.astype(np.float64), np.ones(len(pts))]
        out = np.zeros((len(pts), 3))
        for c in range(2):
            out += jw[:, c:c + 1] * np.einsum("vij,vj->vi", skin_m[ji[:, c]], p)[:, :3]
        skinned.append(out)
    return np.array(worlds), np.array(skinned)


@pytest.mark.parametrize("nodes_move", [False, True])
def test_mixamo_like_gltf_converts_to_conventional_usdskel_shape(tmp_path, capsys, gltf_validator, nodes_move):
    """With ``nodes_move`` the animation also moves Character and turns Armature: they are still
    Xforms above the SkelRoot, their xformOps time-sampled (the skeleton's only animation), and
    come back as animated glTF nodes. (They used to stay joints, with bind transforms at scale
    0.001: Blender showed that character 6.6-53 m off; benchmarks/blender_check.py.)"""
    src = tmp_path / "char.glb"
    world_joints, skinned = _mixamo_like(src, nodes_move)
    usd = tmp_path / "char.usda"
    assert run(capsys, "convert", str(src), str(usd))[0] == 0
    assert usd_compliance_errors(usd) == []

    stage = Usd.Stage.Open(str(usd))
    skel_prim = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton))
    skel = UsdSkel.Skeleton(skel_prim)
    joint_leaves = [str(t).rsplit("/", 1)[-1] for t in skel.GetJointNamesAttr().Get() or skel.GetJointsAttr().Get()]
    assert joint_leaves == SKIN                       # no Character, no Armature
    bind = matrices_to_numpy(skel.GetBindTransformsAttr().Get())
    assert np.allclose(np.linalg.norm(bind[:, :3, :3], axis=1), 1.0, atol=1e-6)   # unit scale

    # the Xforms above the SkelRoot carry the 0.001 scale
    root = skel_prim.GetParent()
    assert root.IsA(UsdSkel.Root)
    above = matrices_to_numpy([UsdGeom.Xformable(root).ComputeLocalToWorldTransform(Usd.TimeCode.Default())])[0]
    assert np.allclose(np.linalg.norm(above[:3, :3], axis=0), 0.001, rtol=1e-6)
    names = [p.GetName() for p in (root.GetParent(), root.GetParent().GetParent())]
    assert names == ["Armature", "Character"]
    assert root.GetParent().IsA(UsdGeom.Xform) and root.GetParent().GetParent().IsA(UsdGeom.Xform)
    for p in (root.GetParent(), root.GetParent().GetParent()):
        assert UsdGeom.Xformable(p).TransformMightBeTimeVarying() == nodes_move

    # UsdSkel's own world joints equal the glTF's
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(root), Usd.TraverseInstanceProxies())
    query = cache.GetSkelQuery(skel)
    xf = UsdGeom.XformCache()
    for f in (0, 3, 7, 10):
        tc = Usd.TimeCode(f)
        xf.SetTime(tc)
        to_world = np.asarray(xf.GetLocalToWorldTransform(skel_prim), dtype=np.float64).T
        jw = matrices_to_numpy(query.ComputeJointWorldTransforms(xf))   # the prim's transform included
        local = matrices_to_numpy(query.ComputeJointSkelTransforms(tc))
        assert np.allclose(jw, to_world @ local, atol=1e-9)
        assert np.abs(jw[:, :3, 3] - world_joints[f]).max() * 100 < 1e-4   # cm (metres per unit 1)

    # UsdSkel's skinning of the mesh agrees with the glTF's
    mesh_prim = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    shutil.copy(usd, tmp_path / "bake.usda")     # baking edits the layer, which stays open for the convert below
    stage_bake = Usd.Stage.Open(str(tmp_path / "bake.usda"))
    assert UsdSkel.BakeSkinning(stage_bake.Traverse(), Gf.Interval(0, KEYS - 1))
    baked = UsdGeom.Mesh(stage_bake.GetPrimAtPath(mesh_prim.GetPath()))
    bcache = UsdGeom.XformCache()
    for f in (0, 5, 10):
        bcache.SetTime(Usd.TimeCode(f))
        m = np.asarray(bcache.GetLocalToWorldTransform(baked.GetPrim()), dtype=np.float64).T
        p = np.asarray(baked.GetPointsAttr().Get(Usd.TimeCode(f)), dtype=np.float64)
        p = (np.c_[p, np.ones(len(p))] @ m.T)[:, :3]
        lo, hi = p.min(0), p.max(0)
        assert np.abs(lo - skinned[f].min(0)).max() * 100 < 0.1
        assert np.abs(hi - skinned[f].max(0)).max() * 100 < 0.1

    # glTF -> USD -> glTF keeps the world joints
    back = tmp_path / "back.glb"
    assert run(capsys, "convert", str(usd), str(back))[0] == 0
    clip = read_asset(back).clips[0]
    names = [n.rsplit("/", 1)[-1] for n in clip.skeleton.joint_names]
    cols = [names.index(n) for n in SKIN]
    got = clip.world_positions()[:, cols]
    assert got.shape[0] == KEYS
    assert np.abs(got - world_joints).max() * 100 < 1e-4
    # ... and the source's node tree: Character > Armature > the skin's joints, the nodes' channels
    assert gltf_validator(back)[0]["numErrors"] == 0
    g = pygltflib.GLTF2().load(str(back))
    assert [g.nodes[n].name for n in g.skins[0].joints] == SKIN
    char = next(i for i, n in enumerate(g.nodes) if n.name == "Character")
    assert g.scenes[0].nodes[0] == char and [g.nodes[c].name for c in g.nodes[char].children] == ["Armature"]
    arm = g.nodes[char].children[0]
    assert [g.nodes[c].name for c in g.nodes[arm].children] == ["mixamorig:Hips"]
    targets = {(c.target.node, c.target.path) for c in g.animations[0].channels}
    assert ({(char, "translation"), (arm, "rotation")} <= targets) == nodes_move
    assert not {(char, "rotation"), (char, "scale"), (arm, "translation"), (arm, "scale")} & targets


def _gltf_scene_points(g: pygltflib.GLTF2, animation: str, t: float) -> dict[str, np.ndarray]:
    """Every mesh node's world points at time ``t`` (s) of ``animation``, straight from the glTF:
    node TRS with the animation's LINEAR/STEP samplers applied, world = product of locals down the
    node tree, skinned nodes by linear blend skinning with the skin's inverse bind matrices and
    the weights normalized (as three.js and Blender do).
    Returns node name -> (V, 3), the primitives stacked."""
    blob = g.binary_blob()

    def acc(i):
        a = g.accessors[i]
        bv = g.bufferViews[a.bufferView]
        n = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[a.type]
        dt = {pygltflib.FLOAT: np.float32, pygltflib.UNSIGNED_SHORT: np.uint16,
              pygltflib.UNSIGNED_BYTE: np.uint8}[a.componentType]
        raw = np.frombuffer(blob, dt, a.count * n, (bv.byteOffset or 0) + (a.byteOffset or 0))
        return raw.reshape(a.count, n).astype(np.float64)

    trs = {i: [np.array(n.translation or [0.0] * 3), np.array(n.rotation or [0.0, 0, 0, 1]),
               np.array(n.scale or [1.0] * 3)] for i, n in enumerate(g.nodes)}
    anim = next(a for a in g.animations if a.name == animation)
    for ch in anim.channels:
        if ch.target.path == "weights":        # morph weights: the bounding boxes hold without them
            continue
        s = anim.samplers[ch.sampler]
        times, values = acc(s.input)[:, 0], acc(s.output)
        k = int(np.clip(np.searchsorted(times, t), 1, len(times) - 1))
        u = 0.0 if s.interpolation == "STEP" else float(np.clip((t - times[k - 1]) / (times[k] - times[k - 1]), 0, 1))
        slot = ["translation", "rotation", "scale"].index(ch.target.path)
        if slot == 1:
            v = Rotation.from_quat(values[k - 1:k + 1])
            trs[ch.target.node][1] = (v[0] * Rotation.from_rotvec(u * (v[0].inv() * v[1]).as_rotvec())).as_quat()
        else:
            trs[ch.target.node][slot] = (1 - u) * values[k - 1] + u * values[k]
    parent = {c: i for i, n in enumerate(g.nodes) for c in (n.children or [])}
    world: dict[int, np.ndarray] = {}

    def world_of(i):
        if i not in world:
            local = trs_to_xform(*trs[i])
            world[i] = world_of(parent[i]) @ local if i in parent else local
        return world[i]

    out = {}
    for i, n in enumerate(g.nodes):
        if n.mesh is None:
            continue
        pts = []
        for prim in g.meshes[n.mesh].primitives:
            p = np.c_[acc(prim.attributes.POSITION), np.ones(g.accessors[prim.attributes.POSITION].count)]
            if n.skin is None:
                pts.append((p @ world_of(i).T)[:, :3])
                continue
            skin = g.skins[n.skin]
            ibm = np.swapaxes(acc(skin.inverseBindMatrices).reshape(-1, 4, 4), 1, 2)
            m = np.array([world_of(j) for j in skin.joints]) @ ibm
            ji, jw = acc(prim.attributes.JOINTS_0).astype(int), acc(prim.attributes.WEIGHTS_0)
            jw /= jw.sum(axis=1, keepdims=True)    # RobotExpressive's hands' weights sum to up to 1.75
            pts.append(sum(jw[:, c, None] * np.einsum("vij,vj->vi", m[ji[:, c]], p) for c in range(4))[:, :3])
        out[n.name] = np.concatenate(pts)
    return out


def test_robot_expressive_binds_at_unit_scale_and_every_mesh_where_the_gltf_puts_it(shared_assets, tmp_path):
    """RobotExpressive's skin is bound at 1/100 of the scale of the ``RobotArmature`` node above it
    (the node scales by 100, the inverse bind matrices do not). Blender's USD importer builds its
    bones from the bind transforms without their scale, so such binds put the robot 48 m off there:
    the writer moves the uniform scale from that Xform into the root joints, every bind transform
    has scale 1, and UsdSkel's BakeSkinning still puts each of the 19 meshes (skinned hands, rigid
    head, torso and limbs) where the glTF node tree does (0.01 cm). The reader gives the node its
    source scale back (customData ``usdhands:nodeScale``)."""
    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    usd = tmp_path / "robot.usda"
    convert(src, usd)
    assert usd_compliance_errors(usd) == []
    stage = Usd.Stage.Open(str(usd))
    skel_prim = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton))
    skel = UsdSkel.Skeleton(skel_prim)
    bind = matrices_to_numpy(skel.GetBindTransformsAttr().Get())
    np.testing.assert_allclose(np.linalg.norm(bind[:, :3, :3], axis=1), 1.0, atol=2e-5)   # float32 inverse binds
    armature = skel_prim.GetParent().GetParent()
    assert armature.GetName() == "RobotArmature" and armature.GetCustomDataByKey("usdhands:nodeScale") == 100.0
    assert read_asset(usd).root_nodes[0][-1][0] == "RobotArmature"
    np.testing.assert_allclose(np.linalg.norm(read_asset(usd).root_nodes[0][-1][1][:3, :3], axis=0), 100, rtol=1e-6)

    g = pygltflib.GLTF2().load(str(src))
    anim = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Animation) and p.GetName() == "Wave")
    UsdSkel.BindingAPI(skel_prim).GetAnimationSourceRel().SetTargets([anim.GetPath()])
    assert UsdSkel.BakeSkinning(stage.Traverse())
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    tcps = stage.GetTimeCodesPerSecond()
    for code in (0.0, 17.0, 40.0):
        truth = _gltf_scene_points(g, "Wave", code / tcps)
        got: dict[str, list] = {}
        for m in meshes:
            x = matrices_to_numpy([UsdGeom.Xformable(m).ComputeLocalToWorldTransform(code)])[0]
            p = np.asarray(UsdGeom.Mesh(m).GetPointsAttr().Get(code), dtype=np.float64)
            got.setdefault(m.GetCustomDataByKey("usdhands:sourceNode"), []).append(p @ x[:3, :3].T + x[:3, 3])
        assert sorted(got) == sorted(truth)
        for name, parts in got.items():
            p = np.concatenate(parts)
            assert p.shape == truth[name].shape
            assert np.abs(p.min(0) - truth[name].min(0)).max() * 100 < 0.01, (name, code)   # cm
            assert np.abs(p.max(0) - truth[name].max(0)).max() * 100 < 0.01, (name, code)


def test_nodes_that_move_in_one_of_several_animations_stay_joints(tmp_path):
    """An Xform holds one set of time samples, which would play under every SkelAnimation: with two
    animations, Character and Armature (moving in the first) stay joints, and each animation's world
    joints are still the glTF's."""
    src = tmp_path / "char.glb"
    world_joints, _ = _mixamo_like(src, nodes_move=True)
    asset = read_asset(src)
    (clip,) = asset.clips
    still = clip.replace(name="Still", rotations=np.broadcast_to(clip.skeleton.rest_rotations, clip.rotations.shape),
                         translations=np.broadcast_to(clip.skeleton.rest_translations, clip.translations.shape))
    usd = tmp_path / "two.usda"
    write_asset(dataclasses.replace(asset, clips=(clip, still)), usd)
    assert usd_compliance_errors(usd) == []
    stage = Usd.Stage.Open(str(usd))
    skel = UsdSkel.Skeleton(next(p for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton)))
    assert [str(t).rsplit("/", 1)[-1] for t in skel.GetJointsAttr().Get()][:2] == ["Character", "Armature"]
    assert not any(p.GetCustomDataByKey("usdhands:node") for p in stage.Traverse())
    back = read_asset(usd)
    names = [n.rsplit("/", 1)[-1] for n in back.clips[0].skeleton.joint_names]
    got = back.clips[0].world_positions()[:, [names.index(n) for n in SKIN]]
    assert np.abs(got - world_joints).max() * 100 < 1e-3   # cm: float3 translations, 0.001 scale below them
    np.testing.assert_allclose(back.clips[1].world_positions(), still.world_positions(), atol=1e-5)


@pytest.mark.parametrize("value", ["100", -100.0, float("nan"), 0.0])
def test_a_node_scale_that_is_no_positive_number_is_ignored(shared_assets, tmp_path, value):
    """``usdhands:nodeScale`` only says how the source split the scale between the Xform and the
    root joints: a value that is no positive finite number is ignored, and the joints are still
    where UsdSkel puts them (the Xform's own transform folded into the roots)."""
    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    usd = tmp_path / "robot.usda"
    convert(src, usd)
    good = read_asset(usd)
    stage = Usd.Stage.Open(str(usd))
    arm = next(p for p in stage.Traverse() if p.GetName() == "RobotArmature")
    arm.SetCustomDataByKey("usdhands:nodeScale", value)
    stage.GetRootLayer().Export(str(tmp_path / "edited.usda"))
    bad = read_asset(tmp_path / "edited.usda")
    np.testing.assert_allclose(np.linalg.norm(bad.root_nodes[0][0].local[:3, :3], axis=0), 1.0, rtol=1e-9)
    for a, b in zip(good.clips[:3], bad.clips[:3]):
        np.testing.assert_allclose(b.world_positions(), a.world_positions(), atol=1e-9)
    back = tmp_path / "back.glb"
    convert(tmp_path / "edited.usda", back)
    for a, b in zip(read_asset(src).clips[:3], read_asset(back).clips[:3]):   # glTF again: RobotArmature a joint
        np.testing.assert_allclose(b.world_positions(), a.world_positions(), atol=1e-5)

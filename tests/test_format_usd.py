"""USD reader and writers: stages built here with known content, round trips, real assets, bad input."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, UsdSkel, Vt

from usdhands.errors import AssetReadError, JointMismatchError, NoSkeletonError
from usdhands.formats.io import read_asset, read_clip, write_asset, write_clip
from usdhands.formats.usd import HANDLER
from usdhands.formats.usd_common import joint_tokens_for, matrices_to_numpy
from usdhands.formats.usd_validate import usd_compliance_errors
from usdhands.model.asset import Asset, SkinnedMesh
from usdhands.model.clip import Clip
from usdhands.model.rotations import quat_angle_deg, quat_slerp, trs_to_xform
from usdhands.model.skeleton import Skeleton

RNG = np.random.default_rng(7)

# skeleton order; the animation animates a permuted subset
SKEL_JOINTS = ["Hips", "Hips/Spine", "Hips/Spine/Hand", "Hips/Spine/Hand/Index1", "Hips/Leg"]
ANIM_JOINTS = ["Hips/Spine/Hand", "Hips", "Hips/Leg"]  # not Spine, not Index1


def random_quats(shape) -> np.ndarray:
    q = RNG.normal(size=tuple(shape) + (4,))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q[q[..., 3] < 0] *= -1
    return q


def gf_rows(m: np.ndarray) -> Vt.Matrix4dArray:
    """Column-vector (N,4,4) → Vt.Matrix4dArray (USD rows), written the naive way."""
    return Vt.Matrix4dArray([Gf.Matrix4d(*[float(x) for x in mat.T.reshape(-1)]) for mat in m])


class Built:
    """Ground truth of a stage built by :func:`build_stage`."""

    rest_t = np.array([[0, 1, 0], [0, 0.5, 0], [0.3, 0.2, 0], [0.1, 0, 0.02], [0.1, -0.5, 0]], dtype=float)
    rest_q = random_quats((5,))
    times = np.arange(10.0, 16.0)  # time codes 10..15
    anim_q = random_quats((6, 3))
    anim_t = RNG.normal(size=(6, 3, 3)).astype(np.float32).astype(float)


def build_stage(path: Path, *, skel_root: bool = True, rest: str = "rest", anim_joints=ANIM_JOINTS,
                n_rot=None, with_mesh: bool = True) -> Path:
    """A stage written with raw pxr calls: tcps 30, centimetres, Z up, a Material, a mesh."""
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(30)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    top = UsdSkel.Root.Define(stage, "/Char") if skel_root else UsdGeom.Xform.Define(stage, "/Char")
    stage.SetDefaultPrim(top.GetPrim())
    UsdShade.Material.Define(stage, "/Char/Looks/Skin")
    skel = UsdSkel.Skeleton.Define(stage, "/Char/Skel")
    skel.CreateJointsAttr().Set(SKEL_JOINTS)
    local = trs_to_xform(Built.rest_t, Built.rest_q)
    world = local.copy()
    for j, p in enumerate([-1, 0, 1, 2, 0]):
        if p >= 0:
            world[j] = world[p] @ local[j]
    if rest in ("rest", "both"):
        skel.CreateRestTransformsAttr().Set(gf_rows(local))
    skel.CreateBindTransformsAttr().Set(gf_rows(world))
    anim = UsdSkel.Animation.Define(stage, "/Char/Skel/Anim")
    anim.CreateJointsAttr().Set(list(anim_joints))
    K = len(anim_joints)
    for f, t in enumerate(Built.times):
        q = Built.anim_q[f, :K] if n_rot is None else Built.anim_q[f, :n_rot]
        anim.CreateRotationsAttr().Set(Vt.QuatfArray([Gf.Quatf(w, Gf.Vec3f(x, y, z)) for x, y, z, w in q]), t)
        anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*v) for v in Built.anim_t[f, :K]]), t)
    anim.CreateScalesAttr().Set(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)] * K))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    if with_mesh and skel_root:
        # a quad split into two triangles; st faceVarying with a seam at vertex 2
        mesh = UsdGeom.Mesh.Define(stage, "/Char/Body")
        mesh.CreatePointsAttr().Set([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)])
        mesh.CreateFaceVertexCountsAttr().Set([3, 3])
        mesh.CreateFaceVertexIndicesAttr().Set([0, 1, 2, 0, 2, 3])
        mesh.CreateExtentAttr().Set([(0, 0, 0), (1, 1, 0)])
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                     UsdGeom.Tokens.faceVarying)
        st.Set([(0, 0), (1, 0), (1, 1), (0, 0), (0.5, 0.5), (0, 1)])
        binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
        binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
        # mesh-local joint order: [Hand, Hips]; two influences per vertex
        binding.CreateJointsAttr().Set(["Hips/Spine/Hand", "Hips"])
        binding.CreateJointIndicesPrimvar(False, 2).Set([0, 1, 0, 1, 1, 0, 1, 0])
        binding.CreateJointWeightsPrimvar(False, 2).Set([0.75, 0.25, 0.5, 0.5, 1.0, 0.0, 0.6, 0.4])
        binding.CreateGeomBindTransformAttr().Set(Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 0, 2)))
    stage.GetRootLayer().Save()
    return path


def expected_clip_arrays(anim_joints=ANIM_JOINTS):
    """(T, J, 4) rotations and (T, J, 3) translations the reader must produce."""
    T = len(Built.times)
    rot = np.tile(Built.rest_q, (T, 1, 1))
    tr = np.tile(Built.rest_t, (T, 1, 1))
    for k, name in enumerate(anim_joints):
        j = SKEL_JOINTS.index(name)
        rot[:, j] = Built.anim_q[:, k]
        tr[:, j] = Built.anim_t[:, k]
    return rot, tr


def assert_rotations_close(a, b, deg=1e-4):
    assert quat_angle_deg(np.asarray(a), np.asarray(b)).max() < deg


def random_clip(T=40, J=65, names=None) -> Clip:
    parents = np.array([-1] + [int(RNG.integers(0, j)) for j in range(1, J)])
    names = names or [f"joint{j}" for j in range(J)]
    sk = Skeleton(names, parents, RNG.normal(size=(J, 3)) * 10, random_quats((J,)), meters_per_unit=0.01,
                  up_axis="Z", name="Rig")
    return Clip(sk, 30.0, random_quats((T, J)), RNG.normal(size=(T, J, 3)) * 10, name="Take 1", start_time=0.5)


# --------------------------------------------------------------------------- reading
def test_read_permuted_subset_animation(tmp_path):
    p = build_stage(tmp_path / "char.usda")
    asset = HANDLER.read(p)
    assert len(asset.skeletons) == 1 and len(asset.clips) == 1
    sk = asset.skeletons[0]
    assert sk.joint_names == tuple(SKEL_JOINTS)
    assert list(sk.parents) == [-1, 0, 1, 2, 0]
    assert sk.meters_per_unit == pytest.approx(0.01) and sk.up_axis == "Z"
    assert sk.name == "/Char/Skel"
    np.testing.assert_allclose(sk.rest_translations, Built.rest_t, atol=1e-12)
    assert_rotations_close(sk.rest_rotations, Built.rest_q, 1e-6)
    clip = asset.clips[0]
    assert clip.name == "/Char/Skel/Anim"
    assert clip.fps == 30.0 and clip.num_frames == 6
    assert clip.start_time == pytest.approx(10 / 30)
    rot, tr = expected_clip_arrays()
    assert_rotations_close(clip.rotations, rot, 1e-5)
    np.testing.assert_allclose(clip.translations, tr, atol=1e-6)
    # unanimated joints (Spine, Index1) sit at rest at every frame
    np.testing.assert_allclose(clip.translations[:, 1], np.tile(Built.rest_t[1], (6, 1)))


def test_rest_derived_from_bind_transforms(tmp_path):
    a = HANDLER.read(build_stage(tmp_path / "rest.usda"))
    b = HANDLER.read(build_stage(tmp_path / "bind.usda", rest="bind"))
    np.testing.assert_allclose(b.skeletons[0].rest_translations, a.skeletons[0].rest_translations, atol=1e-9)
    assert_rotations_close(b.skeletons[0].rest_rotations, a.skeletons[0].rest_rotations, 1e-6)
    np.testing.assert_allclose(b.skeletons[0].bind_xforms, a.skeletons[0].rest_world_xforms(), atol=1e-9)


def test_skeleton_outside_skelroot(tmp_path):
    p = build_stage(tmp_path / "free.usda", skel_root=False)
    asset = HANDLER.read(p)
    assert [c.name for c in asset.clips] == ["/Char/Skel/Anim"]
    rot, _ = expected_clip_arrays()
    assert_rotations_close(asset.clips[0].rotations, rot, 1e-5)
    assert asset.meshes == ()


def test_read_resamples_with_usd_interpolation(tmp_path):
    p = build_stage(tmp_path / "char.usda")
    clip = HANDLER.read(p, fps=60).clips[0]
    assert clip.fps == 60 and clip.num_frames == 11
    rot, tr = expected_clip_arrays()
    assert_rotations_close(clip.rotations[::2], rot, 1e-5)
    mid = quat_slerp(rot[:-1], rot[1:], 0.5)
    assert_rotations_close(clip.rotations[1::2], mid, 1e-3)
    np.testing.assert_allclose(clip.translations[1::2], (tr[:-1] + tr[1:]) / 2, atol=1e-6)


def test_read_skinned_mesh_maps_joints_and_splits_uv_seams(tmp_path):
    asset = HANDLER.read(build_stage(tmp_path / "char.usda"))
    (m,) = asset.meshes
    assert m.name == "/Char/Body" and m.skeleton_index == 0
    # vertex 0 carries two UVs ((0,0) twice → one), vertex 2 two ((1,1), (0.5,0.5)) → 5 vertices
    assert len(m.points) == 5
    hand, hips = SKEL_JOINTS.index("Hips/Spine/Hand"), SKEL_JOINTS.index("Hips")
    corner_points = m.points[m.face_vertex_indices]
    np.testing.assert_allclose(corner_points, np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 0, 0), (1, 1, 0),
                                                        (0, 1, 0)], dtype=float))
    np.testing.assert_allclose(m.uvs[m.face_vertex_indices], [(0, 0), (1, 0), (1, 1), (0, 0), (0.5, 0.5), (0, 1)])
    # influences of original vertex 2 (mesh-local [1, 0] = Hips, Hand) follow both of its copies
    for corner in (2, 4):
        v = m.face_vertex_indices[corner]
        assert list(m.joint_indices[v]) == [hips, hand]
        np.testing.assert_allclose(m.joint_weights[v], [1.0, 0.0])
    v0 = m.face_vertex_indices[0]
    assert list(m.joint_indices[v0]) == [hand, hips]
    np.testing.assert_allclose(m.geom_bind_xform[:3, 3], [0, 0, 2])


@pytest.mark.parametrize("influences", ["vertex", "constant", "indexed"])
def test_influences_read_once_are_the_skinning_querys(tmp_path, monkeypatch, influences):
    """The reader keeps the influences its check read (no second read through UsdSkel's query) where
    neither primvar is indexed: the mesh's arrays, bit for bit, are those of the query
    (``ComputeJointInfluences``, which flattens the primvars); an indexed primvar goes to the query."""
    from usdhands.formats import usd_read

    path = build_stage(tmp_path / "char.usda")
    stage = Usd.Stage.Open(str(path))
    binding = UsdSkel.BindingAPI(stage.GetPrimAtPath("/Char/Body"))
    if influences == "constant":  # the whole mesh on Hips: one element of two influences
        binding.CreateJointIndicesPrimvar(True, 2).Set([1, 0])
        binding.CreateJointWeightsPrimvar(True, 2).Set([0.9, 0.1])
    elif influences == "indexed":  # the weights' elements in another order, put back by their indices
        weights = binding.GetJointWeightsPrimvar()
        weights.Set([0.6, 0.4, 0.5, 0.5, 1.0, 0.0, 0.75, 0.25])
        weights.SetIndices(Vt.IntArray([3, 1, 2, 0]))
    stage.GetRootLayer().Save()
    calls = []
    real_check = usd_read._check_influences
    monkeypatch.setattr(usd_read, "_check_influences", lambda *a: calls.append(real_check(*a)) or calls[-1])
    (fast,) = HANDLER.read(path).meshes
    monkeypatch.setattr(usd_read, "_check_influences", lambda *a: real_check(*a) and None)
    (query,) = HANDLER.read(path).meshes
    assert (calls[0] is None) == (influences == "indexed")
    assert fast.joint_indices.tobytes() == query.joint_indices.tobytes()
    assert fast.joint_weights.tobytes() == query.joint_weights.tobytes()
    assert fast.joint_indices.shape == (5, 2)
    if influences == "constant":
        assert (fast.joint_indices == [SKEL_JOINTS.index("Hips"), SKEL_JOINTS.index("Hips/Spine/Hand")]).all()
    else:  # the weights of build_stage's vertices, flattened (original vertex 0 is the mesh's first)
        assert fast.joint_weights[fast.face_vertex_indices[0]].tolist() == [0.75, 0.25]


def test_cesium_man_influences_read_once_are_the_skinning_querys(shared_assets, monkeypatch):
    from usdhands.formats import usd_read

    path = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    (fast,) = read_asset(path).meshes
    real_check = usd_read._check_influences
    monkeypatch.setattr(usd_read, "_check_influences", lambda *a: real_check(*a) and None)
    (query,) = read_asset(path).meshes
    assert fast.joint_indices.shape == (3273, 4)
    assert fast.joint_indices.tobytes() == query.joint_indices.tobytes()
    assert fast.joint_weights.tobytes() == query.joint_weights.tobytes()


def test_cesium_man(shared_assets):
    path = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    asset = read_asset(path)
    (sk,) = asset.skeletons
    (clip,) = asset.clips
    assert sk.num_joints == 19 and clip.num_frames == 48 and clip.fps == 24.0
    assert clip.name == "/CesiumMan/Animations/skelAnim_0"
    assert sk.joint_names[0] == "Skeleton_torso_joint_1"
    (m,) = asset.meshes
    assert m.points.shape == (3273, 3) and m.joint_indices.shape == (3273, 4)
    np.testing.assert_allclose(m.joint_weights.sum(axis=1), 1.0, atol=1e-5)
    # below the roots, the clip's rotations are UsdSkel's own answer at each time code
    stage = Usd.Stage.Open(str(path))
    anim_query = UsdSkel.Cache().GetAnimQuery(UsdSkel.Animation(stage.GetPrimAtPath(clip.name)))
    order = [sk.joint_names.index(str(t)) for t in anim_query.GetJointOrder()]
    q = np.asarray(anim_query.ComputeJointLocalTransformComponents(Usd.TimeCode(20))[1])
    below = sk.parents[order] >= 0
    np.testing.assert_allclose(clip.rotations[19][order][below], q[below], atol=1e-7)
    # the Skeleton sits under a Z_UP Xform: its world transform is folded into the root,
    # so joint world transforms are UsdSkel's ComputeJointWorldTransforms at every frame
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetPrimAtPath("/CesiumMan/Geom/Z_UP/Armature/Skeleton_torso_joint_1_3"))
    cache.Populate(root, Usd.PrimDefaultPredicate)
    skel_query = cache.GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath(root.GetPath().AppendChild("Skeleton"))))
    ours = clip.world_xforms()
    for f in range(clip.num_frames):
        code = clip.start_time * 24.0 + f
        world = np.asarray(skel_query.ComputeJointWorldTransforms(UsdGeom.XformCache(code)), dtype=float)
        np.testing.assert_allclose(ours[f], world.transpose(0, 2, 1), atol=1e-5)
    head = sk.index("Skeleton_neck_joint_2")
    feet = clip.world_positions()[0, :, 1].min()
    assert clip.world_positions()[0, head, 1] - feet > 1.0  # +Y is up, as the stage says


def test_teapot_has_no_skeleton(shared_assets):
    path = shared_assets / "usd_teapot" / "UtahTeapot.usd"
    assert read_asset(path).skeletons == ()
    with pytest.raises(NoSkeletonError) as e:
        read_clip(path)
    assert str(e.value) == f"{path}: no skeleton in file"


# --------------------------------------------------------------------------- bad input
def test_missing_file(tmp_path):
    p = tmp_path / "nope.usda"
    with pytest.raises(AssetReadError) as e:
        read_asset(p)
    assert str(e.value) == f"{p}: no such file"
    with pytest.raises(AssetReadError) as e:
        HANDLER.read(p)
    assert str(e.value) == f"{p}: no such file"


def test_truncated_usdc(tmp_path):
    good = tmp_path / "good.usdc"
    stage = Usd.Stage.CreateNew(str(good))
    UsdSkel.Skeleton.Define(stage, "/Skel").CreateJointsAttr().Set(["a"])
    stage.Save()
    data = good.read_bytes()
    bad = tmp_path / "bad.usdc"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(AssetReadError) as e:
        read_asset(bad)
    msg = str(e.value)
    assert "\n" not in msg
    assert re.fullmatch(re.escape(f"{bad}: cannot read as USD: Sdf crate file corrupt, possibly truncated: ")
                        + r"table of contents at offset \d+ but file size is \d+", msg), msg


def test_corrupt_usda(tmp_path):
    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\ndef Xform "A" {\n  float x = \n')
    with pytest.raises(AssetReadError) as e:
        read_asset(bad)
    assert str(e.value).startswith(f"{bad}: cannot read as USD: line 3:3: Expected }}")
    assert "\n" not in str(e.value)


def test_animation_with_unknown_joints(tmp_path):
    p = build_stage(tmp_path / "bad.usda", anim_joints=["Hips", "Hips/Tail", "Hips/Spine/Wing"])
    with pytest.raises(JointMismatchError) as e:
        read_asset(p)
    assert str(e.value) == (f"{p}: /Char/Skel/Anim: animation names 2 joint(s) that skeleton /Char/Skel does not "
                            "have: 'Hips/Tail', 'Hips/Spine/Wing'")


def test_array_of_wrong_length(tmp_path):
    p = build_stage(tmp_path / "bad.usda", n_rot=2)
    with pytest.raises(JointMismatchError) as e:
        read_asset(p)
    assert str(e.value) == f"{p}: /Char/Skel/Anim: rotations has 2 values for 3 joints at time 10"


def test_rest_transforms_of_wrong_length(tmp_path):
    p = build_stage(tmp_path / "bad.usda")
    stage = Usd.Stage.Open(str(p))
    UsdSkel.Skeleton(stage.GetPrimAtPath("/Char/Skel")).GetRestTransformsAttr().Set(
        Vt.Matrix4dArray([Gf.Matrix4d(1)] * 3))
    stage.Save()
    with pytest.raises(JointMismatchError) as e:
        read_asset(p)
    assert str(e.value) == f"{p}: /Char/Skel: restTransforms has 3 entries for 5 joints"


# --------------------------------------------------------------------------- writing
def test_joint_tokens_sanitised_and_unique():
    names = ["mixamorig:Hips", "Palm1.L", "Palm1:L", "Hips/Spine"]
    tokens = joint_tokens_for(names, [-1, 0, 0, -1])
    assert tokens == ["mixamorig_Hips", "mixamorig_Hips/Palm1_L", "mixamorig_Hips/Palm1_L_2", "Hips_Spine"]
    # USD joint paths come back unchanged
    assert joint_tokens_for(SKEL_JOINTS, [-1, 0, 1, 2, 0]) == SKEL_JOINTS


@pytest.mark.parametrize("ext", [".usda", ".usdc", ".usd"])
def test_round_trip_random_clip(tmp_path, ext):
    names = [f"mixamorig:J{j}" if j % 3 else f"Palm{j}.L" for j in range(65)]
    clip = random_clip(names=names)
    out = write_asset(Asset("mem", (clip.skeleton,), (clip,)), tmp_path / f"rt{ext}")
    assert usd_compliance_errors(out) == []
    back = read_clip(out)
    assert back.skeleton.joint_names == tuple(names)
    assert list(back.skeleton.parents) == list(clip.skeleton.parents)
    assert back.fps == 30.0 and back.num_frames == clip.num_frames
    assert back.start_time == pytest.approx(0.5)
    assert back.skeleton.meters_per_unit == pytest.approx(0.01) and back.skeleton.up_axis == "Z"
    assert back.name == "/Root/Take_1"
    # quatf keeps ~1e-7; translations float32 relative 1e-6
    assert np.abs(np.abs((back.rotations * clip.rotations).sum(-1)) - 1).max() < 1e-6
    assert quat_angle_deg(back.rotations, clip.rotations).max() < 1e-4
    np.testing.assert_allclose(back.translations, clip.translations, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(back.skeleton.rest_translations, clip.skeleton.rest_translations, atol=1e-9)
    # UsdSkel's own queries read what was written: world transforms match the model's FK
    stage = Usd.Stage.Open(str(out))
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/Root/Rig"))
    query = UsdSkel.Cache().GetSkelQuery(skel)
    assert query.GetAnimQuery().GetPrim().GetPath() == "/Root/Take_1"
    code = Usd.TimeCode(0.5 * 30 + 7)
    skel_space = matrices_to_numpy(query.ComputeJointSkelTransforms(code))
    np.testing.assert_allclose(skel_space[:, :3, 3], clip.world_positions()[7], atol=1e-3)


def test_round_trip_mesh_and_several_skeletons(tmp_path):
    a, b = random_clip(T=5, J=4), random_clip(T=7, J=3)
    b = b.replace(skeleton=Skeleton(b.skeleton.joint_names, b.skeleton.parents, b.skeleton.rest_translations,
                                    b.skeleton.rest_rotations, meters_per_unit=0.01, up_axis="Z", name="Prop"),
                  name="Spin")
    a2 = a.replace(name="Take 2", rotations=random_quats((5, 4)))
    mesh = SkinnedMesh("Body.001", RNG.normal(size=(4, 3)), np.array([3, 3]), np.array([0, 1, 2, 0, 2, 3]),
                       normals=np.tile([0.0, 0, 1], (4, 1)), uvs=RNG.random((4, 2)),
                       joint_indices=np.array([[0, 1, 2, 3, 0]] * 4), joint_weights=np.full((4, 5), 0.2),
                       geom_bind_xform=trs_to_xform(np.array([1.0, 2, 3]), random_quats(())), skeleton_index=0)
    out = write_asset(Asset("mem", (a.skeleton, b.skeleton), (a, a2, b), (mesh,)), tmp_path / "two.usda")
    assert usd_compliance_errors(out) == []
    back = read_asset(out)
    assert [s.name for s in back.skeletons] == ["/Root/RigRoot/Rig", "/Root/PropRoot/Prop"]
    assert [c.name for c in back.clips] == ["/Root/RigRoot/Take_1", "/Root/PropRoot/Spin", "/Root/RigRoot/Take_2"]
    assert back.clips[2].skeleton is back.skeletons[0]
    assert_rotations_close(back.clips[2].rotations, a2.rotations)
    assert_rotations_close(back.clips[1].rotations, b.rotations)
    (m,) = back.meshes
    np.testing.assert_allclose(m.points, mesh.points, atol=1e-6)
    np.testing.assert_allclose(m.uvs, mesh.uvs, atol=1e-7)
    assert (m.joint_indices == mesh.joint_indices).all() and m.joint_indices.shape == (4, 5)
    np.testing.assert_allclose(m.geom_bind_xform, mesh.geom_bind_xform, atol=1e-12)
    stage = Usd.Stage.Open(str(out))
    mesh_prim = stage.GetPrimAtPath("/Root/RigRoot/Body_001")
    assert UsdSkel.BindingAPI(mesh_prim).GetJointIndicesPrimvar().GetElementSize() == 5


def _layer_bytes(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_write_clip_as_layer_is_sparse_and_composes(tmp_path):
    src = build_stage(tmp_path / "char.usda")
    before = _layer_bytes(src)
    clip = read_clip(src)
    finger = SKEL_JOINTS.index("Hips/Spine/Hand/Index1")
    new_rot = random_quats((clip.num_frames, 1))
    edited = clip.with_joint_rotations([finger], new_rot)
    (tmp_path / "out").mkdir()
    out = write_clip(src, edited, tmp_path / "out" / "fingers.usda", as_layer=True)
    assert _layer_bytes(src) == before
    layer = Sdf.Layer.FindOrOpen(str(out))
    assert list(layer.subLayerPaths) == ["../char.usda"]
    specs = []
    layer.Traverse(layer.pseudoRoot.path, specs.append)
    prim_specs = [layer.GetPrimAtPath(p) for p in specs if p.IsPrimPath()]
    assert prim_specs and all(s.specifier == Sdf.SpecifierOver for s in prim_specs)
    props = sorted(str(p) for p in specs if p.IsPropertyPath())
    # the finger joint was not animated: joints, rotations, translations change; scales stay ones
    assert props == ["/Char/Skel/Anim.joints", "/Char/Skel/Anim.rotations", "/Char/Skel/Anim.scales",
                     "/Char/Skel/Anim.translations"]
    assert layer.timeCodesPerSecond == 30 and layer.GetPrimAtPath("/Char/Looks") is None
    stage = Usd.Stage.Open(str(out))
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/Char/Skel/Anim"))
    assert list(anim.GetJointsAttr().Get()) == ANIM_JOINTS + ["Hips/Spine/Hand/Index1"]
    back = read_clip(out)
    assert_rotations_close(back.rotations[:, finger], new_rot[:, 0])
    assert_rotations_close(back.rotations, edited.rotations)
    np.testing.assert_allclose(back.translations, edited.translations, atol=1e-6)
    assert usd_compliance_errors(out) == []


def test_write_clip_as_layer_leaves_unchanged_attributes_out(tmp_path):
    src = build_stage(tmp_path / "char.usda")
    clip = read_clip(src)
    hand = SKEL_JOINTS.index("Hips/Spine/Hand")
    out = write_clip(src, clip.with_joint_rotations([hand], random_quats((clip.num_frames, 1))),
                     tmp_path / "hand.usda", as_layer=True)
    layer = Sdf.Layer.FindOrOpen(str(out))
    specs = []
    layer.Traverse(layer.pseudoRoot.path, specs.append)
    assert sorted(str(p) for p in specs if p.IsPropertyPath()) == ["/Char/Skel/Anim.rotations"]
    assert list(layer.subLayerPaths) == ["./char.usda"]


def test_write_clip_full_copy_keeps_other_prims(tmp_path):
    src = build_stage(tmp_path / "char.usda")
    before = _layer_bytes(src)
    clip = read_clip(src)
    new = clip.replace(rotations=random_quats(clip.rotations.shape[:2]))
    out = write_clip(src, new, tmp_path / "copy.usdc")
    assert _layer_bytes(src) == before
    stage = Usd.Stage.Open(str(out))
    assert stage.GetPrimAtPath("/Char/Looks/Skin").IsA(UsdShade.Material)
    assert stage.GetPrimAtPath("/Char/Body").IsA(UsdGeom.Mesh)
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    assert not stage.GetRootLayer().subLayerPaths
    back = read_clip(out)
    assert_rotations_close(back.rotations, new.rotations)
    assert len(UsdSkel.Animation(stage.GetPrimAtPath("/Char/Skel/Anim")).GetJointsAttr().Get()) == 5
    assert usd_compliance_errors(out) == []


def test_write_clip_binds_new_animation_when_none(tmp_path):
    src = tmp_path / "rig.usda"
    clip = random_clip(T=3, J=5)
    write_asset(Asset("mem", (clip.skeleton,), ()), src)
    assert read_asset(src).clips == ()
    sk = read_asset(src).skeletons[0]
    new = Clip(sk, 30, random_quats((3, 5)), name="whatever")
    out = write_clip(src, new, tmp_path / "anim.usda", as_layer=True)
    back = read_clip(out)
    assert back.name == "/Root/Animation"
    assert_rotations_close(back.rotations, new.rotations)


def test_write_clip_unknown_joint(tmp_path):
    src = build_stage(tmp_path / "char.usda")
    clip = random_clip(T=3, J=2)
    with pytest.raises(AssetReadError) as e:
        write_clip(src, clip, tmp_path / "x.usda")
    assert str(e.value) == f"{src}: no Skeleton for the clip's skeleton 'Rig'"
    assert not (tmp_path / "x.usda").exists()


def test_cesium_man_write_clip(shared_assets, tmp_path):
    src = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    clip = read_clip(src)
    new = clip.with_joint_rotations([5], random_quats((clip.num_frames, 1)))
    source_errors = set(usd_compliance_errors(src))
    for as_layer in (False, True):
        out = write_clip(src, new, tmp_path / f"cm{int(as_layer)}.usda", as_layer=as_layer)
        assert set(usd_compliance_errors(out)) <= source_errors
        back = read_asset(out)
        assert_rotations_close(back.clips[0].rotations, new.rotations)
        assert back.meshes[0].points.shape == (3273, 3)


# --------------------------------------------------------------------------- schema data
def test_hand_map_and_finger_motion_recorded_in_layer(tmp_path):
    from usdhands.formats.usd_schema_data import read_finger_motion, read_hand_maps
    from usdhands.model.handmap import HandMap, HandSide

    src = build_stage(tmp_path / "char.usda")
    clip = read_clip(src)
    hm = HandMap(left=HandSide("left", wrist="Hand", forearm="Hips/Spine", root="Hips",
                               fingers={"index": ("Hips/Spine/Hand/Index1",)}))
    out = write_clip(src, clip, tmp_path / "marked.usda", as_layer=True, hand_map=hm,
                     finger_motion={"method": "synthesis", "database": "db/gestures.npz",
                                    "parameters": {"k": 5, "wP": 1.0}})
    layer = Sdf.Layer.FindOrOpen(str(out))
    specs = []
    layer.Traverse(layer.pseudoRoot.path, specs.append)
    assert all(layer.GetPrimAtPath(p).specifier == Sdf.SpecifierOver for p in specs if p.IsPrimPath())
    maps = read_hand_maps(out)
    assert list(maps) == ["/Char/Skel"]
    left = maps["/Char/Skel"].left
    assert maps["/Char/Skel"].right is None
    assert (left.wrist, left.forearm, left.shoulder, left.root) == ("Hips/Spine/Hand", "Hips/Spine", None, "Hips")
    assert left.fingers["index"] == ("Hips/Spine/Hand/Index1",) and left.fingers["thumb"] == ()
    stage = Usd.Stage.Open(str(out))
    motion = read_finger_motion(stage.GetPrimAtPath("/Char/Skel/Anim"))
    assert motion == {"method": "synthesis", "database": "db/gestures.npz", "parameters": {"k": 5, "wP": 1.0},
                      "version": "0.1.0"}
    assert read_hand_maps(src) == {}
    assert usd_compliance_errors(out) == []


def test_hand_map_naming_a_missing_joint(tmp_path):
    from usdhands.errors import ConfigError
    from usdhands.formats.usd_schema_data import read_hand_maps

    p = build_stage(tmp_path / "char.usda")
    stage = Usd.Stage.Open(str(p))
    prim = stage.GetPrimAtPath("/Char/Skel")
    prim.AddAppliedSchema("UsdHandsHandMapAPI:right")
    prim.CreateAttribute("usdhands:hand:right:wrist", Sdf.ValueTypeNames.Token).Set("Hips/Spine/Claw")
    stage.Save()
    with pytest.raises(ConfigError) as e:
        read_hand_maps(p)
    assert str(e.value) == f"{p}: /Char/Skel: UsdHandsHandMapAPI names joint 'Hips/Spine/Claw', which the skeleton " \
                           "does not have"


def test_finger_motion_method_checked(tmp_path):
    src = build_stage(tmp_path / "char.usda")
    with pytest.raises(ValueError, match=r"Expected method in .*, got 'magic'"):
        write_clip(src, read_clip(src), tmp_path / "x.usda", finger_motion={"method": "magic"})
    assert not (tmp_path / "x.usda").exists()


def test_write_matches_clips_to_skeletons_by_joint_names(tmp_path):
    clip = random_clip(T=4, J=6)
    twin = Skeleton(clip.skeleton.joint_names, clip.skeleton.parents, clip.skeleton.rest_translations,
                    clip.skeleton.rest_rotations, meters_per_unit=0.01, up_axis="Z", name="Rig")
    out = write_asset(Asset("mem", (twin,), (clip,)), tmp_path / "twin.usda")
    back = read_clip(out)
    assert back.name == "/Root/Take_1"
    assert_rotations_close(back.rotations, clip.rotations)
    stranger = random_clip(T=2, J=3)
    with pytest.raises(ValueError, match="Expected clip 'Take 1' to animate one of the asset's skeletons"):
        HANDLER.write(Asset("mem", (twin,), (stranger,)), tmp_path / "bad.usda")


@pytest.mark.parametrize("name", ["webxr_hand/left.glb", "robot_expressive/RobotExpressive.glb",
                                  "leap_hands/fingers-ok.bvh"])
def test_other_formats_to_usd_and_back(shared_assets, tmp_path, name):
    """Real glTF and BVH files written as USD: valid, and read back joint for joint, but for
    the static nodes above the skin's joints (RobotExpressive's ``RobotArmature``), which
    become Xforms above the SkelRoot and are folded back into the root joints."""
    a = read_asset(shared_assets / name)
    out = write_asset(a, tmp_path / "out.usdc")
    assert usd_compliance_errors(out) == []
    b = read_asset(out)
    lifted = {"robot_expressive/RobotExpressive.glb": {"RobotArmature"}}.get(name, set())
    assert [s.joint_names for s in b.skeletons] == [tuple(n for n in s.joint_names if n not in lifted)
                                                   for s in a.skeletons]
    assert len(b.clips) == len(a.clips) and len(b.meshes) == len(a.meshes)
    for ca, cb in zip(a.clips, b.clips):
        cols = [ca.skeleton.index(n) for n in cb.skeleton.joint_names]
        assert cb.num_frames == ca.num_frames and cb.fps == pytest.approx(ca.fps)
        scale = 1.0 + np.abs(ca.world_positions()).max()
        assert np.abs(ca.world_positions()[:, cols] - cb.world_positions()).max() < 1e-6 * scale
        inner = [k for k, p in enumerate(cb.skeleton.parents) if p >= 0]
        assert quat_angle_deg(ca.rotations[:, cols][:, inner], cb.rotations[:, inner]).max() < 1e-4
        scale = 1.0 + np.abs(ca.translations).max()
        assert np.abs(ca.translations[:, cols][:, inner] - cb.translations[:, inner]).max() < 1e-6 * scale
    for ma, mb in zip(a.meshes, b.meshes):
        remap = {ja: jb for jb, n in enumerate(b.skeletons[mb.skeleton_index].joint_names)
                 for ja in [a.skeletons[ma.skeleton_index].index(n)]}
        assert (mb.joint_indices == np.vectorize(remap.get)(ma.joint_indices)).all()
    for ma, mb in zip(a.meshes, b.meshes):
        np.testing.assert_allclose(mb.points, ma.points, atol=1e-5)
        np.testing.assert_allclose(mb.joint_weights, ma.joint_weights, atol=1e-7)
        assert (mb.face_vertex_indices == ma.face_vertex_indices).all()


def test_write_clip_at_another_rate_than_the_stage(tmp_path):
    src = build_stage(tmp_path / "char.usda")
    clip = read_clip(src, fps=60)  # 11 frames on a 30 time-codes-per-second stage
    out = write_clip(src, clip, tmp_path / "sixty.usda", as_layer=True)
    stage = Usd.Stage.Open(str(out))
    attr = stage.GetPrimAtPath("/Char/Skel/Anim").GetAttribute("rotations")
    assert attr.GetTimeSamples() == [10.0 + 0.5 * i for i in range(11)]
    back = read_clip(out)
    assert back.fps == 60 and back.num_frames == 11 and back.start_time == pytest.approx(clip.start_time)
    assert_rotations_close(back.rotations, clip.rotations)


def test_write_clip_as_layer_shorter_clip(tmp_path):
    src = build_stage(tmp_path / "char.usda")
    clip = read_clip(src).slice(1, 4)  # unchanged values, fewer frames
    out = write_clip(src, clip, tmp_path / "short.usda", as_layer=True)
    back = read_clip(out)
    assert back.num_frames == 3 and back.start_time == pytest.approx(11 / 30)
    assert_rotations_close(back.rotations, clip.rotations)


def test_animation_without_values_has_zero_frames(tmp_path):
    from usdhands.errors import InvalidAnimationError

    p = tmp_path / "empty.usda"
    stage = Usd.Stage.CreateNew(str(p))
    skel = UsdSkel.Skeleton.Define(stage, "/Skel")
    skel.CreateJointsAttr().Set(["a"])
    skel.CreateRestTransformsAttr().Set(Vt.Matrix4dArray([Gf.Matrix4d(1)]))
    anim = UsdSkel.Animation.Define(stage, "/Skel/Anim")
    anim.CreateJointsAttr().Set(["a"])
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    stage.Save()
    assert HANDLER.read(p).clips[0].num_frames == 0
    with pytest.raises(InvalidAnimationError) as e:
        read_clip(p)
    assert str(e.value) == f"{p}: animation '/Skel/Anim' has zero frames"


def test_write_clip_copy_keeps_variants_and_reanchors_asset_paths(tmp_path):
    src = build_stage(tmp_path / "char.usda")
    (tmp_path / "tex").mkdir()
    (tmp_path / "tex" / "skin.png").write_bytes(b"not really a png")
    stage = Usd.Stage.Open(str(src))
    looks = stage.GetPrimAtPath("/Char/Looks")
    vset = looks.GetVariantSets().AddVariantSet("palette")
    for name in ("warm", "cold"):
        vset.AddVariant(name)
        vset.SetVariantSelection(name)
        with vset.GetVariantEditContext():
            stage.DefinePrim(f"/Char/Looks/{name.title()}Only", "Scope")
    vset.SetVariantSelection("warm")
    tex = stage.GetPrimAtPath("/Char/Looks/Skin").CreateAttribute("file", Sdf.ValueTypeNames.Asset)
    tex.Set(Sdf.AssetPath("./tex/skin.png"))
    stage.Save()
    clip = read_clip(src)
    new = clip.replace(rotations=random_quats(clip.rotations.shape[:2]))
    (tmp_path / "out").mkdir()
    out = write_clip(src, new, tmp_path / "out" / "copy.usda")
    layer = Sdf.Layer.FindOrOpen(str(out))
    vspec = layer.GetPrimAtPath("/Char/Looks").variantSets["palette"]
    assert sorted(v.name for v in vspec.variantList) == ["cold", "warm"]  # the unselected variant is kept
    assert layer.GetAttributeAtPath("/Char/Looks/Skin.file").default.path == "../tex/skin.png"
    copied = Usd.Stage.Open(str(out))
    resolved = copied.GetPrimAtPath("/Char/Looks/Skin").GetAttribute("file").Get().resolvedPath
    assert Path(resolved) == tmp_path / "tex" / "skin.png"
    assert_rotations_close(read_clip(out).rotations, new.rotations)


def test_write_clip_flattens_a_source_with_sublayers(tmp_path):
    base = build_stage(tmp_path / "base.usda")
    top = tmp_path / "shot.usda"
    layer = Sdf.Layer.CreateNew(str(top))
    layer.subLayerPaths.append("./base.usda")
    layer.Save()
    stage = Usd.Stage.Open(str(top))
    stage.DefinePrim("/Char/Prop", "Xform")
    stage.Save()
    clip = read_clip(top)
    out = write_clip(top, clip, tmp_path / "flat.usda")
    flat = Sdf.Layer.FindOrOpen(str(out))
    assert list(flat.subLayerPaths) == []
    assert flat.GetPrimAtPath("/Char/Prop") and flat.GetPrimAtPath("/Char/Skel/Anim")
    assert base.exists()


def test_written_files_get_the_usual_permissions(tmp_path):
    import os

    src = build_stage(tmp_path / "char.usda")
    out = write_clip(src, read_clip(src), tmp_path / "perm.usda", as_layer=True)
    umask = os.umask(0)
    os.umask(umask)
    assert out.stat().st_mode & 0o777 == 0o666 & ~umask


def test_write_clip_animation_chosen_by_name_or_path(tmp_path):
    src = build_stage(tmp_path / "char.usda")
    clip = read_clip(src).replace(name="renamed in memory")
    new = clip.replace(rotations=random_quats(clip.rotations.shape[:2]))
    for i, which in enumerate(("Anim", "/Char/Skel/Anim")):
        out = write_clip(src, new, tmp_path / f"by{i}.usda", animation=which)
        assert_rotations_close(read_clip(out).rotations, new.rotations)
    with pytest.raises(AssetReadError) as e:
        write_clip(src, new, tmp_path / "x.usda", animation="Walk")
    assert str(e.value) == f"{src}: no SkelAnimation named 'Walk'; give its prim path"
    with pytest.raises(AssetReadError) as e:
        write_clip(src, new, tmp_path / "x.usda", animation="/Char/Body")
    assert str(e.value) == f"{src}: no SkelAnimation at /Char/Body"


# --------------------------------------------------------------------------- transforms above the Skeleton
def _stage_under_transforms(path):
    """A skinned 3-joint arm under a static rotated, scaled, moved Xform and an animated one."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    stage.SetTimeCodesPerSecond(24)
    world = UsdGeom.Xform.Define(stage, "/World")
    world.AddTranslateOp().Set(Gf.Vec3d(1, 2, 3))
    world.AddRotateXOp().Set(-90.0)
    world.AddScaleOp().Set(Gf.Vec3f(2, 2, 2))
    mover = UsdGeom.Xform.Define(stage, "/World/Mover")
    op = mover.AddTranslateOp()
    for t in range(4):
        op.Set(Gf.Vec3d(0.5 * t, 0, 0), t)
    mover.AddRotateZOp().Set(30.0)
    root = UsdSkel.Root.Define(stage, "/World/Mover/Char")
    skel = UsdSkel.Skeleton.Define(stage, "/World/Mover/Char/Skel")
    joints = ["A", "A/B", "A/B/C"]
    skel.CreateJointsAttr().Set(joints)
    rest = [Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 0, 0.3)), Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 1, 0)),
            Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 1, 0))]
    skel.CreateRestTransformsAttr().Set(rest)
    bind = [rest[0], rest[1] * rest[0], rest[2] * rest[1] * rest[0]]
    skel.CreateBindTransformsAttr().Set(bind)
    anim = UsdSkel.Animation.Define(stage, "/World/Mover/Char/Anim")
    anim.CreateJointsAttr().Set(joints)
    rng = np.random.default_rng(5)
    for t in range(4):
        q = rng.normal(size=(3, 4)).astype(np.float32)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        anim.CreateRotationsAttr().Set(Vt.QuatfArray.FromNumpy(q), t)
        anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([(0.1 * t, 0, 0.3), (0, 1, 0), (0, 1, 0)]), t)
    anim.CreateScalesAttr().Set(Vt.Vec3hArray([(1, 1, 1)] * 3))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    mesh = UsdGeom.Mesh.Define(stage, "/World/Mover/Char/Mesh")
    mesh.CreatePointsAttr().Set([(0.2, 0, 0), (0.2, 1.5, 0), (-0.2, 2, 0.1)])
    mesh.CreateFaceVertexCountsAttr().Set([3])
    mesh.CreateFaceVertexIndicesAttr().Set([0, 1, 2])
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(False, 2).Set([0, 1, 1, 2, 2, 1])
    binding.CreateJointWeightsPrimvar(False, 2).Set([0.7, 0.3, 0.5, 0.5, 0.9, 0.1])
    binding.CreateGeomBindTransformAttr().Set(Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 0.1, 0)))
    stage.Save()
    return root, skel


def _usd_world_joints(path, t):
    stage = Usd.Stage.Open(str(path))
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(stage.GetPrimAtPath("/World/Mover/Char")), Usd.PrimDefaultPredicate)
    query = cache.GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath("/World/Mover/Char/Skel")))
    return np.asarray(query.ComputeJointWorldTransforms(UsdGeom.XformCache(t)), dtype=float).transpose(0, 2, 1)


def test_transforms_above_the_skeleton_are_folded_into_the_roots(tmp_path):
    src = tmp_path / "moved.usda"
    _stage_under_transforms(src)
    asset = read_asset(src)
    clip = asset.clips[0]
    assert clip.num_frames == 4
    ours = clip.world_xforms()
    for t in range(4):  # the Mover's animated translate is folded frame by frame
        np.testing.assert_allclose(ours[t], _usd_world_joints(src, t), atol=1e-5)
    # the skinned mesh lands where UsdSkel's own skinning puts it
    m = asset.meshes[0]
    sk = clip.skeleton
    stage = Usd.Stage.Open(str(src))
    stage.SetEditTarget(stage.GetSessionLayer())
    assert UsdSkel.BakeSkinning(UsdSkel.Root(stage.GetPrimAtPath("/World/Mover/Char")), Gf.Interval(2, 2))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Mover/Char/Mesh"))
    baked = np.asarray(mesh.GetPointsAttr().Get(2), dtype=float)
    to_world = np.asarray(mesh.ComputeLocalToWorldTransform(2), dtype=float).T
    want = (np.c_[baked, np.ones(3)] @ to_world.T)[:, :3]
    skin = ours[2] @ np.linalg.inv(sk.bind_xforms)
    p = np.c_[m.points, np.ones(len(m.points))] @ m.geom_bind_xform.T
    got = np.einsum("vk,vkij,vj->vi", m.joint_weights, skin[m.joint_indices], p)[:, :3]
    np.testing.assert_allclose(got, want, atol=1e-5)


def test_folded_roots_are_unfolded_when_written_back(tmp_path):
    src = tmp_path / "moved.usda"
    _stage_under_transforms(src)
    clip = read_clip(src)
    src_stage = Usd.Stage.Open(str(src))
    src_anim = UsdSkel.Animation(src_stage.GetPrimAtPath("/World/Mover/Char/Anim"))
    out = write_clip(src, clip, tmp_path / "copy.usda")
    out_stage = Usd.Stage.Open(str(out))
    anim = UsdSkel.Animation(out_stage.GetPrimAtPath("/World/Mover/Char/Anim"))
    for t in range(4):
        np.testing.assert_allclose(np.asarray(anim.GetRotationsAttr().Get(t)),
                                   np.asarray(src_anim.GetRotationsAttr().Get(t)), atol=1e-6)
        np.testing.assert_allclose(np.asarray(anim.GetTranslationsAttr().Get(t)),
                                   np.asarray(src_anim.GetTranslationsAttr().Get(t)), atol=1e-6)
        np.testing.assert_allclose(_usd_world_joints(out, t), clip.world_xforms()[t], atol=1e-5)
    # an unchanged clip as a layer authors no root override
    layer = write_clip(src, clip, tmp_path / "layer.usda", as_layer=True)
    assert "rotations" not in layer.read_text() and "translations" not in layer.read_text()
    # a changed root comes back as changed, in world space
    moved = clip.replace(translations=clip.translations + np.array([0.0, 0.25, 0.0]))
    layer = write_clip(src, moved, tmp_path / "layer2.usda", as_layer=True)
    back = read_clip(layer)
    np.testing.assert_allclose(back.world_positions(), moved.world_positions(), atol=1e-5)
    np.testing.assert_allclose(back.world_positions()[:, 0] - clip.world_positions()[:, 0],
                               np.tile([0, 0.25, 0], (4, 1)), atol=1e-5)


def test_one_value_at_a_later_frame_is_refused_not_broadcast(tmp_path):
    """The reader copies whole frames at once; a frame with one translation for 3 joints
    would broadcast into all three: it must still be refused, naming the time."""
    p = build_stage(tmp_path / "one.usda")
    stage = Usd.Stage.Open(str(p))
    attr = UsdSkel.Animation(stage.GetPrimAtPath("/Char/Skel/Anim")).GetTranslationsAttr()
    t = attr.GetTimeSamples()[1]
    attr.Set(Vt.Vec3fArray([Gf.Vec3f(1, 2, 3)]), t)
    stage.Save()
    with pytest.raises(JointMismatchError) as e:
        read_asset(p)
    assert str(e.value) == f"{p}: /Char/Skel/Anim: translations has 1 values for 3 joints at time {t:g}"


def test_clip_values_are_the_authored_samples(tmp_path):
    """Every frame's rotations and translations equal attribute.Get at that time (the whole-frame copy)."""
    p = build_stage(tmp_path / "anim.usda")
    clip = HANDLER.read(p).clip()
    stage = Usd.Stage.Open(str(p))
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/Char/Skel/Anim"))
    order = [clip.skeleton.joint_names.index(str(j)) for j in anim.GetJointsAttr().Get()]
    times = anim.GetRotationsAttr().GetTimeSamples()
    assert clip.num_frames == len(times) > 1
    for f, t in enumerate(times):
        q = np.array(anim.GetRotationsAttr().Get(t), dtype=np.float64)
        tr = np.array(anim.GetTranslationsAttr().Get(t), dtype=np.float64)
        assert np.array_equal(clip.rotations[f, order], q)
        assert np.array_equal(clip.translations[f, order], tr)


@pytest.mark.parametrize("sampled", [False, True])
def test_clip_scales_are_the_authored_scales(tmp_path, sampled):
    """Scales without time samples are read once and hold at every frame; time-sampled
    ones are read at every frame (both equal attribute.Get at that time)."""
    p = build_stage(tmp_path / "anim.usda")
    stage = Usd.Stage.Open(str(p))
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/Char/Skel/Anim"))
    times = anim.GetRotationsAttr().GetTimeSamples()
    K = len(anim.GetJointsAttr().Get())
    attr = anim.GetScalesAttr()
    if sampled:
        for f, t in enumerate(times):
            attr.Set(Vt.Vec3hArray([Gf.Vec3h(1 + 0.25 * f, 2 - 0.125 * k, 0.5) for k in range(K)]), t)
    else:
        attr.Set(Vt.Vec3hArray([Gf.Vec3h(0.5, 1.5, 2 + k) for k in range(K)]))
    stage.Save()
    clip = HANDLER.read(p).clip()
    order = [clip.skeleton.joint_names.index(str(j)) for j in anim.GetJointsAttr().Get()]
    assert clip.num_frames == len(times) > 1
    for f, t in enumerate(times):
        assert np.array_equal(clip.scales[f, order], np.array(attr.Get(t), dtype=np.float64))
    assert (len(np.unique(clip.scales[:, order[0], 0])) > 1) == sampled


@pytest.mark.parametrize("case", ["equal", "round alike", "differ"])
def test_written_scales_are_one_value_when_their_half_floats_are(tmp_path, case):
    """Scales are written as one default value when every frame's half floats are the same
    (the same numbers, or numbers that round alike), else one time sample per frame."""
    rng = np.random.default_rng(4)
    T, J = 6, 3
    sk = Skeleton(["a", "a/b", "a/b/c"], [-1, 0, 1], rng.normal(size=(J, 3)), np.tile([0.0, 0, 0, 1], (J, 1)))
    q = rng.normal(size=(T, J, 4))
    scales = np.tile([[1.5, 2.0, 0.75]], (T, J, 1))
    if case == "round alike":
        scales[3] += 1e-6  # below half a half-float step
    elif case == "differ":
        scales[3, 1, 2] = 3.0
    clip = Clip(sk, 24.0, q / np.linalg.norm(q, axis=-1, keepdims=True), rng.normal(size=(T, J, 3)), scales,
                name="Anim")
    out = write_asset(Asset("s", (sk,), (clip,)), tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(out))
    anim = next(UsdSkel.Animation(p) for p in stage.Traverse() if p.IsA(UsdSkel.Animation))
    attr = anim.GetScalesAttr()
    assert attr.GetNumTimeSamples() == (T if case == "differ" else 0)
    back = read_asset(out).clip()
    assert np.array_equal(back.scales, clip.scales.astype(np.float16).astype(np.float64))


def test_all_close_answers_as_numpys_allclose():
    """The readers' all_close is np.allclose's answer: finite references (its own test, both ways),
    infinite and NaN ones on either side, zero and negative tolerances."""
    from usdhands.formats.usd_common import all_close

    rng = np.random.default_rng(3)
    specials = [0.0, 1.0, -1.0, 1e-13, 1e300, np.inf, -np.inf, np.nan]
    for trial in range(3000):
        shape = [(), (3,), (4, 4), (2, 4, 4)][trial % 4]
        b = rng.normal(size=shape)
        a = b + rng.normal(size=shape) * 10.0 ** -rng.integers(3, 15)
        if trial % 3 == 0:
            a = np.where(rng.random(shape) < 0.2, rng.choice(specials, size=shape), a)
        if trial % 5 == 0:
            b = np.where(rng.random(shape) < 0.2, rng.choice(specials, size=shape), b)
        rtol, atol = [(1e-5, 1e-8), (0.0, 1e-12), (1e-6, 1e-9), (0.0, 0.0), (-1e-5, 1e-8), (1e-5, -1e-8)][trial % 6]
        with np.errstate(all="ignore"):
            assert all_close(a, b, rtol=rtol, atol=atol) == bool(np.allclose(a, b, rtol=rtol, atol=atol)), (a, b)


def test_joint_transform_check_fast_path_agrees_with_the_full_check(monkeypatch):
    """_xforms_ok (the whole array at once) passes exactly the transforms the full check passes:
    random rest poses with non-finite, zero-scale, collapsed and projective joints mixed in."""
    from usdhands.formats import usd_read

    rng = np.random.default_rng(5)
    full = usd_read._check_xforms

    def passes_full(m):
        monkeypatch.setattr(usd_read, "_xforms_ok", lambda m: False)
        try:
            full(m, [f"j{k}" for k in range(len(m))], "restTransforms", None, "/Skel")
            return True
        except AssetReadError:
            return False
        finally:
            monkeypatch.undo()

    for trial in range(400):
        J = int(rng.integers(1, 8))
        m = trs_to_xform(rng.normal(size=(J, 3)), rng.normal(size=(J, 4)), rng.uniform(0.5, 2, size=(J, 3)))
        j = int(rng.integers(0, J))
        defect = trial % 8
        if defect == 1:
            m[j, int(rng.integers(0, 4)), int(rng.integers(0, 4))] = rng.choice([np.nan, np.inf, -np.inf])
        elif defect == 2:
            m[j, :3, int(rng.integers(0, 3))] = 0.0  # a zero scale
        elif defect == 3:
            m[j, :3, 1] = m[j, :3, 0] * rng.uniform(0.5, 2)  # collapsed axes
        elif defect == 4:
            m[j, 3, int(rng.integers(0, 4))] += rng.choice([1e-3, -1e-7, 5e-7, 3e-6, -2e-6, 1.0])  # fourth column
        elif defect == 5:
            m[j] *= 1e300  # overflows in the column lengths
        assert usd_read._xforms_ok(m) == passes_full(m), (trial, m)


def test_fold_into_roots_splits_a_transform_that_does_not_move_once():
    """A world transform equal at every frame gives the numbers of folding each frame on its own."""
    from usdhands.formats.usd_common import fold_into_roots
    from usdhands.model.rotations import quat_to_matrix

    rng = np.random.default_rng(2)
    T, J = 7, 5
    parents = np.array([-1, 0, 0, -1, 3])
    t, q, s = rng.normal(size=(T, J, 3)), rng.normal(size=(T, J, 4)), rng.uniform(0.5, 2, (T, J, 3))
    world = np.eye(4)
    world[:3, :3] = quat_to_matrix(rng.normal(size=4)) * 0.01
    world[:3, 3] = rng.normal(size=3)
    whole = fold_into_roots(parents, np.repeat(world[None], T, axis=0), t, q, s)
    for f in range(T):
        alone = fold_into_roots(parents, world[None], t[f:f + 1], q[f:f + 1], s[f:f + 1])
        for a, b in zip(whole, alone):
            assert a[f:f + 1].tobytes() == b.tobytes()


def test_fold_into_roots_gives_the_numbers_of_splitting_each_product_on_its_own():
    """The roots' products and the world transforms are split in one xform_to_trs call: the same bits
    as splitting the products, then the world (the hemisphere reference), each in a call of its own,
    for worlds that move, that do not move, that mirror, and one frame."""
    from usdhands.formats.usd_common import fold_into_roots
    from usdhands.model.rotations import quat_canonical, quat_multiply, trs_to_xform, xform_to_trs

    def separately(parents, world, t, q, s):
        t, q, s = (np.array(a, dtype=np.float64) for a in (t, q, s))
        roots = np.flatnonzero(parents < 0)
        m = world[:, None] @ trs_to_xform(t[:, roots], q[:, roots], s[:, roots])
        nt, nq, ns = xform_to_trs(m)
        one = len(world) > 1 and bool((world == world[:1]).all())
        qw = quat_canonical(xform_to_trs(world[:1] if one else world)[1])
        ref = quat_multiply(np.broadcast_to(qw[:, None], q[:, roots].shape), q[:, roots])
        nq = np.where((np.sum(nq * ref, axis=-1) < 0)[..., None], -nq, nq)
        t[:, roots], q[:, roots], s[:, roots] = nt, nq, ns
        return t, q, s

    rng = np.random.default_rng(3)
    for trial in range(120):
        T, J = int(rng.integers(1, 25)), int(rng.integers(1, 6))
        parents = np.array([-1] + [int(rng.integers(-1, j)) for j in range(1, J)])
        t, q, s = rng.normal(size=(T, J, 3)), rng.normal(size=(T, J, 4)), rng.uniform(0.5, 2, (T, J, 3))
        if trial % 3 == 0:  # does not move
            world = np.repeat(trs_to_xform(rng.normal(size=3), rng.normal(size=4), np.full(3, 0.01))[None], T, 0)
        else:  # moves; every third mirrored
            world = trs_to_xform(rng.normal(size=(T, 3)), rng.normal(size=(T, 4)), rng.uniform(0.5, 2, (T, 3)))
            if trial % 3 == 2:
                world = world @ np.diag([1.0, -1.0, 1.0, 1.0])
        for a, b in zip(fold_into_roots(parents, world, t, q, s), separately(parents, world, t, q, s)):
            assert a.shape == b.shape and a.tobytes() == b.tobytes(), trial


def test_mesh_extent_is_numpys_min_and_max_to_the_bit():
    """The written extent equals pts.min(axis=0) / pts.max(axis=0) bit for bit: signed zeros at the
    bounds (either order), NaN and infinite points, one point, many."""
    from usdhands.formats.usd_write import _extent

    rng = np.random.default_rng(7)
    for trial in range(600):
        n = int(rng.integers(1, 5000)) if trial % 3 else int(rng.integers(1, 6))
        pts = rng.normal(size=(n, 3)).astype(np.float32)
        if trial % 4 == 1:  # bounds at zero, signed both ways
            pts = np.abs(pts) * rng.choice([1, -1])
            pts[rng.integers(0, n, 3), rng.integers(0, 3, 3)] = rng.choice([0.0, -0.0], 3)
        if trial % 7 == 2:
            pts[rng.integers(0, n), rng.integers(0, 3)] = rng.choice([np.nan, np.inf, -np.inf])
        lo, hi = _extent(pts)
        assert lo.tobytes() == pts.min(axis=0).tobytes() and hi.tobytes() == pts.max(axis=0).tobytes(), trial

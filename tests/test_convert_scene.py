"""Scene-preserving conversion glTF <-> USD (issue 12, item 1): every mesh on a skeleton (skinned
and rigid parts below joints), materials as UsdPreviewSurface with their textures, morph targets as
UsdSkel BlendShapes with animated weights, animation names and interpolation, through
glTF -> USD -> glTF (and USD -> glTF -> USD) on the third-party assets and a constructed file.
Every written glTF passes the Khronos validator, every written USD USD's validators."""

from __future__ import annotations

import io
import json
import os
import threading
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from pxr import Usd, UsdShade, UsdSkel

from usdhands.formats.gltf_container import BinaryAppender, load_gltf, save_gltf
from usdhands.formats.io import read_asset, write_asset
from usdhands.formats.usd_validate import usd_compliance_errors
from usdhands.jobs.conversion import ConvertOptions, convert

from hostile import check_promise, listing


def _gltf_json(path: Path) -> dict:
    data = path.read_bytes()
    if path.suffix == ".glb":
        n = int.from_bytes(data[12:16], "little")
        return json.loads(data[20:20 + n])
    return json.loads(data)


def _summary(path: Path) -> dict:
    """What a glTF file holds, counted from its JSON (independently of the reader)."""
    g = _gltf_json(path)
    acc = g.get("accessors", [])
    anims = g.get("animations", [])
    return {
        "meshes": len(g.get("meshes", [])),
        "primitives": sum(len(m["primitives"]) for m in g.get("meshes", [])),
        "vertices": sum(acc[p["attributes"]["POSITION"]]["count"] for m in g.get("meshes", []) for p in m["primitives"]),
        "materials": len(g.get("materials", [])),
        "images": len(g.get("images", [])),
        "morph_targets": sum(len(p.get("targets", [])) for m in g.get("meshes", []) for p in m["primitives"]),
        "target_names": [m.get("extras", {}).get("targetNames") for m in g.get("meshes", [])
                         if m.get("extras", {}).get("targetNames")],
        "animations": [a.get("name") for a in anims],
        "keys": [sorted({acc[s["input"]]["count"] for s in a["samplers"]}) for a in anims],
        "interpolation": [sorted({s.get("interpolation", "LINEAR") for s in a["samplers"]}) for a in anims],
        "weights_channels": [sum(1 for c in a["channels"] if c["target"]["path"] == "weights") for a in anims],
    }


def _usd_counts(path: Path) -> dict:
    stage = Usd.Stage.Open(str(path))
    prims = list(stage.Traverse())
    meshes = [p for p in prims if p.GetTypeName() == "Mesh"]
    anims = [UsdSkel.Animation(p) for p in prims if p.IsA(UsdSkel.Animation)]
    return {
        "meshes": len(meshes),
        "points": sum(len(p.GetAttribute("points").Get()) for p in meshes),
        "bound": sum(1 for p in meshes if UsdSkel.BindingAPI(p).GetSkeletonRel().GetTargets()),
        "materials": sum(1 for p in prims if p.IsA(UsdShade.Material)),
        "with_material": sum(1 for p in meshes if UsdShade.MaterialBindingAPI(p).ComputeBoundMaterial()[0]),
        "blend_shapes": sum(1 for p in prims if p.IsA(UsdSkel.BlendShape)),
        "animation_shapes": [len(a.GetBlendShapesAttr().Get() or []) for a in anims],
    }


# -- the third-party assets ------------------------------------------------------------

def test_robot_expressive_keeps_the_whole_scene(shared_assets, tmp_path, gltf_validator):
    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    usd, back = tmp_path / "robot.usda", tmp_path / "robot.glb"
    result = convert(src, usd)
    assert result.meshes == 19 and result.notes == ()
    convert(usd, back)
    a, b = _summary(src), _summary(back)
    assert a["vertices"] == b["vertices"] == 7214
    assert (b["meshes"], b["primitives"]) == (a["meshes"], a["primitives"]) == (14, 19)
    assert b["materials"] == a["materials"] == 3
    assert b["morph_targets"] == a["morph_targets"] == 9
    assert b["target_names"] == a["target_names"] == [["Angry", "Surprised", "Sad"]]
    assert b["animations"] == a["animations"] and len(a["animations"]) == 14
    assert b["keys"] == a["keys"] and b["weights_channels"] == a["weights_channels"] == [1] * 14
    assert gltf_validator(back)[0]["numErrors"] == 0
    # in USD: every mesh is bound to the skeleton (the rigid parts follow one joint), 3 materials bound
    # to all 19, 3 blend shapes on each of the head's 3 primitives, weights in every SkelAnimation
    u = _usd_counts(usd)
    assert (u["meshes"], u["points"], u["bound"]) == (19, 7214, 19)
    assert (u["materials"], u["with_material"]) == (3, 19)
    assert u["blend_shapes"] == 9 and u["animation_shapes"] == [3] * 14
    assert usd_compliance_errors(usd) == []
    # material factors are the source's
    ga, gb = _gltf_json(src)["materials"], _gltf_json(back)["materials"]
    for ma, mb in zip(ga, gb):
        assert mb["name"] == ma["name"]
        np.testing.assert_allclose(mb["pbrMetallicRoughness"]["baseColorFactor"],
                                   ma["pbrMetallicRoughness"]["baseColorFactor"], atol=1e-6)
        for k in ("metallicFactor", "roughnessFactor"):
            assert mb["pbrMetallicRoughness"][k] == pytest.approx(ma["pbrMetallicRoughness"][k], abs=1e-6)


def test_robot_expressive_rigid_parts_move_with_their_joints(shared_assets, tmp_path):
    """UsdSkel's own BakeSkinning of the converted head (a mesh node below the Head joint in the glTF)
    puts it where the glTF node tree does: world transform of its node at each frame times its points."""
    from pxr import UsdGeom

    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    usd = tmp_path / "robot.usda"
    convert(src, usd)
    g = pygltflib.GLTF2().load(str(src))
    asset = read_asset(src)
    clip = asset.clip("Wave")
    sk = clip.skeleton
    head = next(m for m in asset.meshes if m.name == "Head_0")
    j = head.rigid_joint()
    assert sk.joint_names[j] == "Head"
    world = clip.world_xforms()[:, j] @ np.linalg.inv(sk.bind_xforms[j]) @ head.geom_bind_xform
    expect = np.einsum("tij,vj->tvi", world, np.c_[head.points, np.ones(len(head.points))])[..., :3]
    # the node tree of the glTF, independently: Head node's world rest transform times the mesh node's TRS
    node = next(i for i, n in enumerate(g.nodes) if n.name == "Head" and n.mesh is not None)
    assert g.nodes[node].skin is None

    stage = Usd.Stage.Open(str(usd))
    anim = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Animation) and p.GetName() == "Wave")
    skel = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton))
    UsdSkel.BindingAPI(skel).GetAnimationSourceRel().SetTargets([anim.GetPath()])
    assert UsdSkel.BakeSkinning(stage.Traverse())
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(next(p.GetPath() for p in stage.Traverse() if p.GetName() == "Head_0")))
    tcps = stage.GetTimeCodesPerSecond()
    for f in (0, clip.num_frames // 2, clip.num_frames - 1):
        code = Usd.TimeCode(clip.start_time * tcps + f * tcps / clip.fps)
        x = np.array(mesh.ComputeLocalToWorldTransform(code)).T
        pts = np.asarray(mesh.GetPointsAttr().Get(code), dtype=np.float64) @ x[:3, :3].T + x[:3, 3]
        np.testing.assert_allclose(pts, expect[f], atol=1e-4)  # metres: 0.01 cm


def test_cesium_man_texture_comes_through_usdz_to_gltf_and_back(shared_assets, tmp_path, gltf_validator):
    src = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    glb, usd = tmp_path / "cesium.glb", tmp_path / "out" / "cesium.usda"
    usd.parent.mkdir()
    convert(src, glb)
    convert(glb, usd)
    assert gltf_validator(glb)[0]["numErrors"] == 0
    s = _summary(glb)
    assert (s["materials"], s["images"], s["vertices"]) == (1, 1, 3273)
    g = _gltf_json(glb)
    assert g["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"] == 0
    # the image bytes are the usdz's, in the glb and then in a file beside the USD output
    stage = Usd.Stage.Open(str(src))
    tex = next(p for p in stage.Traverse() if p.GetName() == "diffuseColor_texture")
    from pxr import Ar

    original = bytes(Ar.GetResolver().OpenAsset(Ar.ResolvedPath(tex.GetAttribute("inputs:file").Get().resolvedPath))
                     .GetBuffer())
    written = usd.parent / "cesium_textures" / "CesiumMan_img0.jpg"
    assert written.read_bytes() == original
    out = Usd.Stage.Open(str(usd))
    tex2 = next(p for p in out.Traverse() if p.GetName() == "baseColor_texture")
    assert tex2.GetAttribute("inputs:file").Get().path == "./cesium_textures/CesiumMan_img0.jpg"
    assert usd_compliance_errors(usd) == []
    assert _usd_counts(usd)["with_material"] == 1


def test_webxr_hand_material_round_trip(shared_assets, tmp_path, gltf_validator):
    src = shared_assets / "webxr_hand" / "left.glb"
    usd, back = tmp_path / "left.usdc", tmp_path / "left.gltf"
    convert(src, usd)
    convert(usd, back)
    a, b = _summary(src), _summary(back)
    assert (b["vertices"], b["materials"], b["meshes"]) == (a["vertices"], a["materials"], a["meshes"]) == (1360, 1, 1)
    ma, mb = _gltf_json(src)["materials"][0], _gltf_json(back)["materials"][0]
    assert mb["name"] == ma["name"]
    assert mb["pbrMetallicRoughness"]["roughnessFactor"] == pytest.approx(
        ma["pbrMetallicRoughness"]["roughnessFactor"], abs=1e-6)
    assert gltf_validator(back)[0]["numErrors"] == 0
    assert usd_compliance_errors(usd) == []


# -- a constructed file with every feature ------------------------------------------------

def _png(rgba) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGBA", (4, 4), tuple(rgba)).save(buf, "PNG")
    return buf.getvalue()


FPS = 30.0


def _scene(path: Path) -> dict:
    """Root > Child joints; a skinned quad (UVs, material with all five textures, MASK, double-sided);
    a rigid triangle below Child with two morph targets (default weights 0.25, 0); animations
    ``wave-01`` (STEP, rotation and weights) and ``spin`` (CUBICSPLINE)."""
    g = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"))
    g.buffers = [pygltflib.Buffer(byteLength=0)]
    app = BinaryAppender(g, 0)
    f32 = np.float32
    g.nodes = [pygltflib.Node(name="Root", children=[1], translation=[0.0, 1.0, 0.0]),
               pygltflib.Node(name="Child", children=[4], translation=[0.0, 0.5, 0.0]),
               pygltflib.Node(name="Quad", mesh=0, skin=0),
               pygltflib.Node(name="Hat", mesh=1)]
    g.nodes.append(pygltflib.Node(name="HatPivot", children=[3], translation=[0.1, 0.2, 0.0], scale=[2.0, 2.0, 2.0]))
    ibm = np.array([np.linalg.inv(m).T.reshape(-1) for m in
                    (np.array([[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1.0]]),
                     np.array([[1, 0, 0, 0], [0, 1, 0, 1.5], [0, 0, 1, 0], [0, 0, 0, 1.0]]))], dtype=f32)
    g.skins = [pygltflib.Skin(name="Rig", joints=[0, 1], inverseBindMatrices=app.add_accessor(ibm, "MAT4"))]
    quad = np.array([[-0.5, 1, 0], [0.5, 1, 0], [0.5, 2, 0], [-0.5, 2, 0]], dtype=f32)
    attrs = pygltflib.Attributes(
        POSITION=app.add_accessor(quad, "VEC3", min_max=True),
        NORMAL=app.add_accessor(np.tile(np.array([0, 0, 1], f32), (4, 1)), "VEC3"),
        TEXCOORD_0=app.add_accessor(np.array([[0, 1], [1, 1], [1, 0], [0, 0]], f32), "VEC2"),
        JOINTS_0=app.add_accessor(np.array([[0, 1, 0, 0]] * 2 + [[1, 0, 0, 0]] * 2, np.uint8), "VEC4"),
        WEIGHTS_0=app.add_accessor(np.array([[0.5, 0.5, 0, 0]] * 2 + [[1, 0, 0, 0]] * 2, f32), "VEC4"))
    idx = app.add_accessor(np.array([0, 1, 2, 0, 2, 3], np.uint16).reshape(-1, 1), "SCALAR")
    tri = np.array([[0, 0, 0], [0.2, 0, 0], [0, 0.2, 0]], dtype=f32)
    smile = np.array([[0, 0.05, 0], [0, 0, 0], [0, 0, 0]], dtype=f32)
    blink = np.array([[0, 0, 0], [0.05, 0, 0], [0, 0, 0.05]], dtype=f32)
    hat = pygltflib.Primitive(attributes=pygltflib.Attributes(POSITION=app.add_accessor(tri, "VEC3", min_max=True)),
                              material=1, targets=[
                                  pygltflib.Attributes(POSITION=app.add_accessor(smile, "VEC3", min_max=True)),
                                  pygltflib.Attributes(POSITION=app.add_accessor(blink, "VEC3", min_max=True))])
    g.meshes = [pygltflib.Mesh(name="QuadMesh", primitives=[pygltflib.Primitive(attributes=attrs, indices=idx,
                                                                                 material=0)]),
                pygltflib.Mesh(name="HatMesh", primitives=[hat], weights=[0.25, 0.0],
                               extras={"targetNames": ["Smile", "Blink"]})]
    colors = [(200, 30, 30, 255), (0, 128, 255, 255), (128, 128, 255, 255), (255, 255, 255, 255), (10, 200, 10, 255)]
    g.images = [pygltflib.Image(name=f"tex{i}", mimeType="image/png", bufferView=app.add_view(_png(c)))
                for i, c in enumerate(colors)]
    g.samplers = [pygltflib.Sampler(wrapS=33071, wrapT=33648)]
    g.textures = [pygltflib.Texture(source=i, sampler=0) for i in range(5)]
    g.materials = [
        pygltflib.Material(name="Skin Mat", alphaMode="MASK", alphaCutoff=0.3, doubleSided=True,
                           emissiveFactor=[0.5, 0.25, 0.0],
                           pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
                               baseColorFactor=[0.9, 0.8, 0.7, 0.6], metallicFactor=0.2, roughnessFactor=0.7,
                               baseColorTexture=pygltflib.TextureInfo(index=0),
                               metallicRoughnessTexture=pygltflib.TextureInfo(index=1)),
                           normalTexture=pygltflib.NormalMaterialTexture(index=2, scale=0.8),
                           occlusionTexture=pygltflib.OcclusionTextureInfo(index=3, strength=0.6),
                           emissiveTexture=pygltflib.TextureInfo(index=4)),
        pygltflib.Material(name="Plain", alphaMode="BLEND", pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
            baseColorFactor=[0.1, 0.2, 0.3, 0.5], metallicFactor=0.0, roughnessFactor=0.4))]
    t = (np.arange(6) / FPS).astype(f32).reshape(-1, 1)
    ang = np.radians([0, 20, 40, 60, 40, 20])
    rot = np.stack([np.sin(ang / 2), 0 * ang, 0 * ang, np.cos(ang / 2)], axis=1).astype(f32)
    w = np.array([[0, 0], [0.5, 0], [1, 0.2], [1, 0.4], [0.5, 1], [0, 0]], dtype=f32)
    t_in = app.add_accessor(t, "SCALAR", min_max=True)
    wave = pygltflib.Animation(name="wave-01", samplers=[
        pygltflib.AnimationSampler(input=t_in, output=app.add_accessor(rot, "VEC4"), interpolation="STEP"),
        pygltflib.AnimationSampler(input=t_in, output=app.add_accessor(w.reshape(-1, 1), "SCALAR"),
                                   interpolation="STEP")],
        channels=[pygltflib.AnimationChannel(sampler=0, target=pygltflib.AnimationChannelTarget(node=1, path="rotation")),
                  pygltflib.AnimationChannel(sampler=1, target=pygltflib.AnimationChannelTarget(node=3, path="weights"))])
    cubic = np.concatenate([np.zeros_like(rot), rot, np.zeros_like(rot)], axis=1).reshape(-1, 4)
    spin = pygltflib.Animation(name="spin", samplers=[
        pygltflib.AnimationSampler(input=t_in, output=app.add_accessor(cubic, "VEC4"), interpolation="CUBICSPLINE")],
        channels=[pygltflib.AnimationChannel(sampler=0, target=pygltflib.AnimationChannelTarget(node=0, path="rotation"))])
    g.animations = [wave, spin]
    g.scenes = [pygltflib.Scene(nodes=[0, 2])]
    g.scene = 0
    buffers: list[bytes] = []
    app.finish(buffers)
    save_gltf(g, buffers, path, glb=True)
    return {"weights": w, "colors": colors}


def test_constructed_scene_round_trips_every_feature(tmp_path, gltf_validator):
    src = tmp_path / "scene.glb"
    truth = _scene(src)
    assert gltf_validator(src)[0]["numErrors"] == 0
    usd, back = tmp_path / "scene.usda", tmp_path / "back.glb"
    assert convert(src, usd).notes == ()
    convert(usd, back)
    assert usd_compliance_errors(usd) == []
    assert gltf_validator(back)[0]["numErrors"] == 0
    a, b = _summary(src), _summary(back)
    for key in ("meshes", "primitives", "vertices", "materials", "images", "morph_targets", "target_names",
                "animations", "keys", "interpolation", "weights_channels"):
        assert b[key] == a[key], key
    assert a["interpolation"] == [["STEP"], ["CUBICSPLINE"]]

    # USD: textures written beside the output, each the source's PNG bytes
    folder = tmp_path / "scene_textures"
    assert sorted(p.name for p in folder.iterdir()) == [f"tex{i}.png" for i in range(5)]
    assert [(folder / f"tex{i}.png").read_bytes() for i in range(5)] == [_png(c) for c in truth["colors"]]
    stage = Usd.Stage.Open(str(usd))
    surface = UsdShade.Material(stage.GetPrimAtPath("/Root/Materials/Skin_Mat")).ComputeSurfaceSource()[0]
    assert surface.GetIdAttr().Get() == "UsdPreviewSurface"
    for name in ("diffuseColor", "opacity", "metallic", "roughness", "normal", "occlusion", "emissiveColor"):
        assert surface.GetInput(name).HasConnectedSource(), name
    assert surface.GetInput("opacityThreshold").Get() == pytest.approx(0.3)

    # glTF again: every material value as in the source
    ga, gb = _gltf_json(src), _gltf_json(back)
    for ma, mb in zip(ga["materials"], gb["materials"]):
        assert mb["name"] == ma["name"] and mb.get("alphaMode") == ma.get("alphaMode")
        assert mb.get("doubleSided", False) == ma.get("doubleSided", False)
        assert mb.get("alphaCutoff", 0.5) == pytest.approx(ma.get("alphaCutoff", 0.5))
        np.testing.assert_allclose(mb.get("emissiveFactor", [0, 0, 0]), ma.get("emissiveFactor", [0, 0, 0]), atol=1e-6)
        pa, pb = ma["pbrMetallicRoughness"], mb["pbrMetallicRoughness"]
        np.testing.assert_allclose(pb["baseColorFactor"], pa["baseColorFactor"], atol=1e-6)
        for k in ("metallicFactor", "roughnessFactor"):
            assert pb[k] == pytest.approx(pa[k], abs=1e-6)
        for k in ("baseColorTexture", "metallicRoughnessTexture"):
            assert (k in pb) == (k in pa)
        for k, s in (("normalTexture", "scale"), ("occlusionTexture", "strength")):
            assert (k in mb) == (k in ma)
            if k in ma:
                assert mb[k][s] == pytest.approx(ma[k][s], abs=1e-6)
    assert [(s["wrapS"], s["wrapT"]) for s in gb["samplers"]] == [(33071, 33648)]
    images = [bytes(read_asset(back).images[i].content()) for i in range(5)]
    assert images == [_png(c) for c in truth["colors"]]
    assert gb["meshes"][1]["weights"] == [0.25, 0.0]
    # morph weights animated exactly at the keys, STEP kept
    asset = read_asset(back)
    np.testing.assert_allclose(asset.blend_shape_weights["wave-01"].weights, truth["weights"], atol=1e-6)
    assert asset.blend_shape_weights["wave-01"].names == ("Smile", "Blink")
    assert asset.interpolation == {"wave-01": "STEP", "spin": "CUBICSPLINE"}
    # the rigid hat is a mesh node below the Child joint again, with its pivot folded in
    hat = next(n for n in gb["nodes"] if n.get("mesh") == 1)
    child = next(n for n in gb["nodes"] if n.get("name") == "Child")
    assert gb["nodes"].index(hat) in child["children"] and "skin" not in hat
    np.testing.assert_allclose(hat["translation"], [0.1, 0.2, 0.0], atol=1e-6)
    np.testing.assert_allclose(hat["scale"], [2.0, 2.0, 2.0], atol=1e-6)


def test_animation_option_picks_one_and_keeps_its_weights(tmp_path):
    src = tmp_path / "scene.glb"
    truth = _scene(src)
    usd = tmp_path / "one.usda"
    result = convert(src, usd, ConvertOptions(animation="wave-01"))
    assert [a["name"] for a in result.animations] == ["wave-01"]
    asset = read_asset(usd)
    (clip,) = asset.clips
    assert asset.source_names[clip.name] == "wave-01"
    np.testing.assert_allclose(asset.blend_shape_weights[clip.name].weights, truth["weights"], atol=1e-6)


@pytest.mark.parametrize("middle", [".usda", None])
def test_source_nodes_above_the_skin_stay_plain_nodes(shared_assets, tmp_path, middle, gltf_validator):
    """RobotArmature (scale 100, -90° about x) is a node above the skin's joints in the source; it comes
    back as such (not a skin joint: Blender's importer makes every skin joint a bone, and a bone cannot
    hold that scale, which put the rigid parts up to 58 cm off), through USD (an Xform above the
    SkelRoot there) and glTF -> glTF alike."""
    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    back = tmp_path / "back.glb"
    if middle:
        convert(src, tmp_path / f"mid{middle}")
        convert(tmp_path / f"mid{middle}", back)
    else:
        convert(src, back)
    assert gltf_validator(back)[0]["numErrors"] == 0
    ga, gb = pygltflib.GLTF2().load(str(src)), pygltflib.GLTF2().load(str(back))
    names = lambda g, skin: [g.nodes[n].name for n in skin.joints]  # noqa: E731
    assert names(gb, gb.skins[0]) == names(ga, ga.skins[0])
    arm = next(n for n in gb.nodes if n.name == "RobotArmature")
    assert gb.nodes.index(arm) not in gb.skins[0].joints
    np.testing.assert_allclose(arm.scale, [100, 100, 100], rtol=1e-6)
    assert [gb.nodes[c].name for c in arm.children] == ["Bone"]  # the root joint, as in the source
    a, b = read_asset(src), read_asset(back)
    for ca, cb in zip(a.clips, b.clips):
        np.testing.assert_allclose(cb.world_positions(), ca.world_positions(), atol=1e-5)


def test_usd_material_subsets_become_primitives_of_one_mesh(tmp_path, gltf_validator):
    """A skinned USD Mesh with two ``materialBind`` GeomSubsets (Blender's USD export of a mesh with
    two material slots) becomes one glTF mesh with one primitive per material, each with the
    vertices its faces use."""
    from pxr import Gf, Sdf, UsdGeom, Vt

    usd = tmp_path / "subsets.usda"
    stage = Usd.Stage.CreateNew(str(usd))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdSkel.Root.Define(stage, "/Char")
    stage.SetDefaultPrim(root.GetPrim())
    skel = UsdSkel.Skeleton.Define(stage, "/Char/Skel")
    skel.CreateJointsAttr(["Hips", "Hips/Spine"])
    eye = Gf.Matrix4d(1)
    up = Gf.Matrix4d().SetTranslate(Gf.Vec3d(0, 1, 0))
    skel.CreateBindTransformsAttr([eye, up])
    skel.CreateRestTransformsAttr([eye, up])
    mesh = UsdGeom.Mesh.Define(stage, "/Char/Body")
    pts = [(-1, 0, 0), (1, 0, 0), (1, 1, 0), (-1, 1, 0), (1, 2, 0), (-1, 2, 0)]
    mesh.CreatePointsAttr(pts)
    mesh.CreateFaceVertexCountsAttr([4, 4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3, 3, 2, 4, 5])
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(False, 1).Set(Vt.IntArray([0, 0, 1, 1, 1, 1]))
    binding.CreateJointWeightsPrimvar(False, 1).Set(Vt.FloatArray([1.0] * 6))
    binding.CreateGeomBindTransformAttr(eye)
    colours = {"Red": (1.0, 0.0, 0.0), "Blue": (0.0, 0.0, 1.0)}
    for face, (name, rgb) in enumerate(colours.items()):
        mat = UsdShade.Material.Define(stage, f"/Char/Looks/{name}")
        shader = UsdShade.Shader.Define(stage, f"/Char/Looks/{name}/Surface")
        shader.CreateIdAttr("UsdPreviewSurface")
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*rgb))
        mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        subset = UsdGeom.Subset.CreateGeomSubset(mesh, name, UsdGeom.Tokens.face, Vt.IntArray([face]),
                                                  UsdShade.Tokens.materialBind)
        UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(mat)
    stage.GetRootLayer().Save()

    glb = tmp_path / "subsets.glb"
    assert convert(usd, glb).notes == ()
    assert gltf_validator(glb)[0]["numErrors"] == 0
    g = _gltf_json(glb)
    assert len(g["meshes"]) == 1 and g["meshes"][0]["name"] == "Body"
    prims = g["meshes"][0]["primitives"]
    assert [g["accessors"][p["attributes"]["POSITION"]]["count"] for p in prims] == [4, 4]
    assert [g["materials"][p["material"]]["name"] for p in prims] == ["Red", "Blue"]
    assert [m["pbrMetallicRoughness"]["baseColorFactor"][:3] for m in g["materials"]] == [[1, 0, 0], [0, 0, 1]]


@pytest.mark.parametrize("interpolation", ["LINEAR", "STEP"])
def test_sparse_keys_come_back_as_the_same_keys(tmp_path, gltf_validator, interpolation):
    """A hand-keyed animation (keys at 0, 0.5, 1 and 2 s) is sampled per frame in USD (61 frames at
    30 fps) and keyed at the same 4 times with the same values back in glTF."""
    g = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"))
    g.buffers = [pygltflib.Buffer(byteLength=0)]
    app = BinaryAppender(g, 0)
    g.nodes = [pygltflib.Node(name="Root", children=[1]), pygltflib.Node(name="Tip", translation=[0.0, 1.0, 0.0]),
               pygltflib.Node(name="Body", mesh=0, skin=0)]
    ibm = np.array([np.eye(4).reshape(-1), np.linalg.inv(np.array(
        [[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1.0]])).T.reshape(-1)], dtype=np.float32)
    g.skins = [pygltflib.Skin(joints=[0, 1], inverseBindMatrices=app.add_accessor(ibm, "MAT4"))]
    tri = np.array([[0, 0, 0], [0.1, 1, 0], [0, 1, 0.1]], dtype=np.float32)
    g.meshes = [pygltflib.Mesh(name="Body", primitives=[pygltflib.Primitive(attributes=pygltflib.Attributes(
        POSITION=app.add_accessor(tri, "VEC3", min_max=True),
        JOINTS_0=app.add_accessor(np.array([[0, 0, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0]], np.uint8), "VEC4"),
        WEIGHTS_0=app.add_accessor(np.array([[1, 0, 0, 0]] * 3, np.float32), "VEC4")))])]
    times = np.array([0.0, 0.5, 1.0, 2.0], dtype=np.float32)
    ang = np.radians([0.0, 30.0, -20.0, 45.0])
    rot = np.stack([0 * ang, 0 * ang, np.sin(ang / 2), np.cos(ang / 2)], axis=1).astype(np.float32)
    g.animations = [pygltflib.Animation(name="keyed", samplers=[pygltflib.AnimationSampler(
        input=app.add_accessor(times.reshape(-1, 1), "SCALAR", min_max=True), output=app.add_accessor(rot, "VEC4"),
        interpolation=interpolation)], channels=[pygltflib.AnimationChannel(
            sampler=0, target=pygltflib.AnimationChannelTarget(node=1, path="rotation"))])]
    g.scenes = [pygltflib.Scene(nodes=[0, 2])]
    g.scene = 0
    buffers: list[bytes] = []
    app.finish(buffers)
    src = tmp_path / "keyed.glb"
    save_gltf(g, buffers, src, glb=True)

    usd, back = tmp_path / "keyed.usda", tmp_path / "back.glb"
    convert(src, usd)
    assert read_asset(usd).clips[0].num_frames == 61
    convert(usd, back)
    assert gltf_validator(back)[0]["numErrors"] == 0
    gb = pygltflib.GLTF2().load(str(back))
    anim = gb.animations[0]
    tip = next(i for i, n in enumerate(gb.nodes) if n.name == "Tip")
    ch = next(c for c in anim.channels if c.target.node == tip and c.target.path == "rotation")
    doc = load_gltf(back)
    smp = anim.samplers[ch.sampler]
    assert smp.interpolation == interpolation
    np.testing.assert_allclose(doc.accessor(smp.input)[:, 0], times, atol=1e-6)
    got = doc.accessor(smp.output)
    got = got * np.sign(np.sum(got * rot, axis=1))[:, None]
    np.testing.assert_allclose(got, rot, atol=1e-6)


def test_missing_texture_file_is_named_and_the_rest_converts(tmp_path, caplog):
    src = tmp_path / "scene.glb"
    _scene(src)
    g = pygltflib.GLTF2().load(str(src))
    g.images[0] = pygltflib.Image(uri="missing.png")
    gltf = tmp_path / "scene.gltf"
    g.convert_buffers(pygltflib.BufferFormat.DATAURI)
    g.save_json(str(gltf))
    with caplog.at_level("WARNING", logger="usdhands"):
        convert(gltf, tmp_path / "out.usda")
    asset = read_asset(tmp_path / "out.usda")
    assert len(asset.materials) == 2 and "baseColor" not in asset.materials[0].textures
    assert len(asset.images) == 4
    warned = [r.getMessage() for r in caplog.records if "not converted" in r.getMessage()]
    assert len(warned) == 1 and "image 0 (image file 'missing.png' cannot be read" in warned[0]


def test_usd_texture_file_missing_is_named(tmp_path, caplog):
    src = tmp_path / "scene.glb"
    _scene(src)
    usd = tmp_path / "scene.usda"
    convert(src, usd)
    (tmp_path / "scene_textures" / "tex1.png").unlink()
    with caplog.at_level("WARNING", logger="usdhands"):
        convert(usd, tmp_path / "back.glb")
    warned = [r.getMessage() for r in caplog.records if "not converted" in r.getMessage()]
    assert len(warned) == 1 and "1 texture file(s) not found (./scene_textures/tex1.png)" in warned[0]
    assert len(read_asset(tmp_path / "back.glb").images) == 4


def test_mesh_on_no_skeleton_comes_through_as_a_static_mesh(shared_assets, tmp_path, gltf_validator):
    """A prop node beside the character (no joint above it) is a static Mesh with its transform in USD
    and a mesh node at the scene root again in glTF, where the source puts it."""
    src = tmp_path / "robot_prop.glb"
    g = pygltflib.GLTF2().load(str(shared_assets / "robot_expressive" / "RobotExpressive.glb"))
    g.nodes.append(pygltflib.Node(name="Prop", mesh=0, translation=[2.0, 0.5, 0.0], scale=[3.0, 3.0, 3.0]))
    g.scenes[g.scene or 0].nodes.append(len(g.nodes) - 1)
    g.save_binary(str(src))
    usd, back = tmp_path / "prop.usda", tmp_path / "back.glb"
    assert convert(src, usd).meshes == 20
    convert(usd, back)
    assert usd_compliance_errors(usd) == []
    assert gltf_validator(back)[0]["numErrors"] == 0
    stage = Usd.Stage.Open(str(usd))
    from pxr import UsdGeom

    prop = UsdGeom.Mesh(next(p for p in stage.Traverse() if p.GetCustomDataByKey("usdhands:sourceNode") == "Prop"))
    assert prop.GetPath().GetParentPath() == "/Root"
    assert not prop.GetPrim().HasAPI(UsdSkel.BindingAPI)
    x = np.array(prop.ComputeLocalToWorldTransform(Usd.TimeCode.Default())).T
    np.testing.assert_allclose(x[:3, 3], [2.0, 0.5, 0.0], atol=1e-9)
    a, b = _summary(src), _summary(back)
    # the prop's node uses the foot's mesh in the source; it is a mesh of its own after the round trip
    assert (a["meshes"], a["vertices"]) == (14, 7214) and (b["meshes"], b["vertices"]) == (15, 7214 + 64)
    gb = _gltf_json(back)
    node = next(n for n in gb["nodes"] if n.get("name") == "Prop")
    assert gb["nodes"].index(node) in gb["scenes"][0]["nodes"] and "skin" not in node
    np.testing.assert_allclose(node["translation"], [2.0, 0.5, 0.0], atol=1e-9)
    np.testing.assert_allclose(node["scale"], [3.0, 3.0, 3.0], atol=1e-9)


# -- texture files written atomically (issue 8) --------------------------------------------

def test_two_threads_writing_one_usd_output_both_write_its_textures(tmp_path, monkeypatch):
    """Textures went through the fixed temporary name .NAME.tmpPID: two threads of one process (stage
    hooks, Dask with processes=False) writing the same output shared it, and the second rename found
    no file (FileNotFoundError). Each texture's rename waits here until both writers reach it."""
    src = tmp_path / "scene.glb"
    truth = _scene(src)
    asset = read_asset(src)
    out = tmp_path / "out.usda"
    together = threading.Barrier(2, timeout=60)
    replace = os.replace

    def replace_together(a, b):
        if Path(b).suffix == ".png":
            together.wait()
        return replace(a, b)

    monkeypatch.setattr(os, "replace", replace_together)
    errors = []

    def write():
        try:
            write_asset(asset, out)
        except BaseException as e:  # noqa: BLE001  (reported by the assert below)
            errors.append(e)

    threads = [threading.Thread(target=write) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    folder = tmp_path / "out_textures"
    assert listing(tmp_path) == sorted(["scene.glb", "out.usda", "out_textures",
                                        *(f"out_textures/tex{i}.png" for i in range(5))])
    assert [(folder / f"tex{i}.png").read_bytes() for i in range(5)] == [_png(c) for c in truth["colors"]]
    assert len(read_asset(out).images) == 5


def test_texture_writes_leave_a_file_named_like_their_old_temporary_alone(tmp_path):
    """The fixed temporary name overwrote a user's file '.tex0.png.tmpPID' and renamed it away."""
    src = tmp_path / "scene.glb"
    _scene(src)
    folder = tmp_path / "out_textures"
    folder.mkdir()
    keep = folder / f".tex0.png.tmp{os.getpid()}"
    keep.write_text("the user's own file\n")
    convert(src, tmp_path / "out.usda")
    assert keep.read_text() == "the user's own file\n"
    assert sorted(p.name for p in folder.iterdir()) == [keep.name, *(f"tex{i}.png" for i in range(5))]


@pytest.mark.parametrize("blocked", ["tex0.png", "tex3.png"])
def test_texture_that_cannot_be_written_leaves_nothing(tmp_path, blocked):
    """A folder where a texture goes: the rename failed and the temporary .tex0.png.tmpPID was left; the
    textures written before it (tex0-tex2) stayed beside the output that was not written."""
    src = tmp_path / "scene.glb"
    _scene(src)
    blocked = tmp_path / "out_textures" / blocked
    blocked.mkdir(parents=True)
    (tmp_path / "out_textures" / "notes.txt").write_text("the user's own file\n")
    check_promise(["convert", src, tmp_path / "out.usda"], folder=tmp_path, inputs=[src], names=blocked,
                  message="is a folder")


def test_a_failed_usd_write_takes_the_texture_folder_it_made_with_it(tmp_path, monkeypatch):
    """An error after the textures were written (here: saving the layer) left them, and their folder,
    beside an output that was never written."""
    from pxr import Sdf

    src = tmp_path / "scene.glb"
    _scene(src)
    asset = read_asset(src)

    def refuse(self, *args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(Sdf.Layer, "Export", refuse)
    monkeypatch.setattr(Sdf.Layer, "Save", refuse)
    with pytest.raises(OSError, match="disk full"):
        write_asset(asset, tmp_path / "out.usda")
    assert listing(tmp_path) == ["scene.glb"]


def test_atomic_write_bytes_gives_the_mode_of_a_plain_open_and_leaves_nothing_on_failure(tmp_path):
    """The texture writer's one-open atomic write: the file gets what ``open()`` under the umask
    gives (mkstemp's 0600 would fail it), the old bytes stay when the write fails (a str is not
    bytes: TypeError inside the write), and no temporary file is left either way."""
    from usdhands.errors import OutputPathError
    from usdhands.formats.registry import atomic_write_bytes

    target, plain = tmp_path / "tex.png", tmp_path / "plain.png"
    old = os.umask(0o027)
    try:
        atomic_write_bytes(target, b"\x89PNG first")
        plain.write_bytes(b"x")
    finally:
        os.umask(old)
    assert target.read_bytes() == b"\x89PNG first"
    assert (target.stat().st_mode & 0o777) == (plain.stat().st_mode & 0o777) == 0o640
    atomic_write_bytes(target, b"second")
    assert target.read_bytes() == b"second"
    with pytest.raises(TypeError):
        atomic_write_bytes(target, "not bytes")
    assert target.read_bytes() == b"second"
    assert listing(tmp_path) == ["plain.png", "tex.png"]
    with pytest.raises(OutputPathError, match="cannot write into folder"):
        atomic_write_bytes(tmp_path / "missing" / "tex.png", b"x")
    with pytest.raises(OutputPathError, match="is a folder"):
        atomic_write_bytes(tmp_path, b"x")
    assert listing(tmp_path) == ["plain.png", "tex.png"]


@pytest.mark.parametrize("resolving", [False, True])
def test_a_texture_that_would_overwrite_the_input_is_refused(tmp_path, monkeypatch, resolving):
    """A texture's target that is the input file itself, or a symbolic link to it, is refused; a hard link
    to it (another path to the same file, which the resolved paths do not show) and any other file are
    written over, as before the files' identities were compared first (``resolving``: with that shortcut
    off, the resolved paths alone decide)."""
    import dataclasses

    import usdhands.formats.usd_materials as materials

    if resolving:
        monkeypatch.setattr(materials, "_file_ids", lambda paths: None)
    src = tmp_path / "scene.glb"
    _scene(src)
    asset = read_asset(src)
    out = tmp_path / "out.usda"
    write_asset(asset, out)
    target = tmp_path / "out_textures" / "tex0.png"
    before = target.read_bytes()
    for name, make in (("same", None), ("symlink", os.symlink), ("hardlink", os.link), ("other", None)):
        source = target
        if make is not None:
            source = tmp_path / f"{name}.png"
            make(target, source)
        elif name == "other":
            source = tmp_path / "other.png"
            source.write_bytes(b"another file")
        pretend = dataclasses.replace(asset, path=str(source))
        if name in ("same", "symlink"):
            with pytest.raises(ValueError, match=f"texture {target} would overwrite an input"):
                write_asset(pretend, out)
            assert target.read_bytes() == before
        else:
            write_asset(pretend, out)
            assert target.exists() and target.stat().st_ino != source.stat().st_ino

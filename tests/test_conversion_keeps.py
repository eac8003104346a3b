"""What a glTF -> USD -> glTF conversion keeps, on third-party files: the table of docs/format-usd.md.

Skinned meshes (count, vertices, faces), animation names (also names USD cannot hold
as prim names), frame counts and rates survive; what is left out is named in
``Asset.left_out`` and identical before and after.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from usdhands.jobs.conversion import convert
from usdhands.formats.io import read_asset, write_asset
from usdhands.model import Clip, Skeleton
from usdhands.model.asset import Asset

FILES = ["robot_expressive/RobotExpressive.glb", "webxr_hand/left.glb", "usd_cesiumman/CesiumMan.usdz"]


@pytest.mark.parametrize("name", FILES)
def test_round_trip_keeps_meshes_animations_and_names(shared_assets, tmp_path, gltf_validator, name):
    src = shared_assets / name
    mid = tmp_path / ("mid.usda" if src.suffix == ".glb" else "mid.glb")
    back = tmp_path / ("back.glb" if src.suffix == ".glb" else "back.usda")
    convert(src, mid)
    convert(mid, back)
    a, b = read_asset(src), read_asset(back)
    assert len(b.meshes) == len(a.meshes)
    for ma, mb in zip(a.meshes, b.meshes):
        assert ma.points.shape == mb.points.shape and ma.name.rsplit("/", 1)[-1] == mb.name.rsplit("/", 1)[-1]
        assert np.asarray(mb.face_vertex_counts).sum() == np.asarray(ma.face_vertex_counts).sum()
    short = lambda c: c.name.rsplit("/", 1)[-1]  # noqa: E731
    assert [short(c) for c in b.clips] == [short(c) for c in a.clips]
    assert [(c.num_frames, c.fps) for c in b.clips] == [(c.num_frames, c.fps) for c in a.clips]
    if back.suffix == ".glb":
        assert gltf_validator(back)[0]["numErrors"] == 0


def test_names_usd_cannot_hold_come_back(tmp_path):
    sk = Skeleton(["mixamorig:Hips", "mixamorig:Hips/mixamorig:Spine"], [-1, 0], [[0, 1, 0], [0, 0.2, 0]],
                  np.tile([0, 0, 0, 1.0], (2, 1)))
    rot = np.tile([0, 0, 0, 1.0], (4, 2, 1))
    names = ["dance-01", "mixamo.com|Take 001", "Idle"]
    glb = write_asset(Asset("mem", (sk,), tuple(Clip(sk, 30, rot, name=n) for n in names)), tmp_path / "a.glb")
    usd = tmp_path / "b.usda"
    back = tmp_path / "c.gltf"
    convert(glb, usd)
    convert(usd, back)
    mid = read_asset(usd)
    assert [c.name.rsplit("/", 1)[-1] for c in mid.clips] == ["dance_01", "mixamo_com_Take_001", "Idle"]
    assert [mid.source_names.get(c.name) for c in mid.clips] == ["dance-01", "mixamo.com|Take 001", None]
    assert [a["name"] for a in json.loads(back.read_text())["animations"]] == names
    assert [n.rsplit("/", 1)[-1] for n in read_asset(back).skeletons[0].joint_names] == \
        ["mixamorig:Hips", "mixamorig:Spine"]
    # UsdSkel's jointNames holds the names too: a file without usdhands' customData reads them back
    from pxr import Usd, UsdSkel

    stage = Usd.Stage.Open(str(usd))
    skel = next(UsdSkel.Skeleton(p) for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton))
    assert list(skel.GetJointNamesAttr().Get()) == ["mixamorig:Hips", "mixamorig:Spine"]
    skel.GetPrim().ClearCustomDataByKey("usdhands:sourceJointNames")
    stage.GetRootLayer().Export(str(tmp_path / "jointnames_only.usda"))
    assert list(read_asset(tmp_path / "jointnames_only.usda").skeletons[0].joint_names) == \
        ["mixamorig:Hips", "mixamorig:Hips/mixamorig:Spine"]


@pytest.mark.parametrize("name", ["robot_expressive/RobotExpressive.glb", "usd_cesiumman/CesiumMan.usdz"])
def test_skinned_mesh_bbox_usdskel_bake_matches_numpy_lbs(shared_assets, tmp_path, name):
    """The converted USD deformed by UsdSkel's own BakeSkinning has the bounding box that linear
    blend skinning of the glTF's meshes (numpy, from the glTF side) gives, within 0.1 cm, at several
    frames of the bound animation."""
    from pxr import Usd, UsdGeom, UsdSkel

    src = shared_assets / name
    gltf = src if src.suffix == ".glb" else tmp_path / "src.glb"
    if gltf != src:
        convert(src, gltf)
    usd = tmp_path / "conv.usda"
    convert(gltf, usd)
    asset = read_asset(gltf)
    clip = asset.clips[0]
    sk = clip.skeleton
    world = clip.world_xforms()                                       # (T, J, 4, 4)
    inv_bind = np.linalg.inv(sk.bind_xforms)                          # (J, 4, 4)
    frames = np.unique(np.linspace(0, clip.num_frames - 1, 5).round().astype(int))

    stage = Usd.Stage.Open(str(usd))
    tcps = stage.GetTimeCodesPerSecond()
    assert UsdSkel.BakeSkinning(stage.Traverse())
    baked = [UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    assert len(baked) == len(asset.meshes)
    for f in frames:
        lbs = []
        for m in asset.meshes:
            p = np.c_[m.points, np.ones(len(m.points))] @ m.geom_bind_xform.T  # skeleton (bind) space
            skin = world[f] @ inv_bind                                     # (J, 4, 4)
            out = np.zeros((len(p), 4))
            for k in range(m.joint_indices.shape[1]):
                out += m.joint_weights[:, k, None] * np.einsum("vij,vj->vi", skin[m.joint_indices[:, k]], p)
            lbs.append(out[:, :3])
        lbs = np.concatenate(lbs)
        code = Usd.TimeCode(clip.start_time * tcps + f * tcps / clip.fps)
        pts = []
        for mesh in baked:
            x = np.array(mesh.ComputeLocalToWorldTransform(code)).T
            q = np.asarray(mesh.GetPointsAttr().Get(code), dtype=np.float64)
            pts.append(q @ x[:3, :3].T + x[:3, 3])
        pts = np.concatenate(pts)
        np.testing.assert_allclose(pts.min(axis=0), lbs.min(axis=0), atol=1e-3)  # metres: 0.1 cm
        np.testing.assert_allclose(pts.max(axis=0), lbs.max(axis=0), atol=1e-3)

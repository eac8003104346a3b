"""``usdhands convert``: glTF <-> USD <-> BVH through the command line, meshes included."""

from __future__ import annotations

import numpy as np
import pytest

from usdhands.cli import main
from usdhands.formats.io import read_asset
from usdhands.formats.usd_validate import usd_compliance_errors
from usdhands.model import Clip, Skeleton
from usdhands.model.asset import Asset, SkinnedMesh
from usdhands.model.rotations import quat_angle_deg
from usdhands.formats.io import write_asset


def convert(capsys, src, dst, *extra) -> str:
    code = main(["convert", str(src), str(dst), *map(str, extra)])
    err = capsys.readouterr().err
    assert code == 0, err
    return err


def assert_same_motion(a: Clip, b: Clip, rot_rad=1e-4, trans_rel=1e-5):
    assert b.num_frames == a.num_frames and b.fps == pytest.approx(a.fps)
    idx = [b.skeleton.index(n) for n in a.skeleton.joint_names]
    angle = np.radians(quat_angle_deg(a.rotations, b.rotations[:, idx]))
    assert angle.max() < rot_rad
    scale = max(1.0, np.abs(a.skeleton.rest_translations).max())
    assert np.abs(a.translations - b.translations[:, idx]).max() < trans_rel * scale


def test_gltf_usd_gltf_round_trip_keeps_motion_and_meshes(shared_assets, tmp_path, capsys, gltf_validator):
    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    usd = tmp_path / "robot.usdc"
    back = tmp_path / "robot.glb"
    convert(capsys, src, usd)
    assert usd_compliance_errors(usd) == []
    convert(capsys, usd, back)
    assert gltf_validator(back)[0]["numErrors"] == 0
    a, b = read_asset(src), read_asset(back)
    assert [c.name for c in b.clips] == [c.name for c in a.clips]
    sa, sb = a.skeletons[0], b.skeletons[0]
    # RobotArmature (a static node above the skin's joints) is an Xform above the SkelRoot in
    # USD and a plain node above the skin's joints again in glTF: the same joints come back
    assert sb.joint_names == sa.joint_names
    common = [n for n in sa.joint_names if n in sb.joint_names]
    ia, ib = [sa.index(n) for n in common], [sb.index(n) for n in common]
    inner = [k for k, j in enumerate(ib) if sb.parents[j] >= 0]
    scale = np.abs(sa.bind_xforms[:, :3, 3]).max()
    np.testing.assert_allclose(sb.bind_xforms[ib], sa.bind_xforms[ia], atol=1e-6 * scale)  # inverse bind matrices
    np.testing.assert_allclose(sb.rest_translations[ib][inner], sa.rest_translations[ia][inner], atol=1e-6 * scale)
    for ca, cb in zip(a.clips, b.clips):
        assert cb.num_frames == ca.num_frames and cb.fps == pytest.approx(ca.fps)
        extent = np.ptp(ca.world_positions().reshape(-1, 3), axis=0).max()  # float32 in USD
        np.testing.assert_allclose(cb.world_positions()[:, ib], ca.world_positions()[:, ia], atol=1e-5 * extent)
        angle = np.radians(quat_angle_deg(ca.rotations[:, ia][:, inner], cb.rotations[:, ib][:, inner]))
        assert angle.max() < 1e-4
    # 4 skinned primitives and 15 rigid ones (mesh nodes below joints), all 7,214 vertices
    assert len(b.meshes) == len(a.meshes) == 19
    assert sum(len(m.points) for m in b.meshes) == 7214
    for ma, mb in zip(a.meshes, b.meshes):
        np.testing.assert_allclose(mb.points, ma.points, atol=1e-5)
        np.testing.assert_allclose(mb.normals, ma.normals, atol=1e-5)
        assert (ma.uvs is None) == (mb.uvs is None)
        if ma.uvs is not None:
            np.testing.assert_allclose(mb.uvs, ma.uvs, atol=1e-6)
        names_a = np.array(a.skeletons[0].joint_names)[ma.joint_indices]
        names_b = np.array(b.skeletons[0].joint_names)[mb.joint_indices]
        assert (names_a == names_b)[ma.joint_weights > 0].all()
        np.testing.assert_allclose(mb.joint_weights, ma.joint_weights, atol=1e-6)
        np.testing.assert_allclose(mb.geom_bind_xform, ma.geom_bind_xform, atol=1e-9)


def test_one_animation_by_name(shared_assets, tmp_path, capsys):
    out = tmp_path / "wave.usda"
    convert(capsys, shared_assets / "robot_expressive" / "RobotExpressive.glb", out, "--animation", "Wave")
    clips = read_asset(out).clips
    assert [c.name.rsplit("/", 1)[-1] for c in clips] == ["Wave"]


def test_bvh_to_gltf_converts_centimetres_to_metres(shared_assets, tmp_path, capsys, gltf_validator):
    src = shared_assets / "leap_hands" / "fingers-ok.bvh"
    out = tmp_path / "ok.glb"
    convert(capsys, src, out)
    assert gltf_validator(out)[0]["numErrors"] == 0
    a, b = read_asset(src).clips[0], read_asset(out).clips[0]
    assert a.skeleton.meters_per_unit == 0.01 and b.skeleton.meters_per_unit == 1.0
    idx = [b.skeleton.index(n) for n in a.skeleton.joint_names]
    np.testing.assert_allclose(b.world_positions()[:, idx], a.world_positions() * 0.01, atol=1e-6)
    # and back to BVH, in centimetres again
    bvh = tmp_path / "ok.bvh"
    convert(capsys, out, bvh)
    c = read_asset(bvh).clips[0]
    idx = [c.skeleton.index(n) for n in a.skeleton.joint_names]
    np.testing.assert_allclose(c.world_positions()[:, idx], a.world_positions(), atol=1e-3)


def test_z_up_usd_to_gltf_is_y_up(tmp_path, capsys):
    sk = Skeleton(["Hips", "Hips/Head"], [-1, 0], [[0, 0, 100], [0, 0, 60]], np.tile([0, 0, 0, 1.0], (2, 1)),
                  meters_per_unit=0.01, up_axis="Z")
    src = write_asset(Asset("mem", (sk,), (Clip(sk, 24, np.tile([0, 0, 0, 1.0], (3, 2, 1)), name="Anim"),)),
                      tmp_path / "zup.usda")
    out = tmp_path / "yup.glb"
    convert(capsys, src, out)
    head = read_asset(out).clips[0].world_positions()[0, 1]
    np.testing.assert_allclose(head, [0, 1.6, 0], atol=1e-6)
    # to BVH: centimetres, +Y; to BVH in inches
    convert(capsys, src, tmp_path / "yup.bvh")
    np.testing.assert_allclose(read_asset(tmp_path / "yup.bvh").clips[0].world_positions()[0, 1], [0, 160, 0],
                               atol=1e-5)
    convert(capsys, src, tmp_path / "yup_in.bvh", "--bvh-units", "in")
    np.testing.assert_allclose(read_asset(tmp_path / "yup_in.bvh", units="in").clips[0].world_positions()[0, 1],
                               [0, 160 / 2.54, 0], atol=1e-5)


def test_mesh_with_six_influences_survives_usd_and_gltf(tmp_path, capsys, gltf_validator):
    J = 7
    names = ["root"] + [f"root/b{i}" for i in range(1, J)]
    sk = Skeleton(names, [-1] + [0] * (J - 1), np.r_[[[0, 0, 0]], np.eye(3)[np.arange(J - 1) % 3]],
                  np.tile([0, 0, 0, 1.0], (J, 1)), bind_xforms=None)
    bind = np.tile(np.eye(4), (J, 1, 1))
    bind[:, :3, 3] = sk.rest_world_positions()
    sk = Skeleton(sk.joint_names, sk.parents, sk.rest_translations, sk.rest_rotations, bind_xforms=bind)
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(4, 3))
    idx = np.array([rng.permutation(J)[:6] for _ in range(4)])
    w = rng.uniform(0.1, 1, size=(4, 6))
    w /= w.sum(axis=1, keepdims=True)
    mesh = SkinnedMesh("blob", pts, np.array([3, 3]), np.array([0, 1, 2, 0, 2, 3]),
                       normals=np.tile([0, 0, 1.0], (4, 1)), uvs=rng.uniform(size=(4, 2)),
                       joint_indices=idx, joint_weights=w)
    rot = np.tile([0, 0, 0, 1.0], (5, J, 1))
    src = write_asset(Asset("mem", (sk,), (Clip(sk, 30, rot, name="A"),), (mesh,)), tmp_path / "six.usda")
    glb = tmp_path / "six.glb"
    convert(capsys, src, glb)
    assert gltf_validator(glb)[0]["numErrors"] == 0
    usd = tmp_path / "six_back.usda"
    convert(capsys, glb, usd)
    for path in (glb, usd):
        m = read_asset(path).meshes[0]
        dense = np.zeros((4, J))
        np.add.at(dense, (np.arange(4)[:, None], m.joint_indices), m.joint_weights)  # padding adds 0
        ref = np.zeros((4, J))
        np.add.at(ref, (np.arange(4)[:, None], idx), w)
        np.testing.assert_allclose(dense, ref, atol=1e-6)


def test_bvh_units_option_reads_and_writes_other_units(shared_assets, tmp_path, capsys):
    src = shared_assets / "leap_hands" / "fingers-ok.bvh"
    in_cm = read_asset(src).clips[0]
    glb = tmp_path / "ok_mm.glb"
    convert(capsys, src, glb, "--bvh-units", "mm")  # the numbers taken as millimetres
    b = read_asset(glb).clips[0]
    idx = [b.skeleton.index(n) for n in in_cm.skeleton.joint_names]
    np.testing.assert_allclose(b.world_positions()[:, idx], in_cm.world_positions() * 0.001, atol=1e-7)
    # written back in metres: the root rForeArm's OFFSET "0 0 20" (mm) becomes 0.02
    bvh = tmp_path / "ok_m.bvh"
    convert(capsys, glb, bvh, "--bvh-units", "m")
    lines = bvh.read_text().splitlines()
    assert lines[1] == "ROOT rForeArm"
    assert lines[3].split() == ["OFFSET", "0.000000", "0.000000", "0.020000"]
    c = read_asset(bvh, units="m").clips[0]
    assert c.skeleton.meters_per_unit == 1.0
    np.testing.assert_allclose(c.world_positions()[:, idx], b.world_positions()[:, idx], atol=2e-6)


def test_read_clip_passes_units_to_bvh_only(shared_assets):
    from usdhands.formats.io import read_clip

    clip = read_clip(shared_assets / "leap_hands" / "fingers-ok.bvh", units="in")
    assert clip.skeleton.meters_per_unit == 0.0254
    with pytest.raises(TypeError, match="units"):
        read_clip(shared_assets / "robot_expressive" / "RobotExpressive.glb", units="in")


def two_skeleton_usd(tmp_path):
    def rig(prefix, n):
        names = [f"{prefix}Hips"] + [f"{prefix}Hips/{prefix}J{i}" for i in range(1, n)]
        return Skeleton(names, [-1] + [0] * (n - 1), np.arange(n * 3, dtype=float).reshape(n, 3),
                        np.tile([0, 0, 0, 1.0], (n, 1)), name=prefix)

    a, b = rig("A", 3), rig("B", 4)
    rng = np.random.default_rng(0)

    def take(sk, name):
        q = rng.normal(size=(6, sk.num_joints, 4))
        return Clip(sk, 30, q / np.linalg.norm(q, axis=-1, keepdims=True), name=name)

    return write_asset(Asset("mem", (a, b), (take(a, "WalkA"), take(b, "WaveB"))), tmp_path / "two.usda")


def test_several_skeletons_to_bvh_says_which_was_taken(tmp_path, capsys):
    src = two_skeleton_usd(tmp_path)
    err = convert(capsys, src, tmp_path / "first.bvh")
    note = err.splitlines()[0]
    assert note.startswith("usdhands: BVH holds one skeleton and one animation: took animation '/Root/ARoot/WalkA'"
                           " of skeleton '/Root/ARoot/A'; left out 1 other animation(s), 1 other skeleton(s)")
    assert "--animation" in note
    first = read_asset(tmp_path / "first.bvh")
    assert first.skeletons[0].num_joints == 3
    err = convert(capsys, src, tmp_path / "second.bvh", "--animation", "/Root/BRoot/WaveB")
    assert "took animation '/Root/BRoot/WaveB' of skeleton '/Root/BRoot/B'" in err
    second = read_asset(tmp_path / "second.bvh").clips[0]
    want = read_asset(src).clip("/Root/BRoot/WaveB")
    assert second.skeleton.num_joints == 4
    assert quat_angle_deg(second.rotations, want.rotations).max() < 1e-3


def test_fps_option_resamples(shared_assets, tmp_path, capsys):
    src = shared_assets / "leap_hands" / "fingers-ok.bvh"  # 245 frames at 40 fps
    out = tmp_path / "ok20.usda"
    convert(capsys, src, out, "--fps", "20")
    a, b = read_asset(src).clips[0], read_asset(out).clips[0]
    assert b.fps == 20.0 and b.num_frames == 123
    idx = [b.skeleton.index(n) for n in a.skeleton.joint_names]
    np.testing.assert_allclose(b.world_positions()[:, idx] * 0.01, a.world_positions()[::2] * 0.01, atol=1e-6)


def test_output_by_option_or_position_and_json(sample_assets, tmp_path, capsys):
    """-o OUT like every other command; the positional OUT still works; --json says what was written."""
    import json

    src = sample_assets / "humanoid.bvh"
    assert main(["convert", str(src), "-o", str(tmp_path / "a.glb"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    clip = read_asset(src).clips[0]
    assert report == {"input": str(src), "output": str(tmp_path / "a.glb"), "skeletons": [report["skeletons"][0]],
                      "animations": [{"name": report["animations"][0]["name"], "frames": clip.num_frames,
                                      "fps": clip.fps}],
                      "meshes": 0, "notes": []}
    assert read_asset(tmp_path / "a.glb").clips[0].num_frames == clip.num_frames
    convert(capsys, src, tmp_path / "b.glb")  # positional
    assert (tmp_path / "b.glb").is_file()
    assert main(["convert", str(src), str(tmp_path / "c.glb"), "--output", str(tmp_path / "c.glb")]) == 0
    capsys.readouterr()
    for argv, message in (([], "no output file given (-o OUT)"),
                          ([str(tmp_path / "d.glb"), "-o", str(tmp_path / "e.glb")], "two outputs given")):
        assert main(["convert", str(src), *argv]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"usdhands: error: {message}") and len(err.splitlines()) == 1, err
    assert not (tmp_path / "d.glb").exists() and not (tmp_path / "e.glb").exists()


def test_bvh_units_refuses_an_unknown_unit(sample_assets, tmp_path, capsys):
    code = main(["convert", str(sample_assets / "humanoid.bvh"), "-o", str(tmp_path / "a.bvh"), "--bvh-units", "yard"])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("usdhands: error: ")  # no usage text (issue 8)
    assert "invalid choice: 'yard' (choose from cm, dm, ft, in, inch, m, mm)" in err[0]

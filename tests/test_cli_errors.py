"""Bad input: one line naming the file and what is wrong, exit status 2, nothing written."""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
from pathlib import Path


from usdhands.cli import main


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def run_cli(capsys, *argv) -> tuple[int, str]:
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    return code, err


def leap_copy(shared_assets: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "ok.bvh"
    shutil.copy(shared_assets / "leap_hands" / "fingers-ok.bvh", dst)
    return dst


def edit_motion_line(src: Path, dst: Path, frame: int, edit) -> None:
    lines = src.read_text().splitlines()
    first = next(k for k, line in enumerate(lines) if line.startswith("Frame Time")) + 1
    lines[first + frame] = edit(lines[first + frame])
    dst.write_text("\n".join(lines) + "\n")


def check_error(capsys, tmp_path, argv, message, inputs):
    before = {p: sha(p) for p in inputs}
    listing = sorted(p.name for p in tmp_path.iterdir())
    code, err = run_cli(capsys, *argv)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("usdhands: error: ")
    assert message in lines[0], lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == listing  # no partial output
    assert {p: sha(p) for p in inputs} == before  # inputs untouched


def test_no_skeleton(shared_assets, tmp_path, capsys):
    teapot = tmp_path / "teapot.usd"
    shutil.copy(shared_assets / "usd_teapot" / "UtahTeapot.usd", teapot)
    check_error(capsys, tmp_path, ["convert", teapot, tmp_path / "out.glb"],
                f"{teapot}: no skeleton in file", [teapot])


def test_skeleton_without_hands_lists_joints(shared_assets, tmp_path, capsys):
    cesium = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    check_error(capsys, tmp_path, ["handmap", cesium, "-o", tmp_path / "map.json"],
                "no hand found in skeleton", [cesium])
    code, err = run_cli(capsys, "handmap", cesium)
    assert "saw 19 joints: " in err and "Skeleton_arm_joint_L__4_" in err


def test_missing_file(tmp_path, capsys):
    check_error(capsys, tmp_path, ["convert", tmp_path / "nope.bvh", tmp_path / "out.glb"],
                f"{tmp_path / 'nope.bvh'}: no such file", [])


def test_output_equals_input(shared_assets, tmp_path, capsys):
    src = leap_copy(shared_assets, tmp_path)
    check_error(capsys, tmp_path, ["convert", src, src], "output path equals the input", [src])


def test_truncated_glb(shared_assets, tmp_path, capsys):
    bad = tmp_path / "trunc.glb"
    bad.write_bytes((shared_assets / "robot_expressive" / "RobotExpressive.glb").read_bytes()[:20000])
    check_error(capsys, tmp_path, ["convert", bad, tmp_path / "out.usda"],
                f"{bad}: truncated .glb: header says 463988 bytes, file has 20000", [bad])


def test_corrupt_glb_header(tmp_path, capsys):
    bad = tmp_path / "noise.glb"
    bad.write_bytes(b"not a glb file at all, just text" * 4)
    check_error(capsys, tmp_path, ["inspect", bad],
                f"usdhands: error: {bad}: not a .glb file (magic b'not ', expected b'glTF')", [bad])
    short = tmp_path / "short.glb"
    short.write_bytes(b"glTF")  # the magic, then nothing: a header cut short
    check_error(capsys, tmp_path, ["inspect", short],
                f"usdhands: error: {short}: truncated .glb: 4 bytes, shorter than the 12-byte header", [short])


def test_bvh_numbers_do_not_match_channels(shared_assets, tmp_path, capsys):
    src = leap_copy(shared_assets, tmp_path)
    bad = tmp_path / "short.bvh"
    edit_motion_line(src, bad, 2, lambda line: " ".join(line.split()[:-3]))
    check_error(capsys, tmp_path, ["convert", bad, tmp_path / "out.glb"],
                f"{bad}: line 112: expected 54 values, found 51", [bad, src])


def test_bvh_nan(shared_assets, tmp_path, capsys):
    src = leap_copy(shared_assets, tmp_path)
    bad = tmp_path / "nan.bvh"
    edit_motion_line(src, bad, 4, lambda line: " ".join(line.split()[:-1] + ["nan"]))
    check_error(capsys, tmp_path, ["convert", bad, tmp_path / "out.usda"],
                f"{bad}: line 114: value 54 is not finite: 'nan'", [bad])


def test_zero_frames(shared_assets, tmp_path, capsys):
    src = leap_copy(shared_assets, tmp_path)
    lines = src.read_text().splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith("Frame Time"))
    bad = tmp_path / "zero.bvh"
    bad.write_text("\n".join(lines[: i - 1] + ["Frames: 0", lines[i]]) + "\n")
    check_error(capsys, tmp_path, ["convert", bad, tmp_path / "out.glb"],
                f"{bad}: animation 'zero' has zero frames", [bad])


USD_HEADER = '#usda 1.0\n(\n    timeCodesPerSecond = 24\n)\n'


def usd_skel(joints_anim: str, rotations: str) -> str:
    return USD_HEADER + f'''
def SkelRoot "Root"
{{
    def Skeleton "Skel" (prepend apiSchemas = ["SkelBindingAPI"])
    {{
        uniform token[] joints = ["Hips", "Hips/LeftHand"]
        uniform matrix4d[] bindTransforms = [( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1) ), ( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 1, 0, 1) )]
        uniform matrix4d[] restTransforms = [( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1) ), ( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 1, 0, 1) )]
        rel skel:animationSource = </Root/Skel/Anim>

        def SkelAnimation "Anim"
        {{
            uniform token[] joints = {joints_anim}
            quatf[] rotations.timeSamples = {{
                0: {rotations},
                1: [(1, 0, 0, 0), (1, 0, 0, 0)],
            }}
        }}
    }}
}}
'''


def test_usd_animation_joints_do_not_match(tmp_path, capsys):
    bad = tmp_path / "mismatch.usda"
    bad.write_text(usd_skel('["Hips", "Hips/RightHand"]', "[(1, 0, 0, 0), (1, 0, 0, 0)]"))
    check_error(capsys, tmp_path, ["convert", bad, tmp_path / "out.glb"], "Hips/RightHand", [bad])


def test_usd_zero_length_quaternion(tmp_path, capsys):
    bad = tmp_path / "zeroquat.usda"
    bad.write_text(usd_skel('["Hips", "Hips/LeftHand"]', "[(1, 0, 0, 0), (0, 0, 0, 0)]"))
    check_error(capsys, tmp_path, ["convert", bad, tmp_path / "out.glb"],
                "/Root/Skel/Anim: rotations hold a zero-length quaternion (joint 'Hips/LeftHand', frame 0 at time 0)", [bad])


def test_unknown_output_extension(shared_assets, tmp_path, capsys):
    src = leap_copy(shared_assets, tmp_path)
    check_error(capsys, tmp_path, ["convert", src, tmp_path / "out.xyz"],
                "unknown file extension '.xyz'", [src])


def test_exit_status_from_the_installed_command(tmp_path):
    out = subprocess.run([sys.executable, "-m", "usdhands", "inspect", str(tmp_path / "missing.usda")],
                         capture_output=True, text=True)
    assert out.returncode == 2
    assert out.stderr.strip() == f"usdhands: error: {tmp_path / 'missing.usda'}: no such file"
    assert "Traceback" not in out.stderr


def gltf_with_bad_rotation(tmp_path: Path, value, name: str) -> Path:
    """A 2-joint glTF (data-URI buffer) whose second joint's rotation key 2 is ``value``."""
    import base64
    import json

    import numpy as np

    from usdhands.formats.io import write_asset
    from usdhands.model import Clip, Skeleton
    from usdhands.model.asset import Asset

    sk = Skeleton(["Hips", "Hand"], [-1, 0], [[0, 0, 0], [0, 1, 0]], np.tile([0, 0, 0, 1.0], (2, 1)))
    q = np.random.default_rng(0).normal(size=(4, 2, 4))
    good = write_asset(Asset("mem", (sk,), (Clip(sk, 30, q / np.linalg.norm(q, axis=-1, keepdims=True),
                                                 name="A"),)), tmp_path / "good.gltf")
    d = json.loads(good.read_text())
    good.unlink()
    head, data = d["buffers"][0]["uri"].split(",", 1)
    buf = bytearray(base64.b64decode(data))
    channel = next(c for c in d["animations"][0]["channels"] if c["target"] == {"node": 1, "path": "rotation"})
    acc = d["accessors"][d["animations"][0]["samplers"][channel["sampler"]]["output"]]
    start = d["bufferViews"][acc["bufferView"]].get("byteOffset", 0) + acc.get("byteOffset", 0) + 2 * 16
    buf[start:start + 16] = np.asarray(value, dtype="<f4").tobytes()
    d["buffers"][0]["uri"] = head + "," + base64.b64encode(bytes(buf)).decode()
    bad = tmp_path / name
    bad.write_text(json.dumps(d))
    return bad


def test_gltf_nan_quaternion(tmp_path, capsys):
    bad = gltf_with_bad_rotation(tmp_path, [float("nan"), 0, 0, 1], "nan.gltf")
    check_error(capsys, tmp_path, ["convert", bad, tmp_path / "out.usda"],
                f"{bad}: animation 'A' has NaN or infinite rotations (joint 'Hand', frame 2)", [bad])


def test_gltf_zero_length_quaternion(tmp_path, capsys):
    bad = gltf_with_bad_rotation(tmp_path, [0, 0, 0, 0], "zero.gltf")
    check_error(capsys, tmp_path, ["inspect", bad],
                f"{bad}: animation 'A' has a zero-length quaternion (joint 'Hand', frame 2)", [bad])


def test_failing_write_leaves_nothing_behind(shared_assets, tmp_path):
    """An error raised while the output is being written removes the temporary file."""
    import pytest

    from usdhands.errors import JointMismatchError
    from usdhands.formats.io import read_clip, write_clip

    src = leap_copy(shared_assets, tmp_path)
    clip = read_clip(src)
    sub = clip.skeleton.subset([clip.skeleton.index(n) for n in ("rForeArm", "rHand")])
    partial = clip.replace(skeleton=sub, rotations=clip.rotations[:, :2], translations=clip.translations[:, :2],
                           scales=clip.scales[:, :2])
    before = sha(src)
    with pytest.raises(JointMismatchError, match=r"the clip has no joint\(s\) rThumb1"):
        write_clip(src, partial, tmp_path / "out.bvh")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.bvh"]
    assert sha(src) == before


def test_animation_by_name_or_index_and_unknown_ones(shared_assets):
    import pytest

    from usdhands.errors import AssetReadError
    from usdhands.formats.io import read_clip

    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    assert read_clip(src).name == "Dance"  # the first by default
    assert read_clip(src, animation="Wave").name == "Wave"
    assert read_clip(src, animation=3).name == read_clip(src, animation="3").name == "Jump"
    with pytest.raises(AssetReadError) as e:
        read_clip(src, animation="Nope")
    assert str(e.value).startswith(f"{src}: no animation named 'Nope'; there are 'Dance', 'Death', ")
    with pytest.raises(AssetReadError) as e:
        read_clip(src, animation=99)
    assert str(e.value) == f"{src}: animation index 99 out of range 0..13"


def test_usd_zero_length_and_nan_quaternion_with_translations(tmp_path, capsys):
    """With translations authored UsdSkel's query hands the quaternions over; Clip.validate reports them."""
    for value, what in (("(0, 0, 0, 0)", "a zero-length quaternion"), ("(nan, 0, 0, 0)", "NaN or infinite rotations")):
        text = usd_skel('["Hips", "Hips/LeftHand"]', f"[(1, 0, 0, 0), {value}]").replace(
            "            quatf[] rotations", "            float3[] translations = [(0, 0, 0), (0, 1, 0)]\n"
                                         "            quatf[] rotations")
        bad = tmp_path / "bad.usda"
        bad.write_text(text)
        check_error(capsys, tmp_path, ["convert", bad, tmp_path / "out.glb"],
                    f"{bad}: animation '/Root/Skel/Anim' has {what} (joint 'Hips/LeftHand', frame 0)", [bad])
        bad.unlink()

"""Odd content: very short clips, trimmed clips, clips with only root motion, one-handed and
mirrored skeletons, USD animations without rotations."""

from __future__ import annotations


import numpy as np
import pytest

from usdhands.cli import main
from cli_helpers import run  # noqa: E402  (tests/ is on sys.path, like splice_synth)
from usdhands.formats.io import read_clip, write_clip
from usdhands.model.rotations import quat_angle_deg


@pytest.mark.parametrize("ext", ["glb", "gltf"])
@pytest.mark.parametrize("first, stop", [(0, 1), (0, 2), (30, 60)])
def test_gltf_write_clip_of_a_trimmed_clip(ext, first, stop, ok_glb, tmp_path, capsys, gltf_validator):
    """write_clip into a glTF kept the source's unchanged channels with their 89 keys, so a
    1-frame (or trimmed) clip read back with the source's 89 frames."""
    src = ok_glb
    if ext == "gltf":
        src = tmp_path / "ok.gltf"
        assert main(["convert", str(ok_glb), str(src)]) == 0
    clip = read_clip(src)
    part = clip.slice(first, stop)
    out = tmp_path / f"part.{ext}"
    write_clip(src, part, out)
    back = read_clip(out)
    assert back.num_frames == stop - first
    assert back.start_time == pytest.approx(part.start_time)
    assert quat_angle_deg(back.rotations, part.rotations).max() < 1e-3
    np.testing.assert_allclose(back.translations, part.translations, atol=1e-6)
    report = gltf_validator(out)[0]
    assert report["numErrors"] == 0, report["messages"]


def mirrored_rig(ok_glb, out):
    """ok_00 with a negative x scale on LeftArm (a mirrored left arm), written to ``out``."""
    from usdhands.formats.io import read_asset, write_asset
    from usdhands.model.asset import Asset
    from usdhands.model.skeleton import Skeleton

    clip = read_asset(ok_glb).clips[0]
    sk = clip.skeleton
    j = sk.index("LeftArm")
    scales = np.array(sk.rest_scales, copy=True)
    scales[j] = (-1.0, 1.0, 1.0)
    sk2 = Skeleton(sk.joint_names, sk.parents, sk.rest_translations, sk.rest_rotations, scales, None,
                   meters_per_unit=sk.meters_per_unit, up_axis=sk.up_axis, name=sk.name)
    anim_scales = np.array(clip.scales, copy=True)
    anim_scales[:, j] = (-1.0, 1.0, 1.0)
    mirrored = clip.replace(skeleton=sk2, scales=anim_scales)
    write_asset(Asset(str(ok_glb), (sk2,), (mirrored,), ()), out)
    return mirrored


def test_mirrored_hand_refused_naming_file_and_joint(ok_glb, tmp_path, capsys):
    """A negative scale above a hand made hand_rig hand scipy a left-handed matrix: a
    'Non-positive determinant' ValueError traceback from synthesize, db build and evaluate."""
    from usdhands.algorithms.synthesis.finger_transfer import hand_rig
    from usdhands.errors import UnsupportedRigError
    from usdhands.model.hand_detection import detect_hands

    src = tmp_path / "mirror.usda"
    clip = mirrored_rig(ok_glb, src)
    message = ("the left hand's joint frames are mirrored (a negative scale on 'LeftArm'); finger motion needs "
               "right-handed joint frames: freeze the mirror into the rig's rest pose first")
    hands = detect_hands(clip.skeleton)
    with pytest.raises(UnsupportedRigError, match=r"left hand's joint frames are mirrored"):
        hand_rig(clip.skeleton, hands.left)
    hand_rig(clip.skeleton, hands.right)  # the other hand is fine
    for argv in (["synthesize", src, "-o", tmp_path / "out.usda"],
                 ["db", "build", "-o", tmp_path / "db", src],
                 ["evaluate", "--holdout", ok_glb, src]):
        code, err = run(capsys, *argv)
        assert (code, err) == (2, [f"usdhands: error: {src}: {message}"]), argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mirror.usda", "ok.glb"]


@pytest.mark.parametrize("ext", ["glb", "usda", "bvh"])
def test_write_clip_refuses_nan(ext, ok_glb, tmp_path):
    """A NaN rotation given to write_clip compared as 'unchanged' in the glTF writer, which
    silently kept the source's keys; every writer now refuses it before writing."""
    from usdhands.errors import InvalidAnimationError

    src = ok_glb
    if ext != "glb":
        src = tmp_path / f"ok.{ext}"
        assert main(["convert", str(ok_glb), str(src)]) == 0
    clip = read_clip(src)
    rot = np.array(clip.rotations, copy=True)
    j = clip.skeleton.index("LeftHandThumb1")
    rot[3, j] = np.nan
    bad = clip.replace(rotations=rot)
    out = tmp_path / f"out.{ext}"
    with pytest.raises(InvalidAnimationError, match=r"has NaN or infinite rotations \(joint '.*LeftHandThumb1', frame 3\)"):
        write_clip(src, bad, out)
    assert not out.exists()

"""Odd content: very short clips, trimmed clips, clips with only root motion, one-handed and
mirrored skeletons, USD animations without rotations."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from usdhands.cli import main
from usdhands.formats.io import read_clip, write_clip
from usdhands.model.rotations import quat_angle_deg


def run(capsys, *argv) -> tuple[int, list[str]]:
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err.strip().splitlines()


@pytest.fixture()
def ok_glb(sample_assets, tmp_path):
    dst = tmp_path / "ok.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", dst)
    return dst


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

"""Exact frame rates: non-integer and odd rates survive glTF <-> USD with the same frame count.

A clip at 23.976, 29.97, 37 and 59.94 fps is written to one format, converted to the
other and back; the rate and the frame count must come back. glTF files usdhands
writes record the rate in the animation's extras; files from elsewhere do not, so
the rate found from float32 key times alone is checked too, over long takes.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from usdhands.jobs.conversion import convert
from usdhands.formats.gltf_read import detect_fps
from usdhands.formats.io import read_asset, write_asset
from usdhands.model import Clip, Skeleton
from usdhands.model.asset import Asset

RATES = [24000 / 1001, 30000 / 1001, 37.0, 60000 / 1001]


def _clip(fps: float, frames: int) -> Clip:
    sk = Skeleton(["Hips", "Hips/Spine"], [-1, 0], [[0, 1, 0], [0, 0.2, 0]], np.tile([0, 0, 0, 1.0], (2, 1)))
    a = np.linspace(0, 3, frames)
    rot = np.zeros((frames, 2, 4))
    rot[:, :, 2] = np.sin(a)[:, None] * 0.3
    rot[:, :, 3] = 1.0
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    return Clip(sk, fps, rot, name="Take")


@pytest.mark.parametrize("fps", RATES + [29.97, 23.976])
@pytest.mark.parametrize("first, second", [(".glb", ".usda"), (".usda", ".gltf")])
def test_rate_and_frame_count_round_trip(tmp_path, fps, first, second):
    frames = 2065
    clip = _clip(fps, frames)
    a = write_asset(Asset("mem", (clip.skeleton,), (clip,)), tmp_path / f"a{first}")
    b = tmp_path / f"b{second}"
    c = tmp_path / f"c{first}"
    convert(a, b)
    convert(b, c)
    for path in (a, b, c):
        back = read_asset(path).clips[0]
        assert back.num_frames == frames, path
        assert back.fps == pytest.approx(fps, rel=1e-12), path
        np.testing.assert_allclose(back.rotations, clip.rotations, atol=1e-6)


@pytest.mark.parametrize("fps, frames", [(24000 / 1001, 2065), (30000 / 1001, 2065), (37.0, 1291),
                                         (60000 / 1001, 7200), (29.97, 2065), (23.976, 500), (25.0, 9000)])
def test_rate_from_float32_key_times_alone(fps, frames):
    """No extras (a file from another tool): the rate from the key times as a whole gives the frame count."""
    t = (np.arange(frames) / fps).astype(np.float32)
    found = detect_fps(t)
    assert found == pytest.approx(fps, rel=2e-6)
    assert int(np.floor(float(t[-1] - t[0]) * found + 1e-3)) + 1 == frames
    # the same keys as several sampler inputs (one per channel), shuffled within one of them
    rng = np.random.default_rng(0)
    assert detect_fps([t, t[: frames // 2], rng.permutation(t)]) == found


def test_known_rates_snap_to_ntsc_and_integers():
    assert detect_fps((np.arange(3000) * 1001 / 30000).astype(np.float32)) == 30000 / 1001
    assert detect_fps((np.arange(300) * 1001 / 24000).astype(np.float32)) == 24000 / 1001
    assert detect_fps((np.arange(1291) / 37).astype(np.float32)) == 37.0
    assert detect_fps((np.arange(100) / 12.5).astype(np.float32)) == 12.5


def test_gltf_reader_prefers_recorded_rate_and_ignores_a_bad_one(tmp_path, caplog):
    clip = _clip(37.0, 40)
    path = write_asset(Asset("mem", (clip.skeleton,), (clip,)), tmp_path / "a.gltf")
    doc = json.loads(path.read_text())
    assert doc["animations"][0]["extras"]["usdhands"]["fps"] == 37.0
    doc["animations"][0]["extras"]["usdhands"]["fps"] = 74.0  # keys on every other frame: the recorded rate wins
    path.write_text(json.dumps(doc))
    assert (read_asset(path).clips[0].fps, read_asset(path).clips[0].num_frames) == (74.0, 79)
    for bad, says in (("fast", "ignoring extras.usdhands.fps 'fast'"),
                      (12.0, "key times are not on the frames of the recorded 12 fps")):
        doc["animations"][0]["extras"]["usdhands"]["fps"] = bad
        path.write_text(json.dumps(doc))
        caplog.clear()
        with caplog.at_level("INFO", logger="usdhands"):
            assert read_asset(path).clips[0].fps == 37.0
        assert says in caplog.text

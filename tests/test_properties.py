"""Property tests (hypothesis): random skeletons and clips through every format, resampling,
forward kinematics across conversion, DTW on a sequence and itself, the reduction formulas.

Each property is checked on examples hypothesis draws (a fixed derandomised budget, so a
run is reproducible and CI time bounded); a failing example is shrunk and printed.
"""

from __future__ import annotations

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from usdhands.formats.io import read_asset, write_asset  # noqa: E402
from usdhands.model import Clip, Skeleton  # noqa: E402
from usdhands.model.asset import Asset  # noqa: E402

PROFILE = settings(max_examples=15, deadline=None, derandomize=True,
                   suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

FORMATS = ("glb", "gltf", "usda", "usdc", "bvh")


def unit_quaternions(rng: np.random.Generator, shape: tuple) -> np.ndarray:
    q = rng.normal(size=shape + (4,))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q[..., 3] = np.abs(q[..., 3]) + 0.5  # away from 180-degree turns, where Euler (BVH) is touchy
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


@st.composite
def skeletons_and_clips(draw):
    """A random tree of 2-12 joints (parents first), cm units, and a smooth clip of 2-12 frames."""
    joints = draw(st.integers(2, 12))
    parents = [-1] + [draw(st.integers(0, j - 1)) for j in range(1, joints)]
    frames = draw(st.integers(2, 12))
    fps = draw(st.sampled_from([24.0, 30.0, 60.0]))
    seed = draw(st.integers(0, 2 ** 31 - 1))
    rng = np.random.default_rng(seed)
    rest_t = rng.uniform(-10, 10, size=(joints, 3))
    rest_t[0] = 0
    names = [f"j{k}" for k in range(joints)]
    sk = Skeleton(names, np.array(parents), rest_t, np.tile([0, 0, 0, 1.0], (joints, 1)), meters_per_unit=0.01,
                  name="Skel")
    # smooth rotations: a random start and small steps
    start = unit_quaternions(rng, (joints,))
    steps = unit_quaternions(rng, (frames, joints)) * np.array([0.05, 0.05, 0.05, 1.0])
    steps /= np.linalg.norm(steps, axis=-1, keepdims=True)
    from usdhands.model.rotations import quat_multiply

    rot = np.empty((frames, joints, 4))
    rot[0] = start
    for f in range(1, frames):
        rot[f] = quat_multiply(rot[f - 1], steps[f])
    trans = np.broadcast_to(rest_t, (frames, joints, 3)).copy()
    trans[:, 0] = rng.uniform(-50, 50, size=(frames, 3))  # the root moves
    return Clip(sk, fps, rot, trans, name="Take")


@pytest.mark.parametrize("fmt", FORMATS)
@PROFILE
@given(clip=skeletons_and_clips())
def test_random_clips_round_trip_every_format(fmt, clip, tmp_path_factory):
    """Written and read back: same frame count and rate, and forward kinematics agrees (0.01 cm)."""
    folder = tmp_path_factory.mktemp(fmt)
    path = write_asset(Asset("memory", (clip.skeleton,), (clip,)), folder / f"take.{fmt}")
    back = read_asset(path).clips[0]
    assert back.num_frames == clip.num_frames
    assert back.fps == pytest.approx(clip.fps, rel=1e-6)
    before = clip.world_positions_cm()
    after = back.world_positions_cm()
    # joints by name: formats may add End Sites or keep names as paths
    short = [n.rsplit("/", 1)[-1] for n in back.skeleton.joint_names]
    cols = [short.index(n) for n in clip.skeleton.joint_names]
    np.testing.assert_allclose(after[:, cols], before, atol=0.01)


@PROFILE
@given(clip=skeletons_and_clips(), there=st.sampled_from([120.0, 240.0]))
def test_resampling_up_and_back_is_the_identity(clip, there):
    """Up to a multiple of the rate and back: every original frame is sampled again exactly (1e-9)."""
    back = clip.resample(there).resample(clip.fps)
    assert back.num_frames == clip.num_frames
    d = np.abs(np.sum(back.rotations * clip.rotations, axis=-1))
    np.testing.assert_allclose(d, 1.0, atol=1e-9)
    np.testing.assert_allclose(back.translations, clip.translations, atol=1e-9)


@PROFILE
@given(clip=skeletons_and_clips())
def test_resampling_down_and_up_stays_close(clip):
    """Halved and restored: within the curve's change over one frame (smooth clips)."""
    back = clip.resample(clip.fps / 2).resample(clip.fps)
    from usdhands.model.rotations import quat_angle_deg

    n = back.num_frames
    err = quat_angle_deg(back.rotations, clip.rotations[:n])
    step = quat_angle_deg(clip.rotations[1:], clip.rotations[:-1]).max()
    assert err.max() <= step + 1e-6


@PROFILE
@given(clip=skeletons_and_clips(), fmt=st.sampled_from(["glb", "usda", "bvh"]), to=st.sampled_from(["glb", "usdc"]))
def test_forward_kinematics_agrees_after_conversion(clip, fmt, to, tmp_path_factory):
    """FK of a clip equals FK of the same clip after format -> other format (0.01 cm)."""
    from usdhands.cli import main

    folder = tmp_path_factory.mktemp("fk")
    src = write_asset(Asset("memory", (clip.skeleton,), (clip,)), folder / f"take.{fmt}")
    dst = folder / f"converted.{to}"
    assert main(["convert", str(src), str(dst)]) == 0
    a, b = read_asset(src).clips[0], read_asset(dst).clips[0]
    short = [n.rsplit("/", 1)[-1] for n in b.skeleton.joint_names]
    cols = [short.index(n.rsplit("/", 1)[-1]) for n in a.skeleton.joint_names]
    np.testing.assert_allclose(b.world_positions_cm()[:, cols], a.world_positions_cm(), atol=0.01)


@PROFILE
@given(n=st.integers(1, 40), dims=st.integers(1, 6), seed=st.integers(0, 2 ** 31 - 1))
def test_dtw_of_a_sequence_with_itself_is_the_diagonal(n, dims, seed):
    from usdhands.algorithms.dtw import dtw

    x = np.random.default_rng(seed).normal(size=(n, dims))
    cost = np.linalg.norm(x[:, None] - x[None], axis=-1)
    result = dtw(cost)
    assert result.cost == 0.0
    np.testing.assert_array_equal(result.path, np.stack([np.arange(n)] * 2, axis=1))


finite = st.floats(-180, 180, allow_nan=False)


@PROFILE
@given(values=st.lists(finite, min_size=3, max_size=50), mean=finite, std=st.floats(0.01, 90),
       kind=st.sampled_from(["rmsd1", "rmsd2"]))
def test_reduction_formulas_preserve_mean_and_std(values, mean, std, kind):
    """dep = scale * ctrl + offset with the paper's formulas has the dependent's mean and std."""
    from usdhands.algorithms.reduction.model import Relation

    ctrl = np.asarray(values)
    if ctrl.std() < 1e-3:
        ctrl = ctrl + np.linspace(0, 1, len(ctrl))
    rel = Relation.from_statistics("a", "b", kind, 0.0, mean, std, float(ctrl.mean()), float(ctrl.std()))
    rebuilt = rel.scale * ctrl + rel.offset
    assert rebuilt.mean() == pytest.approx(mean, abs=1e-9 * (1 + abs(mean) + std))
    assert rebuilt.std() == pytest.approx(std, rel=1e-9)
    assert np.sign(np.corrcoef(ctrl, rebuilt)[0, 1]) == (1 if kind == "rmsd1" else -1)


@pytest.mark.parametrize("fmt", ["glb", "gltf"])
@settings(max_examples=6, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(clip=skeletons_and_clips(), magnitude=st.sampled_from([1e-3, 1.0, 1e3, 1e30]))
def test_random_clips_written_as_gltf_pass_the_khronos_validator(fmt, clip, magnitude, tmp_path_factory,
                                                                 gltf_validator):
    """Every output must be one the format's validator accepts (issue 8): quaternions of any magnitude
    (a USD quaternion of 1e38 once failed the validator) are written normalized, and read back the same."""
    scaled = Clip(clip.skeleton, clip.fps, clip.rotations * magnitude, clip.translations, name=clip.name)
    folder = tmp_path_factory.mktemp(fmt)
    path = write_asset(Asset("memory", (clip.skeleton,), (scaled,)), folder / f"take.{fmt}")
    report = gltf_validator(path)[0]
    assert report["numErrors"] == 0, report["issues"]["messages"][:5]
    back = read_asset(path).clips[0]
    np.testing.assert_allclose(back.world_positions_cm(), clip.world_positions_cm(), atol=0.01)

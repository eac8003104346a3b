"""The data model: rotations, skeleton, clip, finger DOF curves."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from usdhands.errors import InvalidAnimationError
from usdhands.model import Clip, Skeleton, apply_finger_curves, finger_curves
from usdhands.model.rotations import (
    euler_deg_to_quat, quat_angle_deg, quat_canonical, quat_multiply, quat_slerp,
    quat_to_euler_deg, trs_to_xform, xform_to_trs,
)


def chain_skeleton(n=3, length=1.0):
    names = ["j0"] + ["j0/" + "/".join(f"j{k}" for k in range(1, i + 1)) for i in range(1, n)]
    return Skeleton(names, [-1] + list(range(n - 1)), [[0, 0, 0]] + [[0, length, 0]] * (n - 1),
                    np.tile([0, 0, 0, 1.0], (n, 1)), meters_per_unit=0.01)


def test_quat_multiply_matches_scipy():
    rng = np.random.default_rng(1)
    a, b = Rotation.random(50, random_state=2), Rotation.random(50, random_state=3)
    ours = quat_multiply(a.as_quat(), b.as_quat())
    ref = (a * b).as_quat()
    assert np.allclose(quat_canonical(ours), quat_canonical(ref), atol=1e-12)
    assert rng is not None


def test_quat_shape_error_quotes_shape():
    with pytest.raises(ValueError, match=r"Expected a to have shape \(\.\.\., 4\), got \(3,\)"):
        quat_multiply(np.zeros(3), np.zeros(4))


def test_slerp_halfway_angle():
    a = euler_deg_to_quat([0, 0, 0])
    b = euler_deg_to_quat([0, 0, 90])
    m = quat_slerp(a, b, 0.5)
    assert quat_angle_deg(a, m) == pytest.approx(45.0, abs=1e-9)
    assert quat_angle_deg(m, b) == pytest.approx(45.0, abs=1e-9)


def test_trs_round_trip():
    rng = np.random.default_rng(0)
    t = rng.normal(size=(20, 3))
    q = Rotation.random(20, random_state=4).as_quat()
    s = rng.uniform(0.5, 2, size=(20, 3))
    t2, q2, s2 = xform_to_trs(trs_to_xform(t, q, s))
    assert np.allclose(t, t2) and np.allclose(s, s2)
    assert np.all(quat_angle_deg(q, q2) < 1e-6)


def test_forward_kinematics_of_bent_chain():
    sk = chain_skeleton(3)
    rot = np.tile([0, 0, 0, 1.0], (1, 3, 1))
    rot[0, 1] = euler_deg_to_quat([0, 0, 90])  # bend at joint 1 about z
    clip = Clip(sk, 30, rot)
    p = clip.world_positions()[0]
    assert np.allclose(p[1], [0, 1, 0])
    assert np.allclose(p[2], [-1, 1, 0])  # y axis turned to -x
    assert np.allclose(clip.world_positions_cm()[0, 2], [-1, 1, 0])  # centimetre units


def test_clip_arrays_are_read_only_copies():
    sk = chain_skeleton(2)
    rot = np.tile([0, 0, 0, 1.0], (4, 2, 1))
    clip = Clip(sk, 30, rot)
    rot[0, 0] = [1, 0, 0, 0]
    assert clip.rotations[0, 0, 3] == 1.0
    with pytest.raises(ValueError):
        clip.rotations[0, 0, 0] = 1


def test_resample_uses_slerp():
    sk = chain_skeleton(2)
    rot = np.stack([euler_deg_to_quat(np.array([[0, 0, 0], [0, 0, a]])) for a in (0.0, 90.0)])
    clip = Clip(sk, 1, rot)  # two frames, one second apart
    r = clip.resample(4)
    assert r.num_frames == 5
    angles = quat_angle_deg(r.rotations[:, 1], rot[0, 1])
    assert np.allclose(angles, [0, 22.5, 45, 67.5, 90], atol=1e-9)


def test_slice_keeps_time():
    clip = Clip(chain_skeleton(2), 10, np.tile([0, 0, 0, 1.0], (20, 2, 1)))
    s = clip.slice(5, 15)
    assert s.num_frames == 10 and s.start_time == pytest.approx(0.5)


def test_validate_reports_nan_with_joint_and_frame():
    rot = np.tile([0, 0, 0, 1.0], (3, 2, 1))
    rot[2, 1] = np.nan
    clip = Clip(chain_skeleton(2), 30, rot)
    with pytest.raises(InvalidAnimationError, match=r"NaN .*rotations \(joint 'j0/j1', frame 2\)"):
        clip.validate()


def test_validate_zero_frames_and_zero_quaternion():
    with pytest.raises(InvalidAnimationError, match="zero frames"):
        Clip(chain_skeleton(2), 30, np.zeros((0, 2, 4))).validate()
    rot = np.tile([0, 0, 0, 1.0], (3, 2, 1))
    rot[1, 0] = 0
    with pytest.raises(InvalidAnimationError, match="zero-length quaternion"):
        Clip(chain_skeleton(2), 30, rot).validate()


def test_finger_curves_round_trip_and_unwrap():
    sk = Skeleton(["a", "b"], [-1, 0], np.zeros((2, 3)), euler_deg_to_quat([[0, 0, 0], [10, 20, 30]]))
    angles = np.linspace(0, 400, 50)  # crosses 180 and 360 about z
    rel = euler_deg_to_quat(np.stack([np.zeros(50), np.zeros(50), angles], axis=1))
    local = quat_multiply(sk.rest_rotations[1], rel)
    rot = np.stack([np.tile([0, 0, 0, 1.0], (50, 1)), local], axis=1)
    clip = Clip(sk, 30, rot)
    fc = finger_curves(clip, [1])
    assert fc.names == ("b.x", "b.y", "b.z")
    assert np.allclose(fc.values[:, 2], angles, atol=1e-6)  # unwrapped, relative to rest
    back = apply_finger_curves(clip, fc)
    assert np.all(quat_angle_deg(back.rotations, clip.rotations) < 1e-6)


def test_skeleton_rejects_child_before_parent():
    with pytest.raises(ValueError, match="parents must come before children"):
        Skeleton(["a", "b"], [1, -1], np.zeros((2, 3)), np.tile([0, 0, 0, 1.0], (2, 1)))


def test_skeleton_short_name_lookup():
    sk = chain_skeleton(3)
    assert sk.index("j2") == 2 and sk.index("j0/j1/j2") == 2
    with pytest.raises(KeyError, match="No joint named 'nope'"):
        sk.index("nope")


def test_euler_round_trip():
    e = np.array([[10.0, -20.0, 30.0]])
    assert np.allclose(quat_to_euler_deg(euler_deg_to_quat(e)), e)


def test_ambiguous_short_name_needs_the_full_path():
    sk = Skeleton(["root", "root/L/Index1", "root/R", "root/R/Index1"], [-1, 0, 0, 2], np.zeros((4, 3)),
                  np.tile([0, 0, 0, 1.0], (4, 1)))
    assert sk.index("root/R/Index1") == 3 and sk.index("R") == 2
    assert not sk.has_joint("Index1")
    with pytest.raises(KeyError, match="No joint named 'Index1'"):
        sk.index("Index1")

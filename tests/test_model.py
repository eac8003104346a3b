"""The data model: rotations, skeleton, clip, finger DOF curves."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from usdhands.errors import InvalidAnimationError
from usdhands.model import Clip, Skeleton, apply_finger_curves, finger_curves
from usdhands.model.rotations import (
    euler_deg_to_quat, matrix_to_quat, quat_angle_deg, quat_canonical, quat_multiply, quat_slerp,
    quat_to_euler_deg, quat_to_matrix, quat_to_rotvec_deg, trs_to_xform, xform_to_trs,
)


def chain_skeleton(n=3, length=1.0):
    names = ["j0"] + ["j0/" + "/".join(f"j{k}" for k in range(1, i + 1)) for i in range(1, n)]
    return Skeleton(names, [-1] + list(range(n - 1)), [[0, 0, 0]] + [[0, length, 0]] * (n - 1),
                    np.tile([0, 0, 0, 1.0], (n, 1)), meters_per_unit=0.01)


def test_quat_multiply_matches_scipy():
    rng = np.random.default_rng(1)
    a = Rotation.from_quat(rng.normal(size=(500, 4)))
    b = Rotation.from_quat(rng.normal(size=(500, 4)))
    ours = quat_multiply(a.as_quat(), b.as_quat())
    ref = (a * b).as_quat()
    assert np.allclose(quat_canonical(ours), quat_canonical(ref), atol=1e-12)
    # the order matters, and is "b first, then a": the reversed product is another rotation
    assert np.max(quat_angle_deg(ours, quat_multiply(b.as_quat(), a.as_quat()))) > 90
    # by hand: 90 deg about z, then 90 deg about x, takes +x to +y, then to +z; +y to -x (stays)
    s = np.sqrt(0.5)
    about_z, about_x = np.array([0, 0, s, s]), np.array([s, 0, 0, s])
    m = quat_to_matrix(quat_multiply(about_x, about_z))
    np.testing.assert_allclose(m @ [1.0, 0, 0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(m @ [0, 1.0, 0], [-1, 0, 0], atol=1e-15)
    # w = s*s, x = s*s, y = -s*s, z = s*s from the Hamilton product written out
    np.testing.assert_allclose(quat_multiply(about_x, about_z), [0.5, -0.5, 0.5, 0.5], atol=1e-15)


EULER_ORDERS = ["XYZ", "ZXY", "ZYX", "YZX", "XZY", "YXZ", "XYX", "ZXZ", "xyz", "zxy", "zyx", "yxy"]


@pytest.mark.parametrize("order", EULER_ORDERS)
def test_euler_conversions_match_scipy(order):
    """Many random rotations and the gimbal-lock ones, each order against scipy's Rotation."""
    rng = np.random.default_rng(sum(map(ord, order)))
    q = rng.normal(size=(2000, 4)) * 3  # not unit: normalized like scipy does
    ref = Rotation.from_quat(q).as_euler(order, degrees=True)
    np.testing.assert_allclose(quat_to_euler_deg(q, order), ref, atol=1e-10)
    e = rng.uniform(-180, 180, size=(2000, 3))
    np.testing.assert_allclose(quat_canonical(euler_deg_to_quat(e, order)),
                               quat_canonical(Rotation.from_euler(order, e, degrees=True).as_quat()), atol=1e-14)
    middle = 0.0 if order[0].lower() == order[2].lower() else 90.0
    locked = Rotation.from_euler(order, [[30, middle, 40], [-70, -middle or 180, 15]], degrees=True).as_quat()
    with np.errstate(all="ignore"), pytest.warns(UserWarning, match="Gimbal lock"):
        ref_locked = Rotation.from_quat(locked).as_euler(order, degrees=True)
    np.testing.assert_allclose(quat_to_euler_deg(locked, order), ref_locked, atol=1e-6)


def test_euler_round_trip():
    """Round trips in several orders, and a case worked by hand."""
    rng = np.random.default_rng(7)
    e = np.stack([rng.uniform(-180, 180, 300), rng.uniform(-89, 89, 300), rng.uniform(-180, 180, 300)], axis=1)
    for order in ("XYZ", "ZXY", "zyx"):
        np.testing.assert_allclose(quat_to_euler_deg(euler_deg_to_quat(e, order), order), e, atol=1e-9)
    # intrinsic XYZ (10, 0, 90): 10 deg about x, then 90 deg about the new z; takes +x to
    # (0, cos 10, sin 10), which extrinsic xyz would not (it turns about the fixed z: +x to +y)
    m = quat_to_matrix(euler_deg_to_quat([10.0, 0.0, 90.0], "XYZ"))
    c, s = np.cos(np.radians(10)), np.sin(np.radians(10))
    np.testing.assert_allclose(m @ [1.0, 0, 0], [0, c, s], atol=1e-15)
    np.testing.assert_allclose(quat_to_matrix(euler_deg_to_quat([10.0, 0.0, 90.0], "xyz")) @ [1.0, 0, 0],
                               [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(quat_to_euler_deg(euler_deg_to_quat([10.0, 0.0, 90.0]), "XYZ"), [10, 0, 90],
                               atol=1e-12)
    with pytest.raises(ValueError, match="Expected consecutive axes to be different"):
        euler_deg_to_quat([0, 0, 0], "XXY")
    with pytest.raises(ValueError, match="Expected an Euler order"):
        quat_to_euler_deg([0, 0, 0, 1], "XYz")


def test_matrix_and_rotvec_conversions_match_scipy():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(3000, 4))
    r = Rotation.from_quat(q)
    np.testing.assert_allclose(quat_to_matrix(q), r.as_matrix(), atol=1e-15)
    assert np.array_equal(quat_to_matrix(q), r.as_matrix())  # the same arithmetic, to the bit
    m = r.as_matrix()
    assert np.array_equal(matrix_to_quat(m), Rotation.from_matrix(m).as_quat())
    bent = m + rng.normal(scale=0.05, size=m.shape)  # not orthogonal: the nearest rotation, as scipy
    np.testing.assert_allclose(matrix_to_quat(bent), Rotation.from_matrix(bent).as_quat(), atol=1e-12)
    small = np.concatenate([q, [[1e-5, 0, 0, 1.0], [0, 0, 0, 1.0], [0, 0, 0, -1.0], [1, 0, 0, 0]]])
    np.testing.assert_allclose(quat_to_rotvec_deg(small), Rotation.from_quat(small).as_rotvec(degrees=True),
                               atol=1e-10)
    with pytest.raises(ValueError, match="Non-positive determinant"):
        matrix_to_quat(np.diag([-1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="zero norm"):
        quat_to_matrix(np.zeros(4))


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


def test_rest_world_xforms_are_computed_once_and_handed_out_as_copies():
    sk = chain_skeleton(3)
    first = sk.rest_world_xforms()
    np.testing.assert_allclose(first[:, :3, 3], [[0, 0, 0], [0, 1, 0], [0, 2, 0]])
    first[2, :3, 3] = 7.0  # the caller's copy
    again = sk.rest_world_xforms()
    assert again is not first and again.flags.writeable
    np.testing.assert_allclose(again[:, :3, 3], [[0, 0, 0], [0, 1, 0], [0, 2, 0]])
    np.testing.assert_allclose(sk.rest_world_positions()[2], [0, 2, 0])


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


def _validate_element_wise(clip: Clip) -> str | None:
    """What ``Clip.validate`` must report, element by element (its checks without the whole-array shortcut):
    the message's kind, joint and frame, or None."""
    from usdhands.model.clip import MAX_MAGNITUDE

    for label, arr in (("rotations", clip.rotations), ("translations", clip.translations), ("scales", clip.scales)):
        for f, j in np.ndindex(arr.shape[:2]):
            if not np.isfinite(arr[f, j]).all():
                return f"NaN or infinite {label} (joint {clip.skeleton.joint_names[j]!r}, frame {f})"
    for label, arr in (("translations", clip.translations), ("scales", clip.scales)):
        for f, j in np.ndindex(arr.shape[:2]):
            if (np.abs(arr[f, j]) > MAX_MAGNITUDE).any():
                return f"{label} beyond {MAX_MAGNITUDE:g} (joint {clip.skeleton.joint_names[j]!r}, frame {f})"
    for f, j in np.ndindex(clip.rotations.shape[:2]):
        if np.sqrt(np.sum(clip.rotations[f, j] ** 2)) < 1e-6:
            return f"zero-length quaternion (joint {clip.skeleton.joint_names[j]!r}, frame {f})"
    return None


def test_validate_finds_what_an_element_wise_check_finds():
    """validate (whole-array extremes first, element-wise only when one could fail) against the checks run
    element by element: random clips with NaN, infinities, magnitudes over 1e30 and short quaternions at
    random places, several at once, and values at the thresholds (lengths 1e-6 and 3e-6, 1e30 itself,
    huge finite quaternions whose squares overflow, tiny ones whose squares underflow)."""
    rng = np.random.default_rng(11)
    skeleton = chain_skeleton(5)
    specials = [np.nan, np.inf, -np.inf, 1e31, -1e31, 1e30, -1e30, 1e200, 1e-200, 0.0]
    for case in range(400):
        rot = rng.normal(size=(7, 5, 4))
        rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
        trans, scales = rng.normal(size=(7, 5, 3)) * 10, rng.uniform(0.5, 2, (7, 5, 3))
        for _ in range(rng.integers(0, 3)):
            target = (rot, trans, scales)[rng.integers(0, 3)]
            f, j, c = rng.integers(0, 7), rng.integers(0, 5), rng.integers(0, target.shape[-1])
            target[f, j, c] = specials[rng.integers(0, len(specials))]
        if case % 5 == 0:  # a short quaternion: zero, just under or over the threshold, tiny or huge
            f, j = rng.integers(0, 7), rng.integers(0, 5)
            rot[f, j] = np.array([0.6, 0.0, 0.0, 0.8]) * [0.0, 0.9e-6, 1.1e-6, 3e-6, 1e-200, 1e200][case // 5 % 6]
        clip = Clip(skeleton, 30, rot, trans, scales)
        with np.errstate(over="ignore"):  # the squares of 1e200
            expected = _validate_element_wise(clip)
            if expected is None:
                assert clip.validate() is clip
            else:
                with pytest.raises(InvalidAnimationError) as err:
                    clip.validate()
                assert expected in str(err.value), (case, expected, str(err.value))


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


def test_ambiguous_short_name_needs_the_full_path():
    sk = Skeleton(["root", "root/L/Index1", "root/R", "root/R/Index1"], [-1, 0, 0, 2], np.zeros((4, 3)),
                  np.tile([0, 0, 0, 1.0], (4, 1)))
    assert sk.index("root/R/Index1") == 3 and sk.index("R") == 2
    assert not sk.has_joint("Index1")
    with pytest.raises(KeyError, match="No joint named 'Index1'"):
        sk.index("Index1")


@pytest.mark.parametrize("dtype", [np.float64, np.float32, None])
def test_clip_arrays_are_read_only_copies_of_what_was_given(dtype):
    """A float32 array (a reader's) is converted once and kept; a float64 one is copied: never the caller's memory."""
    sk = Skeleton(["a", "b"], [-1, 0], np.zeros((2, 3)), np.tile([0, 0, 0, 1.0], (2, 1)))
    rng = np.random.default_rng(4)
    q = rng.normal(size=(5, 2, 4))
    t = rng.normal(size=(5, 2, 3))
    given_q = q.tolist() if dtype is None else q.astype(dtype)
    given_t = t.tolist() if dtype is None else t.astype(dtype)
    clip = Clip(sk, 30, given_q, given_t, np.ones((5, 2, 3), dtype or np.float64))
    for arr, given in ((clip.rotations, given_q), (clip.translations, given_t)):
        assert arr.dtype == np.float64 and not arr.flags.writeable
        assert np.array_equal(arr, np.asarray(given, dtype=np.float64))
        if dtype is not None:
            assert not np.may_share_memory(arr, given)
            given[0, 0, 0] = 99.0  # the caller's array changes, the clip does not
            assert arr[0, 0, 0] != 99.0


def test_clip_shares_a_locked_array_it_is_handed_and_copies_an_unlocked_one():
    sk = Skeleton(["a"], [-1], np.zeros((1, 3)), np.tile([0, 0, 0, 1.0], (1, 1)))
    q = np.zeros((3, 1, 4))
    q[..., 3] = 1.0
    q.setflags(write=False)  # a reader hands over what it made
    locked = Clip(sk, 30, q)
    assert locked.rotations is q
    again = locked.replace(name="b")  # immutable arrays are shared between clips
    assert again.rotations is q
    open_ = np.tile([0, 0, 0, 1.0], (3, 1, 1))
    assert not np.may_share_memory(Clip(sk, 30, open_).rotations, open_)
    view = q[1:]  # not owning its memory: copied
    assert Clip(sk, 30, view).rotations.base is None

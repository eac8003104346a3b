"""Units and up-axis conversion of skeletons and clips."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from usdhands.model import Clip, Skeleton
from usdhands.model.rotations import quat_angle_deg
from usdhands.model.units import clip_to, skeleton_to, up_axis_xform


def z_up_clip():
    rot = Rotation.random(3 * 10, random_state=7).as_quat().reshape(10, 3, 4)
    sk = Skeleton(["hips", "hips/spine", "hips/spine/head"], [-1, 0, 1],
                  [[0, 0, 90], [0, 0, 20], [0, 0, 30]], rot[0], meters_per_unit=0.01, up_axis="Z")
    trans = np.broadcast_to(sk.rest_translations, (10, 3, 3)).copy()
    trans[:, 0, 0] = np.linspace(0, 50, 10)
    return Clip(sk, 30, rot, trans)


@pytest.mark.parametrize("mpu,up", [(1.0, "Y"), (0.01, "Y"), (1.0, "Z")])
def test_world_positions_follow_units_and_axis(mpu, up):
    clip = z_up_clip()
    out = clip_to(clip, skeleton_to(clip.skeleton, mpu, up))
    expected = clip.world_positions() @ up_axis_xform("Z", up)[:3, :3].T * (0.01 / mpu)
    assert np.allclose(out.world_positions(), expected, atol=1e-9)
    # joints below the root keep their local rotations
    assert np.all(quat_angle_deg(out.rotations[:, 1:], clip.rotations[:, 1:]) < 1e-9)
    assert out.skeleton.meters_per_unit == mpu and out.skeleton.up_axis == up


def test_z_to_y_maps_up_vector_to_y():
    assert np.allclose(up_axis_xform("Z", "Y")[:3, :3] @ [0, 0, 1], [0, 1, 0])
    with pytest.raises(ValueError, match="Expected up axes 'Y' or 'Z', got 'X' -> 'Y'"):
        up_axis_xform("X", "Y")


@pytest.mark.parametrize("up", ["Z", "Y"])
def test_clip_to_rotations_equal_the_root_turned_on_a_copy(up):
    """The rotations are those of a copy with the roots turned (the way it was written
    first), to the bit; where the turn changes no bit (the same up axis) the clip's own
    array is shared instead of copied, and copied where it changes one (a root's -0.0)."""
    from usdhands.model.rotations import quat_multiply
    from usdhands.model.units import _axis_quat

    clip = z_up_clip()
    for negative_zero in (False, True):
        rot = np.array(clip.rotations)
        if negative_zero:
            rot[3, 0] = [-0.0, -0.0, -0.0, 1.0]  # the turn by the identity gives +0.0: a bit changes
        src = Clip(clip.skeleton, 30, rot, clip.translations)
        out = clip_to(src, skeleton_to(src.skeleton, 1.0, up))
        want = np.array(src.rotations)
        want[:, 0] = quat_multiply(_axis_quat("Z", up), want[:, 0])
        assert np.array_equal(out.rotations.view(np.uint64), want.view(np.uint64))
        unchanged = np.array_equal(want.view(np.uint64), src.rotations.view(np.uint64))
        assert unchanged == (up == "Z" and not negative_zero)
        assert np.shares_memory(out.rotations, src.rotations) == unchanged

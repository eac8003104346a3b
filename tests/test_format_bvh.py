"""BVH reading and writing: real Leap Motion files, every channel order, bad numbers."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from usdhands.errors import AssetReadError, JointMismatchError
from usdhands.formats.bvh import HANDLER, parse_bvh
from usdhands.formats.io import read_asset, write_asset, write_clip
from usdhands.model import Clip, Skeleton
from usdhands.model.asset import Asset
from usdhands.model.rotations import quat_angle_deg
from usdhands.model.units import up_axis_xform

LEAP = {"fingers-ok.bvh": (245, 0.025), "gesture-pointing.bvh": (153, 0.027), "gesture-typing.bvh": (317, 0.027)}
LEAP_JOINTS = ["rForeArm", "rHand"] + [
    n for F in ("Thumb", "Index", "Mid", "Ring", "Pinky") for n in (f"r{F}1", f"r{F}2", f"r{F}3", f"r{F}3_end")]


def assert_same_motion(a: Clip, b: Clip, deg=1e-5, units=1e-6):
    assert a.skeleton.joint_names == b.skeleton.joint_names
    assert np.array_equal(a.skeleton.parents, b.skeleton.parents)
    assert np.allclose(a.skeleton.rest_translations, b.skeleton.rest_translations, atol=units)
    assert a.num_frames == b.num_frames and a.fps == pytest.approx(b.fps, rel=1e-9)
    assert quat_angle_deg(a.rotations, b.rotations).max() < deg
    assert np.abs(a.translations - b.translations).max() < units


@pytest.mark.parametrize("name", sorted(LEAP))
def test_leap_files(shared_assets, name):
    frames, frame_time = LEAP[name]
    asset = read_asset(shared_assets / "leap_hands" / name)
    sk, = asset.skeletons
    clip = asset.clip()
    assert list(sk.joint_names) == LEAP_JOINTS
    assert sk.meters_per_unit == 0.01 and sk.up_axis == "Y"
    assert clip.num_frames == frames
    assert clip.fps == pytest.approx(1.0 / frame_time, rel=1e-12)
    assert sk.parents[sk.index("rIndex1")] == sk.index("rHand")
    assert np.allclose(sk.rest_translations[sk.index("rIndex1")], [-30, 0, 42])
    assert np.allclose(sk.rest_translations[sk.index("rPinky3_end")], [1, 0, 20])
    # joint 3 of each finger never moves (SOURCES.md)
    assert quat_angle_deg(clip.rotations[:, sk.index("rMid3")], [0, 0, 0, 1]).max() == 0


def test_leap_first_frame_values(shared_assets):
    clip = read_asset(shared_assets / "leap_hands" / "fingers-ok.bvh").clip()
    sk = clip.skeleton
    # line 111 of the file (the first frame after the all-zero rest line)
    assert np.allclose(clip.translations[0, 0], [49.97, 395.64, 215.54])
    ref = Rotation.from_euler("ZYX", [-50.95, 2.03, -102.06], degrees=True).as_quat()
    assert quat_angle_deg(clip.rotations[0, 0], ref) < 1e-9
    ref = Rotation.from_euler("ZYX", [21.66, -25.04, 43.17], degrees=True).as_quat()
    assert quat_angle_deg(clip.rotations[0, sk.index("rThumb1")], ref) < 1e-9
    # non-root joints without position channels keep their offsets
    assert np.allclose(clip.translations[:, sk.index("rIndex1")], [-30, 0, 42])


@pytest.mark.parametrize("name", sorted(LEAP))
def test_leap_round_trip_new_file(shared_assets, tmp_path, name):
    src = shared_assets / "leap_hands" / name
    asset = read_asset(src)
    out = write_asset(asset, tmp_path / "out.bvh")
    back = read_asset(out)
    assert_same_motion(asset.clip(), back.clip())
    text = out.read_text()
    assert "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" in text  # ZXY default
    assert text.count("End Site") == 5
    # a second round trip reproduces the written file exactly
    out2 = write_asset(back, tmp_path / "out2.bvh")
    assert out2.read_text() == text


def test_leap_write_clip_keeps_hierarchy_and_orders(shared_assets, tmp_path):
    src = shared_assets / "leap_hands" / "gesture-pointing.bvh"
    clip = read_asset(src).clip()
    bent = clip.with_joint_rotations([clip.skeleton.index("rIndex2")],
                                     np.tile(Rotation.from_euler("X", 40, degrees=True).as_quat(),
                                             (clip.num_frames, 1, 1)))
    out = write_clip(src, bent, tmp_path / "bent.bvh")
    head = src.read_text().split("MOTION")[0]
    assert out.read_text().split("MOTION")[0] == head
    back = read_asset(out).clip()
    assert_same_motion(bent, back)
    assert "Frame Time: 0.027\n" in out.read_text()


def test_write_clip_missing_joint(shared_assets, tmp_path):
    src = shared_assets / "leap_hands" / "fingers-ok.bvh"
    clip = read_asset(src).clip()
    keep = [j for j, n in enumerate(clip.skeleton.joint_names) if not n.startswith("rPinky")]
    sub = clip.skeleton.subset(keep)
    small = Clip(sub, clip.fps, clip.rotations[:, keep], clip.translations[:, keep])
    with pytest.raises(JointMismatchError) as e:
        write_clip(src, small, tmp_path / "x.bvh")
    assert str(e.value) == f"{src}: the clip has no joint(s) rPinky1, rPinky2, rPinky3 of the source hierarchy"
    assert not (tmp_path / "x.bvh").exists()


def synthetic_bvh(order: str, frames: np.ndarray, frame_time="0.0333333") -> str:
    """Root with 6 channels, a joint with position + rotation channels, a 3-channel leaf."""
    rot = " ".join(f"{a}rotation" for a in order)
    lines = ["HIERARCHY", "ROOT Hips", "{", "  OFFSET 1 2 3", f"  CHANNELS 6 Xposition Yposition Zposition {rot}",
             "  JOINT Chest", "  {", "    OFFSET 0 10 0", f"    CHANNELS 6 {rot} Xposition Yposition Zposition",
             "    JOINT Head", "    {", "      OFFSET 0 5 0", f"      CHANNELS 3 {rot}",
             "      End Site", "      {", "        OFFSET 0 3 0", "      }", "    }", "  }", "}",
             "MOTION", f"Frames: {len(frames)}", f"Frame Time: {frame_time}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in frames]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("order", ["".join(p) for p in itertools.permutations("XYZ")])
def test_every_channel_order_matches_scipy_intrinsic(tmp_path, order):
    rng = np.random.default_rng(abs(hash(order)) % 2**32)
    T = 7
    frames = np.concatenate([rng.uniform(-50, 50, (T, 3)), rng.uniform(-170, 170, (T, 3)),
                             rng.uniform(-80, 80, (T, 3)), rng.uniform(-5, 5, (T, 3)),
                             rng.uniform(-170, 170, (T, 3))], axis=1)
    p = tmp_path / f"{order}.bvh"
    p.write_text(synthetic_bvh(order, frames))
    frames = np.round(frames, 6)  # as printed
    clip = read_asset(p).clip()
    sk = clip.skeleton
    assert list(sk.joint_names) == ["Hips", "Chest", "Head", "Head_end"]
    assert clip.fps == 30.0
    for j, col in ((0, 3), (1, 6), (2, 12)):
        ref = Rotation.from_euler(order, frames[:, col:col + 3], degrees=True).as_quat()
        assert quat_angle_deg(clip.rotations[:, j], ref).max() < 1e-9
    assert np.allclose(clip.translations[:, 0], frames[:, 0:3])
    assert np.allclose(clip.translations[:, 1], frames[:, 9:12])
    assert np.allclose(clip.translations[:, 2], [0, 5, 0]) and np.allclose(clip.translations[:, 3], [0, 3, 0])
    # write_clip keeps this file's order and its channel layout; write() uses ZXY
    out = write_clip(p, clip, tmp_path / "copy.bvh")
    assert out.read_text().split("MOTION")[0] == p.read_text().split("MOTION")[0]
    assert_same_motion(clip, read_asset(out).clip())
    out2 = write_asset(read_asset(p), tmp_path / "new.bvh")
    assert "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" in out2.read_text()
    assert_same_motion(clip, read_asset(out2).clip())


def test_partial_rotation_channels_and_rest_only_joint(tmp_path):
    p = tmp_path / "partial.bvh"
    p.write_text("HIERARCHY\nROOT A\n{\nOFFSET 0 0 0\nCHANNELS 4 Xposition Yposition Zposition Yrotation\n"
                 "JOINT B\n{\nOFFSET 0 1 0\nCHANNELS 0\nJOINT C\n{\nOFFSET 0 1 0\nCHANNELS 2 Xrotation Zrotation\n"
                 "}\n}\n}\nMOTION\nFrames: 2\nFrame Time: 0.5\n1 2 3 30 10 20\n0 0 0 -30 0 90\n")
    clip = read_asset(p).clip()
    assert clip.fps == 2.0
    ref = Rotation.from_euler("Y", [[30], [-30]], degrees=True).as_quat()
    assert quat_angle_deg(clip.rotations[:, 0], ref).max() < 1e-9
    assert quat_angle_deg(clip.rotations[:, 1], [0, 0, 0, 1]).max() == 0
    ref = Rotation.from_euler("XZ", [[10, 20], [0, 90]], degrees=True).as_quat()
    assert quat_angle_deg(clip.rotations[:, 2], ref).max() < 1e-9
    out = write_clip(p, clip, tmp_path / "copy.bvh")
    assert out.read_text().splitlines()[-2:] == ["1.000000 2.000000 3.000000 30.000000 10.000000 20.000000",
                                                 "0.000000 0.000000 0.000000 -30.000000 0.000000 90.000000"]


def test_units_option(shared_assets):
    p = shared_assets / "leap_hands" / "fingers-ok.bvh"
    cm = HANDLER.read(p).clip()
    m = HANDLER.read(p, units="m").clip()
    mm = HANDLER.read(p, units=0.001).clip()
    assert m.skeleton.meters_per_unit == 1.0 and mm.skeleton.meters_per_unit == 0.001
    assert np.allclose(cm.world_positions_cm(), m.world_positions_cm() / 100)
    assert np.allclose(cm.world_positions_cm(), mm.world_positions_cm() * 10)
    with pytest.raises(ValueError, match=r"Expected units as one of .* or metres per unit, got 'furlong'"):
        HANDLER.read(p, units="furlong")


def test_fps_option_resamples(shared_assets):
    clip = HANDLER.read(shared_assets / "leap_hands" / "fingers-ok.bvh", fps=20).clip()
    full = HANDLER.read(shared_assets / "leap_hands" / "fingers-ok.bvh").clip()
    assert clip.fps == 20 and clip.num_frames == 123
    assert quat_angle_deg(clip.rotations[10], full.rotations[20]).max() < 1e-9


def test_write_converts_metres_z_up_to_centimetres_y_up(tmp_path):
    rng = np.random.default_rng(3)
    names = ["root", "root/a", "root/a/b", "root/a/b/b_end"]
    sk = Skeleton(names, [-1, 0, 1, 2], [[0, 0, 1.0], [0, 0, 0.5], [0.2, 0, 0.3], [0, 0, 0.1]],
                  Rotation.random(4, random_state=5).as_quat(), meters_per_unit=1.0, up_axis="Z")
    T = 5
    rot = Rotation.random(T * 4, random_state=6).as_quat().reshape(T, 4, 4)
    tr = np.tile(sk.rest_translations, (T, 1, 1))
    tr[:, 0] += rng.normal(size=(T, 3))
    clip = Clip(sk, 24, rot, tr)
    out = write_asset(Asset("mem.usda", (sk,), (clip,)), tmp_path / "z.bvh")
    back = read_asset(out).clip()
    assert list(back.skeleton.joint_names) == ["root", "a", "b", "b_end"]
    assert "End Site" in out.read_text()
    want = clip.world_positions_cm() @ up_axis_xform("Z", "Y")[:3, :3].T
    assert np.abs(back.world_positions_cm() - want).max() < 1e-4


# -- bad files ---------------------------------------------------------------------------

def leap_lines(shared_assets):
    return (shared_assets / "leap_hands" / "fingers-ok.bvh").read_text().splitlines()


def test_too_few_values_on_a_line(shared_assets, tmp_path):
    lines = leap_lines(shared_assets)
    lines[311] = " ".join(lines[311].split()[:-3])  # line 312
    p = tmp_path / "short.bvh"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(AssetReadError) as e:
        read_asset(p)
    assert str(e.value) == f"{p}: line 312: expected 54 values, found 51"


def test_too_many_values_on_a_line(shared_assets, tmp_path):
    lines = leap_lines(shared_assets)
    lines[119] += " 1 2"
    p = tmp_path / "long.bvh"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(AssetReadError) as e:
        read_asset(p)
    assert str(e.value) == f"{p}: line 120: expected 54 values, found 56"


def test_frames_count_disagrees(shared_assets, tmp_path):
    lines = leap_lines(shared_assets)
    lines[107] = "Frames: 250"
    p = tmp_path / "count.bvh"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(AssetReadError) as e:
        read_asset(p)
    assert str(e.value) == f"{p}: line 355: 'Frames: 250' (line 108) but 246 frames of motion follow"
    lines[107] = "Frames: 200"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(AssetReadError) as e:
        read_asset(p)
    assert str(e.value) == f"{p}: line 310: 'Frames: 200' (line 108) but 246 frames of motion follow"


def test_not_a_number(tmp_path):
    p = tmp_path / "nan.bvh"
    p.write_text(synthetic_bvh("ZXY", np.zeros((3, 15))).replace("\n0.000000", "\nx.000000", 1))
    with pytest.raises(AssetReadError) as e:
        read_asset(p)
    assert str(e.value) == f"{p}: line 24: not a number: 'x.000000'"


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("      }\n    }\n", "      }\n", 1), "line 19: unexpected end of hierarchy inside 'Hips': missing '}'"),
    (lambda t: t.replace("CHANNELS 3", "CHANNELS 4", 1), "line 14: CHANNELS 4 lists fewer than 4 channels"),
    (lambda t: t.replace("  }\n}\n", "  }\n}\n}\n"), "line 21: expected 'ROOT' or 'MOTION', found '}'"),
    (lambda t: t.replace("Zrotation", "Wrotation", 1), "line 5: unknown channel 'Wrotation' (expected X/Y/Z position or rotation)"),
    (lambda t: t.replace("OFFSET 0 10 0", "OFFSET 0 ten 0"), "line 8: expected a number for OFFSET y, found 'ten'"),
    (lambda t: t.replace("JOINT Head", "JOINT Chest"), "line 10: joint name 'Chest' is used twice"),
    (lambda t: t.replace("HIERARCHY", "HIERARCHIE"), "line 1: expected 'HIERARCHY', found 'HIERARCHIE'"),
    (lambda t: t.split("MOTION")[0], "line 20: no MOTION section"),
    (lambda t: t.replace("Frame Time: 0.0333333", "Frame Time: 0"), "line 23: expected a positive frame time, found '0'"),
    (lambda t: t.replace("CHANNELS 3", "CHANNELS \u00b2", 1), "line 13: expected a channel count, found '\u00b2'"),
    (lambda t: t.replace("CHANNELS 3", "CHANNELS " + "3" * 5000, 1), f"line 13: expected a channel count, found '{'3' * 5000}'"),
    (lambda t: t.replace("CHANNELS 3", "CHANNELS 1000000000", 1), "line 13: expected a channel count, found '1000000000'"),
])
def test_malformed_hierarchy(tmp_path, edit, message):
    p = tmp_path / "bad.bvh"
    p.write_text(edit(synthetic_bvh("ZXY", np.zeros((2, 15)))))
    with pytest.raises(AssetReadError) as e:
        parse_bvh(p)
    assert str(e.value) == f"{p}: {message}"


def test_write_bakes_scales_into_offsets(tmp_path):
    # a root scaled 100x (RobotExpressive's armature) and an animated uniform scale below
    sk = Skeleton(["arm", "arm/a", "arm/a/b", "arm/a/b/c"], [-1, 0, 1, 2],
                  [[0, 0, 0], [0, 0.02, 0], [0.01, 0, 0], [0, 0.01, 0]],
                  Rotation.random(4, random_state=8).as_quat(), rest_scales=[[100] * 3, [1] * 3, [1] * 3, [1] * 3],
                  meters_per_unit=0.01)
    T = 4
    scales = np.ones((T, 4, 3))
    scales[:, 0] = 100
    scales[:, 1] = np.linspace(1, 2, T)[:, None]
    clip = Clip(sk, 30, Rotation.random(T * 4, random_state=9).as_quat().reshape(T, 4, 4), scales=scales)
    out = write_asset(Asset("mem", (sk,), (clip,)), tmp_path / "s.bvh")
    back = read_asset(out).clip()
    assert np.abs(back.world_positions() - clip.world_positions()).max() < 1e-5
    assert np.allclose(back.skeleton.rest_translations[1], [0, 2, 0])


def test_euler_channels_to_quat_matches_scipy_for_repeated_axes():
    from usdhands.formats.bvh import euler_channels_to_quat

    a = np.random.default_rng(2).uniform(-180, 180, (20, 3))
    for seq, axes in (("ZXZ", (2, 0, 2)), ("YXY", (1, 0, 1)), ("XYZ", (0, 1, 2))):
        ref = Rotation.from_euler(seq, a, degrees=True).as_quat()
        assert quat_angle_deg(euler_channels_to_quat(a, axes), ref).max() < 1e-9


def _euler_product_from_identity(angles_deg, axes):
    """The twin of bvh._axis_product as it was: every component multiplied from the identity."""
    half = np.radians(np.asarray(angles_deg, dtype=np.float64).T) * 0.5
    c, s = np.cos(half), np.sin(half)
    perms = {0: ([3, 2, 1, 0], [1, 1, -1, -1]), 1: ([2, 3, 0, 1], [-1, 1, 1, -1]), 2: ([1, 0, 3, 2], [1, -1, 1, -1])}
    q = [np.zeros(half.shape[1]) for _ in range(3)] + [np.ones(half.shape[1])]
    for i, a in enumerate(axes):
        perm, sign = perms[a]
        q = [q[k] * c[i] + sign[k] * (q[perm[k]] * s[i]) for k in range(4)]
    return np.stack(q, axis=-1)


def test_euler_product_skipping_zero_components_equals_the_product_from_the_identity():
    """The reader multiplies only the components that are not zero: the same numbers (to the
    bit, up to the sign of a zero) for 1 to 4 channels in every order, repeats included,
    with angles of 0, +-90, +-180, +-360 and beyond."""
    from usdhands.formats.bvh import euler_channels_to_quat

    rng = np.random.default_rng(11)
    special = np.array([0.0, 90.0, -90.0, 180.0, -180.0, 360.0, -360.0, 720.5, 1e-300, -1e-7])
    for n in (1, 2, 3, 4):
        for axes in itertools.product((0, 1, 2), repeat=n):
            a = np.concatenate([rng.uniform(-400, 400, (200, n)), rng.choice(special, (60, n))])
            got = euler_channels_to_quat(a, axes)
            assert np.array_equal(got, _euler_product_from_identity(a, axes)), axes
    big = rng.uniform(-180, 180, (20_000, 3))  # more rows than one chunk
    assert np.array_equal(euler_channels_to_quat(big, (2, 0, 1)), _euler_product_from_identity(big, (2, 0, 1)))


def test_numpy_clip_conversion_equals_each_joint_converted_alone(monkeypatch):
    """The NumPy reader converts every rotation channel of a block of frames at once, each group of
    joints with the same axes together: the same numbers, to the bit, as each joint's channels
    given to euler_channels_to_quat alone, and translations as the offsets with each position
    channel in place (the last of a repeated one). Random hierarchies: mixed axis orders, 6
    channels on inner joints, repeated and partial axes, joints without channels between,
    signed zeros, half and whole turns, channels that hold one number in every frame (the
    posed joints converted once: also 0.0 in some frames and -0.0 in others, or a change
    only in the last frame or after the first two); once more frames than a block."""
    import usdhands.formats.bvh as bvh_module
    from usdhands.formats.bvh import BvhFile, BvhJoint, bvh_to_asset, euler_channels_to_quat

    monkeypatch.setattr(bvh_module, "USE_COMPILED", False)
    rng = np.random.default_rng(21)
    names = ["Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"]
    layouts = [names[:3] + ["Zrotation", "Xrotation", "Yrotation"], ["Zrotation", "Yrotation", "Xrotation"],
               ["Yrotation", "Xrotation", "Zrotation"], names, [], ["Xrotation"], ["Zrotation", "Zrotation"]]
    special = np.array([0.0, -0.0, 90.0, -90.0, 180.0, -180.0, 360.0, 720.5, 1e-300, -1e-7])
    for trial in range(60):
        J = int(rng.integers(1, 14))
        chans = [layouts[int(rng.integers(len(layouts)))] if rng.random() < 0.7 else
                 [names[c] for c in rng.integers(0, 6, int(rng.integers(0, 7)))] for _ in range(J)]
        joints = [BvhJoint(f"j{k}", int(rng.integers(-1, k)) if k else -1, rng.normal(size=3), chans[k])
                  for k in range(J)]
        C = sum(len(c) for c in chans)
        T = 4000 if trial == 0 else int(rng.integers(1, 200))
        values = np.where(rng.random((T, C)) < 0.2, rng.choice(special, (T, C)), rng.uniform(-400, 400, (T, C)))
        for c in np.flatnonzero(rng.random(C) < 0.5):  # columns that do not move, or hardly
            values[:, c] = rng.choice(special)
            edit = int(rng.integers(5))
            if edit == 1 and not values[0, c]:
                values[rng.random(T) < 0.5, c] = -values[0, c]  # 0.0 and -0.0
            elif edit == 2:
                values[-1, c] += 1.0
            elif edit == 3 and T > 2:
                values[2:, c] = rng.uniform(-400, 400)
        monkeypatch.setattr(bvh_module, "_POSED_AFTER", 0 if trial % 2 else bvh_module._POSED_AFTER)
        clip = bvh_to_asset(BvhFile(joints, "", 1 / 30, values), Path("r.bvh")).clip()
        col = 0
        for k, j in enumerate(joints):
            rot_cols = [col + i for i, c in enumerate(j.channels) if c.endswith("rotation")]
            axes = tuple("XYZ".index(j.channels[i - col][0]) for i in rot_cols)
            want_t = np.tile(j.offset, (T, 1))
            for i, c in enumerate(j.channels):
                if c.endswith("position"):
                    want_t[:, "XYZ".index(c[0])] = values[:, col + i]
            want_q = euler_channels_to_quat(values[:, rot_cols], axes) if axes else np.tile([0.0, 0, 0, 1], (T, 1))
            assert clip.rotations[:, k].tobytes() == want_q.tobytes(), (trial, k, j.channels)
            assert clip.translations[:, k].tobytes() == want_t.tobytes(), (trial, k, j.channels)
            col += len(j.channels)


def test_names_with_spaces_and_crlf(tmp_path):
    p = tmp_path / "biped.bvh"
    p.write_bytes(b"HIERARCHY\r\nROOT Bip01 Pelvis\r\n{\r\n\tOFFSET 0 0 0\r\n\tCHANNELS 6 Xposition Yposition "
                  b"Zposition Zrotation Xrotation Yrotation\r\n\tJOINT Bip01 L Hand {\r\n\t\tOFFSET 1 0 0\r\n"
                  b"\t\tCHANNELS 3 Zrotation Xrotation Yrotation\r\n\t\tEnd Site\r\n\t\t{\r\n\t\t\tOFFSET 0 1 0\r\n"
                  b"\t\t}\r\n\t}\r\n}\r\nMOTION\r\nFrames: 1\r\nFrame Time: 0.1\r\n1 2 3 0 0 90 0 45 0\r\n")
    clip = read_asset(p).clip()
    assert list(clip.skeleton.joint_names) == ["Bip01 Pelvis", "Bip01 L Hand", "Bip01 L Hand_end"]
    assert clip.fps == 10.0
    ref = Rotation.from_euler("ZXY", [[0, 45, 0]], degrees=True).as_quat()
    assert quat_angle_deg(clip.rotations[:, 1], ref).max() < 1e-9
    out = write_asset(read_asset(p), tmp_path / "out.bvh")
    assert "JOINT Bip01_L_Hand" in out.read_text()
    assert list(read_asset(out).skeletons[0].joint_names) == ["Bip01_Pelvis", "Bip01_L_Hand", "Bip01_L_Hand_end"]


def test_two_roots_round_trip(tmp_path):
    p = tmp_path / "two.bvh"
    p.write_text("HIERARCHY\nROOT A\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation "
                 "Zrotation\nEnd Site\n{\nOFFSET 0 1 0\n}\n}\nROOT B\n{\nOFFSET 5 0 0\nCHANNELS 3 Yrotation Xrotation "
                 "Zrotation\n}\nMOTION\nFrames: 2\nFrame Time: 0.5\n1 2 3 10 20 30 40 50 60\n4 5 6 70 80 90 -10 -20 -30\n")
    clip = read_asset(p).clip()
    assert list(clip.skeleton.joint_names) == ["A", "A_end", "B"] and list(clip.skeleton.parents) == [-1, 0, -1]
    ref = Rotation.from_euler("YXZ", [[40, 50, 60], [-10, -20, -30]], degrees=True).as_quat()
    assert quat_angle_deg(clip.rotations[:, 2], ref).max() < 1e-9
    assert np.allclose(clip.translations[:, 2], [5, 0, 0])
    out = write_asset(read_asset(p), tmp_path / "out.bvh")
    assert out.read_text().count("ROOT ") == 2
    assert_same_motion(clip, read_asset(out).clip())


def test_write_clip_converts_a_clip_in_metres_back_to_the_source_units(shared_assets, tmp_path):
    src = shared_assets / "leap_hands" / "fingers-ok.bvh"
    clip = read_asset(src).clip()
    in_m = clip.with_meters_per_unit(1.0)
    assert np.allclose(in_m.translations[0, 0], [0.4997, 3.9564, 2.1554])
    back = read_asset(write_clip(src, in_m, tmp_path / "m.bvh")).clip()
    assert_same_motion(clip, back)
    # a source read in metres is written back in metres when told so
    m_clip = HANDLER.read(src, units="m").clip()
    HANDLER.write_clip(src, m_clip, tmp_path / "m2.bvh", units="m")
    assert_same_motion(clip, read_asset(tmp_path / "m2.bvh").clip())


def test_byte_order_mark_is_skipped(tmp_path):
    p = tmp_path / "bom.bvh"
    p.write_text("\ufeff" + synthetic_bvh("ZXY", np.zeros((2, 15))), encoding="utf-8")
    assert read_asset(p).clip().num_frames == 2


def _naive_bvh(path):
    """A plain reference reader: per-token hierarchy walk, per-row float(), per-joint scipy Euler.

    Returns (names, parents, offsets (J, 3), rotations (T, J, 4), translations (T, J, 3)).
    """
    lines = path.read_text().splitlines()
    m = next(i for i, line in enumerate(lines) if line.strip() == "MOTION")
    toks = " ".join(lines[:m]).replace("{", " { ").replace("}", " } ").split()
    names, parents, offsets, channels, stack, pos = [], [], [], [], [], 1
    while pos < len(toks):
        t = toks[pos]
        if t in ("ROOT", "JOINT", "End"):
            names.append(names[stack[-1]] + "_end" if t == "End" else toks[pos + 1])
            parents.append(stack[-1] if stack else -1)
            offsets.append([float(v) for v in toks[pos + 4:pos + 7]])
            channels.append([])
            pos += 7
            if toks[pos] == "CHANNELS":
                n = int(toks[pos + 1])
                channels[-1] = toks[pos + 2:pos + 2 + n]
                pos += 2 + n
            stack.append(len(names) - 1)
        elif t == "}":
            stack.pop()
            pos += 1
        else:
            raise AssertionError(t)
    rows = [[float(v) for v in line.split()] for line in lines[m + 3:] if line.strip()]
    T, J = len(rows), len(names)
    rot = np.tile([0.0, 0, 0, 1], (T, J, 1))
    trans = np.tile(np.array(offsets), (T, 1, 1))
    for f, row in enumerate(rows):
        col = 0
        for j, chans in enumerate(channels):
            seq, angles = "", []
            for c in chans:
                if c.endswith("position"):
                    trans[f, j, "XYZ".index(c[0])] = row[col]
                else:
                    seq, angles = seq + c[0], angles + [row[col]]
                col += 1
            if seq:
                rot[f, j] = Rotation.from_euler(seq, angles, degrees=True).as_quat()
    return names, parents, np.array(offsets), rot, trans


def test_vectorised_reader_matches_a_naive_reader(tmp_path):
    """Exotic channel orders, position channels on inner joints, End Sites, blank lines, tabs."""
    rng = np.random.default_rng(5)
    T = 37
    joints = [  # name, parent, channels
        ("Hips", None, "Xposition Yposition Zposition Yrotation Xrotation Zrotation"),
        ("Spine", "Hips", "Zposition Xposition Yposition Xrotation Zrotation Yrotation"),
        ("Arm", "Spine", "Yrotation Zrotation Xrotation"),
        ("Hand", "Arm", "Xrotation Yrotation Zrotation Yposition"),
        ("Tip", "Hand", None),  # End Site
        ("Leg", "Hips", "Zrotation Yrotation"),
        ("Foot", "Leg", "Xrotation"),
        ("Toe", "Foot", ""),  # a joint without channels
        ("Toe_tip", "Toe", None),
    ]
    kids = {n: [c for c, p, _ in joints if p == n] for n, _, _ in joints}
    out = ["HIERARCHY"]
    ncols = 0

    def emit(name, depth):
        nonlocal ncols
        _, parent, chans = next(j for j in joints if j[0] == name)
        ind = "\t" * depth
        off = " ".join(f"{v:.4f}" for v in rng.normal(size=3) * 10)
        if chans is None:
            out.extend([f"{ind}End Site", f"{ind}{{", f"{ind}\tOFFSET {off}", f"{ind}}}"])
            return
        out.extend([f"{ind}{'ROOT' if parent is None else 'JOINT'} {name}", f"{ind}{{", f"{ind}\tOFFSET {off}"])
        if chans:
            out.append(f"{ind}\tCHANNELS {len(chans.split())} {chans}")
            ncols += len(chans.split())
        for c in kids[name]:
            emit(c, depth + 1)
        out.append(f"{ind}}}")

    emit("Hips", 0)
    values = rng.uniform(-400, 400, (T, ncols))
    out += ["MOTION", f"Frames: {T}", "Frame Time: 0.0333333"]
    for f, row in enumerate(values):
        out.append(("\t" if f % 3 else " ").join(f"{v:.5f}" for v in row) + ("  " if f % 2 else ""))
        if f % 7 == 3:
            out.append("")
    p = tmp_path / "exotic.bvh"
    p.write_text("\n".join(out) + "\n")

    names, parents, offsets, rot, trans = _naive_bvh(p)
    clip = read_asset(p).clip()
    sk = clip.skeleton
    assert list(sk.joint_names) == names == ["Hips", "Spine", "Arm", "Hand", "Hand_end", "Leg", "Foot", "Toe",
                                             "Toe_end"]
    assert sk.parents.tolist() == [-1 if p is None else p for p in parents]
    assert np.array_equal(sk.rest_translations, offsets)
    assert clip.fps == 30.0 and clip.num_frames == T
    assert np.array_equal(clip.translations, trans)  # the same numbers, copied
    assert quat_angle_deg(clip.rotations, rot).max() < 1e-9
    assert quat_angle_deg(clip.rotations[:, 3], [0, 0, 0, 1]).min() > 1  # the channels did something
    # written back in the source layout, read again: the same motion
    back = read_asset(write_clip(p, clip, tmp_path / "again.bvh")).clip()
    assert_same_motion(back, clip)


def test_fast_motion_text_matches_python_formatting():
    """The vectorised %.6f writer against Python's, on ties, huge, tiny and non-finite numbers."""
    from usdhands.formats.fixed_point_text import format_rows_6f

    def python(v):
        fmt = " ".join(["%.6f"] * v.shape[1]) + "\n"
        return "".join(fmt % tuple(r) for r in v.tolist())

    rng = np.random.default_rng(3)
    ties = (rng.integers(-10 ** 9, 10 ** 9, (300, 7)) + 0.5) / 10.0 ** rng.integers(6, 8, (300, 7))
    odd = np.array([[0.0, -0.0, 5e-7, -5e-7, 4.9999995e-7, 1.0000005, 2.5e-6, 123456.7890125, 999999.9999994,
                     999999.9999996, -99999.5, 4.5e9, 1e12, np.inf, -np.inf, np.nan, 1e300, 5e-324, 0.1 + 0.2]])
    for v in (rng.uniform(-200, 200, (600, 13)), rng.normal(size=(300, 5)) * 10.0 ** rng.integers(-8, 12, (300, 5)),
              ties, odd, rng.uniform(0, 1, (3, 1)), np.zeros((2, 0)), np.zeros((0, 3))):
        assert format_rows_6f(v) == python(v)


def test_fast_motion_text_tables_hold_every_digit_group():
    """Every entry of the writer's digit tables (built in NumPy) is the Python-formatted group: all 10,000
    four-digit groups and every sign, point and separator record, not only those random numbers reach."""
    from usdhands.formats import fixed_point_text as f

    def python(width, prefix=b"", suffix=b""):
        return np.frombuffer(b"".join(prefix + f"{i:0{width}d}".encode() + suffix for i in range(10 ** width)), "<u4")

    for table, expected in ((f._SIGN_THOUSANDS, python(3, b"-")), (f._UNITS_POINT, python(3, suffix=b".")),
                            (f._DECIMALS_1_4, python(4)), (f._DECIMALS_5_6[b" "], python(2, suffix=b" \0")),
                            (f._DECIMALS_5_6[b"\n"], python(2, suffix=b"\n\0"))):
        assert table.dtype == expected.dtype and np.array_equal(table, expected)


@pytest.mark.parametrize("order", ["ZXY", "XYZ", "YZX"])
def test_written_euler_angles_match_scipy_as_euler(tmp_path, order):
    """The writer's NumPy Euler conversion against scipy's ``as_euler`` + unwrap (what it replaced).

    Random rotations, exact half turns and gimbal lock (middle angle +-90 degrees):
    every written number within 1e-6 degrees of scipy's (modulo 360, where a half turn
    may come out as +180 or -180) and the same rotations read back.
    """
    rng = np.random.default_rng(3)
    T, J = 40, 4
    q = Rotation.random(T * J, random_state=11).as_quat().reshape(T, J, 4)
    q[:10, 1] = Rotation.from_euler(order, rng.uniform(-90, 90, (10, 3)).round() * 2, degrees=True).as_quat()
    locked = np.column_stack([rng.uniform(-170, 170, 10), np.full(10, 90.0), rng.uniform(-170, 170, 10)])
    q[10:20, 2] = Rotation.from_euler(order, locked, degrees=True).as_quat()
    sk = Skeleton(["Root", "A", "B", "C"], [-1, 0, 1, 2], np.eye(4, 3) * 10, np.tile([0, 0, 0, 1.0], (J, 1)))
    clip = Clip(sk, 30, q)
    out = tmp_path / "w.bvh"
    HANDLER.write(Asset("w", (sk,), (clip,)), out, order=order)
    written = parse_bvh(out).values  # root: 3 positions then 3 angles; the others: 3 angles
    angles = np.concatenate([written[:, 3:6], written[:, 6:]], axis=1).reshape(T, J, 3)
    with pytest.warns(UserWarning, match="Gimbal lock"):
        ref = np.unwrap(Rotation.from_quat(q.reshape(-1, 4)).as_euler(order).reshape(T, J, 3), axis=0)
    diff = (angles - np.degrees(ref) + 180) % 360 - 180
    assert np.abs(diff).max() < 1.5e-6
    assert quat_angle_deg(read_asset(out).clip().rotations, q).max() < 1e-4


def _bvh_variants(text: str):
    """Well-formed and broken variants of one BVH text: what the fast reader must read alike or hand over."""
    head, motion = text.split("MOTION\n", 1)
    frames_line, time_line, *rows = motion.splitlines()
    yield "as is", text
    yield "crlf", text.replace("\n", "\r\n")
    yield "cr", text.replace("\n", "\r")
    yield "bom", "\ufeff" + text
    yield "blank lines", head + "MOTION\n\n" + frames_line + "\n\n" + time_line + "\n\n" + "\n\n".join(rows) + "\n\n"
    yield "tabs", head + "MOTION\n" + frames_line + "\n" + time_line + "\n" + "\n".join(r.replace(" ", "\t") for r in rows)
    yield "leap rest line", head + "MOTION\n" + frames_line + "\n" + time_line + "\n" + " ".join(
        ["0"] * len(rows[0].split())) + "\n" + "\n".join(rows) + "\n"
    yield "one frame short", head + "MOTION\n" + frames_line + "\n" + time_line + "\n" + "\n".join(rows[:-1]) + "\n"
    yield "one value short", head + "MOTION\n" + frames_line + "\n" + time_line + "\n" + "\n".join(
        rows[:2] + [rows[2].rsplit(" ", 1)[0]] + rows[3:]) + "\n"
    yield "nan", text.replace(rows[1], rows[1].replace(rows[1].split()[0], "nan", 1))
    yield "word", text.replace(rows[1], rows[1].replace(rows[1].split()[0], "x1", 1))
    yield "form feed in the head", text.replace("HIERARCHY\n", "HIERARCHY\x0c\n", 1)
    yield "frame time 0", text.replace(time_line, "Frame Time: 0")
    yield "no frames line", head + "MOTION\n" + time_line + "\n" + "\n".join(rows) + "\n"
    yield "zero frames", head + "MOTION\nFrames: 0\n" + time_line + "\n"
    yield "no motion", head


def test_fast_reading_equals_the_line_by_line_reading(tmp_path, sample_assets, monkeypatch):
    """parse_bvh's fast path gives what reading the whole text line by line gives, or hands over."""
    import usdhands.formats.bvh as bvh_module

    from conftest import SHARED_ASSETS

    sources = [sample_assets / "conversation_bodyonly.bvh", sample_assets / "humanoid.bvh"]
    sources += sorted((SHARED_ASSETS / "leap_hands").glob("*.bvh"))  # Leap Motion files: the rest line
    outcomes = []
    for src in sources:
        for name, text in _bvh_variants(src.read_text()):
            p = tmp_path / f"{src.stem}-{name.replace(' ', '_')}.bvh"
            p.write_bytes(text.encode("utf-8"))
            results = []
            for streamed in (True, False):
                with monkeypatch.context() as m:
                    if not streamed:
                        m.setattr(bvh_module, "_parse_bvh_fast", lambda path: None)
                    try:
                        results.append(parse_bvh(p))
                    except AssetReadError as e:
                        results.append(str(e))
            fast, slow = results
            if isinstance(slow, str):
                assert fast == slow, name
            else:
                assert [(j.name, j.parent, j.channels, j.end_site, j.line) for j in fast.joints] == \
                       [(j.name, j.parent, j.channels, j.end_site, j.line) for j in slow.joints], name
                assert all(np.array_equal(a.offset, b.offset) for a, b in zip(fast.joints, slow.joints))
                assert fast.hierarchy_text == slow.hierarchy_text and fast.frame_time == slow.frame_time, name
                assert fast.values.shape == slow.values.shape and np.array_equal(fast.values, slow.values), name
            outcomes.append(isinstance(slow, str))
    assert 4 < sum(outcomes) < len(outcomes) - 10  # both readable and broken variants were tried
    streamed = []
    monkeypatch.setattr(bvh_module, "_parse_bvh_fast",
                        lambda path, f=bvh_module._parse_bvh_fast: streamed.append(f(path)) or streamed[-1])
    parse_bvh(sources[0])
    assert streamed[-1] is not None  # a well-formed file takes the fast path

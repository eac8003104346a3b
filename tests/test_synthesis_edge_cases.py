"""Synthesis on odd inputs: real rigs with degenerate arms, clips shorter than a segment,
damaged databases, other frame rates and up axes."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from usdhands.algorithms.synthesis.database import load_database
from usdhands.cli import main
from usdhands.formats.io import read_clip


def _run(capsys, *argv):
    status = main([str(a) for a in argv])
    out = capsys.readouterr()
    return status, out.out, out.err


def test_db_build_on_leap_bvhs_whose_wrist_sits_on_the_root(shared_assets, capsys, tmp_path):
    # rHand is at offset 0 from the root rForeArm: no forearm direction to build the hand frame from
    leap = shared_assets / "leap_hands"
    db_path = tmp_path / "leapdb"
    status, out, err = _run(capsys, "db", "build", leap, "-o", db_path, "--labels", r"^(\w+)-", "--json")
    assert status == 0, err
    info = json.loads(out)
    assert info["clips"] == 3 and info["tracks"] == 3 and info["labels"] == ["fingers", "gesture"]
    db = load_database(db_path)
    assert set(db.hands) == {"right"} and set(db.tracks[:, 3]) == {1}
    joints = db.hands["right"]["joints"]
    # the hand frame's forward axis (x) points from the wrist towards the fingers
    firsts = [j for j in joints if j["parent"] == -1]
    assert [j["slot"] for j in firsts] == ["thumb.d2", "index.d2", "middle.d2", "ring.d2", "pinky.d2"]
    assert all(j["offset_cm"][0] > 20 for j in firsts[1:]), [j["offset_cm"] for j in firsts]
    for j in joints:
        assert np.linalg.norm(j["rotation"]) == pytest.approx(1.0)
    # the right-hand-only database synthesizes a right hand and refuses a left one clearly
    src = leap / "gesture-pointing.bvh"
    status, _, err = _run(capsys, "synthesize", src, "-o", tmp_path / "o.bvh", "--db", db_path)
    assert status == 0, err
    back, clip = read_clip(tmp_path / "o.bvh"), read_clip(src)
    assert back.num_frames == clip.num_frames


def test_a_clip_shorter_than_half_of_every_database_segment_gets_the_closest_uniform_sample():
    from usdhands.algorithms.synthesis.finger_transfer import NUM_DOFS
    from usdhands.algorithms.synthesis.synthesize import db_side_segments, synthesize_hand
    from usdhands.jobs.inputs import bundled_database_path

    db = load_database(bundled_database_path())
    right = db_side_segments(db, "right")
    lengths = db.segments[right, 1] - db.segments[right, 0]
    assert lengths.min() >= 9  # no warp with steps <= 2 maps 3 or 4 frames onto any of them
    s = int(right[np.argmax(lengths)])
    a, b = int(db.segments[s, 0]), int(db.segments[s, 1])
    for n in (1, 3, 4):
        rows = a + np.round(np.linspace(0, b - a - 1, n)).astype(np.int64)
        res = synthesize_hand(np.asarray(db.features[rows], dtype=np.float64), db, "right")
        assert res.chosen.tolist() == [s] and res.segment_costs[0, 0] == 0.0
        assert (res.candidates[0] >= 0).all() and np.all(np.diff(res.segment_costs[0]) >= 0)
        assert res.curves.shape == (n, NUM_DOFS)
        # the same motion: it starts on the segment's first frame and heads for the frames sampled
        # uniformly, at most the database's 99.5th-percentile step per frame (a 60-frame segment
        # played in 3 frames would otherwise pop)
        got = res.curves[:, db.dof_index]
        target = np.asarray(db.fingers[rows], dtype=np.float64)
        limit = db.step_limits(99.5)
        assert np.allclose(got[0], target[0], atol=1e-5)
        assert (np.abs(np.diff(got, axis=0)) <= limit + 1e-9).all()
        assert (np.abs(got[-1] - target[-1]) <= np.abs(got[0] - target[-1]) + 1e-9).all()
        if n > 1:  # it moves
            assert np.abs(got[-1] - got[0]).max() > 1.0


def test_synthesize_a_clip_of_a_few_frames(sample_assets, capsys, tmp_path):
    from usdhands.formats.io import write_clip

    src = sample_assets / "conversation_bodyonly.bvh"
    clip = read_clip(src)
    for n in (1, 2, 5):
        short = tmp_path / f"short{n}.bvh"
        write_clip(src, clip.slice(0, n), short)
        status, out, err = _run(capsys, "synthesize", short, "-o", tmp_path / f"o{n}.bvh")
        assert status == 0, err
        back = read_clip(tmp_path / f"o{n}.bvh")
        assert back.num_frames == n


def _damaged_copy(tmp_path, name, change):
    """A copy of the bundled database with one array changed in place."""
    import shutil

    from usdhands.jobs.inputs import bundled_database_path

    path = tmp_path / name
    shutil.copytree(bundled_database_path(), path)
    a = np.load(path / f"{change[0]}.npy")
    change[1](a)
    np.save(path / f"{change[0]}.npy", a)
    return path


def test_damaged_databases_are_refused_with_the_reason(capsys, tmp_path, sample_assets):
    from usdhands.errors import ConfigError

    def empty_segment(a):
        a[5, 1] = a[5, 0]

    def outside_track(a):
        a[7, 0] = -1  # before the first frame of its track

    def nan_feature(a):
        a[5, 1] = np.nan

    def bad_side(a):
        a[2, 3] = 7

    cases = [
        ("segments", empty_segment, r"segments.npy: segment 5 \(\d+\.\.\d+\) is empty or outside its track; 1 such"),
        ("segments", outside_track, r"segments.npy: segment 7 \(-1\.\.\d+\) is empty or outside its track"),
        ("features", nan_feature, r"features.npy: features hold NaN or infinite values \(first at frame 5\)"),
        ("tracks", bad_side, "tracks with no frames, or a side or mirror flag other than 0 and 1"),
    ]
    for i, (array, change, message) in enumerate(cases):
        path = _damaged_copy(tmp_path, f"db{i}", (array, change))
        with pytest.raises(ConfigError, match=message):
            load_database(path)
    # on the command line: one line, exit 2, nothing written
    out = tmp_path / "o.glb"
    status, _, err = _run(capsys, "synthesize", sample_assets / "conversation_bodyonly.glb", "-o", out,
                          "--db", tmp_path / "db0")
    assert status == 2 and err.count("\n") == 1 and "segment 5" in err and not out.exists()
    status, _, err = _run(capsys, "synthesize", sample_assets / "conversation_bodyonly.glb", "-o", out,
                          "--db", sample_assets / "humanoid.glb")
    assert status == 2 and not out.exists()
    assert err == (f"usdhands: error: {sample_assets / 'humanoid.glb'}: is a file, not a finger database "
                   f"(a folder made by 'usdhands db build')\n")
    status, _, err = _run(capsys, "synthesize", sample_assets / "conversation_bodyonly.glb", "-o", out,
                          "--db", tmp_path / "missing")
    assert status == 2 and err == f"usdhands: error: {tmp_path / 'missing'}: no such finger database folder\n"
    (tmp_path / "db1" / "manifest.json").write_text('{"format": "usdhands-finger-database", "version": 1')
    status, _, err = _run(capsys, "synthesize", sample_assets / "conversation_bodyonly.glb", "-o", out,
                          "--db", tmp_path / "db1")
    assert status == 2 and "manifest.json: manifest is not valid JSON: Expecting ',' delimiter" in err


@pytest.fixture(scope="module")
def tiny_db():
    from synthesis_data import gesture_set, tiny_handmap

    from usdhands.algorithms.synthesis.database import DatabaseClip, build_database

    hm = tiny_handmap()
    return build_database([DatabaseClip(c, hm, lab, c.name) for lab, c in gesture_set(2)], fps=30, mirror=True)


def test_a_120_fps_input_gets_the_30_fps_result_at_every_fourth_frame(tiny_db):
    from synthesis_data import gesture_clip, tiny_handmap, tiny_skeleton

    from usdhands.algorithms.synthesis.synthesize import synthesize_clip
    from usdhands.model.rotations import quat_angle_deg

    hm = tiny_handmap()
    clip = gesture_clip(tiny_skeleton(), "ok", np.random.default_rng(7), with_fingers=False)
    fast = clip.resample(120.0)
    assert fast.num_frames == 4 * (clip.num_frames - 1) + 1
    a = synthesize_clip(clip, hm, tiny_db)
    b = synthesize_clip(fast, hm, tiny_db)
    assert b.clip.fps == 120.0 and b.clip.num_frames == fast.num_frames
    fingers = sorted(clip.skeleton.index(j) for s in hm.sides for j in s.finger_joints)
    for side in ("left", "right"):  # the same decisions, at the database's rate
        assert np.array_equal(a.hands[side].chosen, b.hands[side].chosen)
        assert np.array_equal(a.hands[side].bounds, b.hands[side].bounds)
    assert quat_angle_deg(b.clip.rotations[::4, fingers], a.clip.rotations[:, fingers]).max() < 1e-3
    assert np.ptp(b.clip.rotations[:, fingers], axis=0).max() > 0.05


def test_database_at_another_rate_serves_a_30_fps_clip(tiny_db):
    from synthesis_data import gesture_clip, gesture_set, tiny_handmap, tiny_skeleton

    from usdhands.algorithms.synthesis.database import DatabaseClip, build_database
    from usdhands.algorithms.synthesis.synthesize import synthesize_clip

    hm = tiny_handmap()
    db24 = build_database([DatabaseClip(c, hm, lab, c.name) for lab, c in gesture_set(2)], fps=24)
    assert db24.fps == 24.0
    # the same takes, fewer frames; segments still 0.33 s (8 frames) to 2 s (48 frames)
    assert db24.num_frames < tiny_db.num_frames / 2 * 0.85
    lengths = db24.segments[:, 1] - db24.segments[:, 0]
    assert lengths.min() >= 8 and lengths.max() <= 48
    clip = gesture_clip(tiny_skeleton(), "wipe", np.random.default_rng(9), with_fingers=False)
    res = synthesize_clip(clip, hm, db24)
    assert res.clip.fps == clip.fps and res.clip.num_frames == clip.num_frames
    h = res.hands["left"]
    assert h.bounds[-1] == int(np.floor(clip.duration * 24 + 1e-6)) + 1  # searched at 24 fps
    labels = db24.segment_labels()
    assert sum(labels[s] == "wipe" for s in h.chosen) >= len(h.chosen) - 1


def test_z_up_usd_through_the_cli_gets_the_fingers_of_its_y_up_twin(tiny_db, capsys, tmp_path):
    from synthesis_data import gesture_clip, tiny_skeleton

    from usdhands.algorithms.synthesis.database import save_database
    from usdhands.formats.io import read_asset, write_asset
    from usdhands.model import Clip, Skeleton
    from usdhands.model.asset import Asset
    from usdhands.model.rotations import matrix_to_quat, quat_angle_deg, quat_multiply

    sk = tiny_skeleton()
    clip = gesture_clip(sk, "big", np.random.default_rng(11), with_fingers=False)
    V = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # Y-up -> Z-up
    qv = matrix_to_quat(V)
    rest_q, rest_t = np.array(sk.rest_rotations), np.array(sk.rest_translations)
    rest_q[0], rest_t[0] = quat_multiply(qv, rest_q[0]), V @ rest_t[0]
    zsk = Skeleton(sk.joint_names, sk.parents, rest_t, rest_q, meters_per_unit=sk.meters_per_unit, up_axis="Z",
                   name=sk.name)
    rot, tr = np.array(clip.rotations), np.array(clip.translations)
    rot[:, 0], tr[:, 0] = quat_multiply(qv[None], rot[:, 0]), tr[:, 0] @ V.T
    zclip = Clip(zsk, clip.fps, rot, tr, name=clip.name)
    y_in, z_in = tmp_path / "y.usda", tmp_path / "z.usda"
    write_asset(Asset("memory", [sk], [clip], []), y_in)
    write_asset(Asset("memory", [zsk], [zclip], []), z_in)
    db = save_database(tiny_db, tmp_path / "db")
    for src in (y_in, z_in):
        status, _, err = _run(capsys, "synthesize", src, "-o", tmp_path / f"out_{src.name}", "--db", db)
        assert status == 0, err
    ya, za = read_asset(tmp_path / "out_y.usda"), read_asset(tmp_path / "out_z.usda")
    assert za.skeletons[0].up_axis == "Z" and ya.skeletons[0].up_axis == "Y"
    yc, zc = ya.clips[0], za.clips[0]
    fingers = [j for j, n in enumerate(sk.short_names) if "Hand" in n and not n.endswith("Hand")]
    assert np.ptp(yc.rotations[:, fingers], axis=0).max() > 0.05
    assert quat_angle_deg(yc.rotations[:, fingers], zc.rotations[:, fingers]).max() < 1e-3
    body = [j for j in range(sk.num_joints) if j not in fingers]
    assert quat_angle_deg(zc.rotations[:, body], zclip.rotations[:, body]).max() < 1e-3


def test_synthesize_usd_as_an_override_layer_and_bad_outputs_before_any_work(sample_assets, capsys, tmp_path,
                                                                              monkeypatch):
    from pxr import Sdf

    from usdhands.algorithms.synthesis import synthesize as synthesis
    from usdhands.model.hand_detection import detect_hands
    from usdhands.model.rotations import quat_angle_deg

    src = sample_assets / "conversation_bodyonly.usdc"
    full, layer = tmp_path / "full.usda", tmp_path / "layer.usda"
    assert _run(capsys, "synthesize", src, "-o", full)[0] == 0
    status, _, err = _run(capsys, "synthesize", src, "-o", layer, "--as-layer")
    assert status == 0, err
    lay = Sdf.Layer.FindOrOpen(str(layer))
    assert [Sdf.ComputeAssetPathRelativeToLayer(lay, p) for p in lay.subLayerPaths] == [str(src)]
    specs = []
    lay.Traverse("/", lambda path: specs.append(lay.GetObjectAtPath(path)))
    prims = [x for x in specs if isinstance(x, Sdf.PrimSpec)]
    assert prims and all(x.specifier == Sdf.SpecifierOver for x in prims)  # overrides only, no new prims
    props = {x.name for x in specs if isinstance(x, Sdf.PropertySpec)}
    # the joint rotations and the provenance record, nothing else (no meshes, translations, joints)
    assert props == {"rotations", "usdhands:fingerMotion:method", "usdhands:fingerMotion:database",
                     "usdhands:fingerMotion:parameters", "usdhands:fingerMotion:version"}
    a, b, c = read_clip(src), read_clip(layer), read_clip(full)
    hm = detect_hands(a.skeleton)
    fingers = sorted(a.skeleton.index(j) for s in hm.sides for j in s.finger_joints)
    body = [j for j in range(a.num_joints) if j not in fingers]
    assert quat_angle_deg(b.rotations, c.rotations).max() < 1e-3  # the layer composes to the full output
    assert quat_angle_deg(b.rotations[:, body], a.rotations[:, body]).max() < 1e-3
    assert np.array_equal(b.translations, a.translations)
    # a bad output fails at once, before reading or synthesizing anything
    monkeypatch.setattr(synthesis, "synthesize_clip", lambda *a, **k: pytest.fail("synthesized"))
    glb = sample_assets / "conversation_bodyonly.glb"
    for argv, message in (
        ([glb, "-o", tmp_path / "x.usda", "--as-layer"], f"{glb}: --as-layer needs a USD input: the layer sublayers it"),
        ([src, "-o", tmp_path / "x.glb", "--as-layer"], f"{tmp_path / 'x.glb'}: --as-layer needs a USD output"),
        ([src, "-o", tmp_path / "x.glb"], f"{tmp_path / 'x.glb'}: the output is the input file with fingers added, "
                                          f"so it must have the input's format (.usdc)"),
        ([src, "-o", src], f"{src}: output path equals the input"),
        ([src, "-o", tmp_path / "no" / "x.usda"], f"{tmp_path / 'no' / 'x.usda'}: output folder"),
    ):
        status, _, err = _run(capsys, "synthesize", *argv)
        assert status == 2 and err.startswith(f"usdhands: error: {message}"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["full.usda", "layer.usda"]


def test_db_build_labels_file_mirror_fps_and_refusals(shared_assets, sample_assets, capsys, tmp_path):
    leap = sorted((shared_assets / "leap_hands").glob("*.bvh"))
    csv = tmp_path / "labels.csv"
    csv.write_text("# file,label\nfingers-ok.bvh,ok\ngesture-pointing,point\n"
                   f"{leap[2]},type\n")
    status, out, err = _run(capsys, "db", "build", *leap, "-o", tmp_path / "db", "--labels-file", csv,
                            "--mirror", "--fps", "20", "--json")
    assert status == 0, err
    info = json.loads(out)
    assert info["labels"] == ["ok", "point", "type"] and info["tracks"] == 6
    db = load_database(tmp_path / "db")
    assert db.fps == 20.0 and [c["label"] for c in db.clips] == ["ok", "point", "type"]
    # mirrored twins: right-hand recordings also serve the left hand, features flipped in x
    assert sorted(db.tracks[:, 3].tolist()) == [0, 0, 0, 1, 1, 1] and set(db.hands) == {"left", "right"}
    r, m = db.tracks[0], db.tracks[1]
    assert (r[3], r[4], m[3], m[4]) == (1, 0, 0, 1)
    fr, fm = np.asarray(db.features[r[0]:r[1]]), np.asarray(db.features[m[0]:m[1]])
    assert np.allclose(fm[:, 0], -fr[:, 0]) and np.allclose(fm[:, 1:4], fr[:, 1:4])
    # 245 frames at 40 fps = 6.1 s -> 123 frames at 20 fps
    assert r[1] - r[0] == 123
    for argv, message in (
        ([leap[0], "-o", tmp_path / "x", "--labels-file", tmp_path / "none.csv"], "no such labels file"),
        ([leap[0], "-o", tmp_path / "x", "--labels", "(", ], "bad --labels regular expression '('"),
        ([leap[0], "-o", tmp_path / "x", "--labels", "x", "--labels-file", csv], "give --labels or --labels-file, not both"),
        ([sample_assets / "conversation_bodyonly.glb", leap[0], "-o", tmp_path / "x", "--labels-file", csv],
         "no label for 'conversation_bodyonly.glb'"),
        ([shared_assets / "usd_cesiumman" / "CesiumMan.usdz", "-o", tmp_path / "x"], "no hand found"),
        ([leap[0], "-o", tmp_path / "x", "--fps", "0"], "--fps must be a frame rate above 0 and at most 1000, got 0"),
    ):
        status, _, err = _run(capsys, "db", "build", *argv)
        assert status == 2 and message in err and err.count("\n") == 1, err
    assert not (tmp_path / "x").exists()


def test_gltf_with_several_animations_gets_fingers_in_one_and_keeps_the_others(shared_assets, capsys, tmp_path):
    from usdhands.formats.io import read_asset
    from usdhands.model.hand_detection import detect_hands

    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    out = tmp_path / "robot.glb"
    status, text, err = _run(capsys, "synthesize", src, "-o", out)
    assert status == 0, err
    assert text.splitlines()[0] == ("animation 'Dance', the first of 14 in the file (--animation NAME for another, "
                                    "or all; the others are written unchanged)")
    status, text, err = _run(capsys, "synthesize", src, "-o", tmp_path / "wave.glb", "--animation", "Wave", "--json")
    assert status == 0, err
    report = json.loads(text)
    assert report["animation"] == "Wave" and report["animations_in_file"] == 14
    a, b = read_asset(src), read_asset(out)
    assert [c.name for c in b.clips] == [c.name for c in a.clips] and len(b.meshes) == len(a.meshes)
    hm = detect_hands(a.skeletons[0])
    fingers = sorted(a.clips[0].skeleton.index(j) for s in hm.sides for j in s.finger_joints)
    for ca, cb in zip(a.clips, b.clips):
        if ca.name == "Dance":
            body = [j for j in range(ca.num_joints) if j not in fingers]
            assert np.array_equal(ca.rotations[:, body], cb.rotations[:, body])
            assert not np.allclose(ca.rotations[:, fingers], cb.rotations[:, fingers], atol=1e-3)
        else:
            assert np.array_equal(ca.rotations, cb.rotations) and np.array_equal(ca.translations, cb.translations)


def test_bundled_database_is_what_the_current_code_builds():
    # a change to features, segmentation or finger transfer must come with
    # `usdhands db build --samples -o usdhands/data/gesture_db`
    from usdhands.algorithms.synthesis.database import build_database
    from usdhands.jobs.inputs import bundled_database_path, sample_database_items

    shipped = load_database(bundled_database_path())
    fresh = build_database(sample_database_items(), fps=30.0)
    for name in ("tracks", "segments", "dof_index"):
        assert np.array_equal(np.asarray(getattr(shipped, name)), getattr(fresh, name)), name
    for name in ("features", "fingers"):  # float32 on disk; allow last-bit differences of other BLAS builds
        assert np.allclose(np.asarray(getattr(shipped, name)), getattr(fresh, name), rtol=0, atol=1e-3), name
    ms, mf = shipped.manifest(), fresh.manifest()
    for key in ("fps", "dofs", "clips", "labels", "segmentation", "counts"):
        assert ms[key] == mf[key], key
    assert ms["reach_cm"] == pytest.approx(mf["reach_cm"])
    for side in ("left", "right"):
        a, b = ms["hands"][side]["joints"], mf["hands"][side]["joints"]
        assert [(j["name"], j["parent"], j["slot"]) for j in a] == [(j["name"], j["parent"], j["slot"]) for j in b]
        assert np.allclose([j["offset_cm"] + j["rotation"] for j in a], [j["offset_cm"] + j["rotation"] for j in b])


def test_cesium_man_without_fingers_is_refused_clearly(shared_assets, capsys, tmp_path):
    src = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    status, _, err = _run(capsys, "synthesize", src, "-o", tmp_path / "c.usdz")
    assert status == 2 and "unknown file extension '.usdz'; writable: .bvh, .glb, .gltf, .usd, .usda, .usdc" in err
    out = tmp_path / "c.usdc"  # a package is read, written as a plain USD layer
    status, _, err = _run(capsys, "synthesize", src, "-o", out)
    assert status == 2 and err.count("\n") == 1
    assert err.startswith(f"usdhands: error: {src}: no hand found in skeleton ")
    assert "saw 19 joints: Skeleton_torso_joint_1" in err
    status, _, err = _run(capsys, "synthesize", src, "-o", out, "--graft-hands")
    assert status == 2 and err == (f"usdhands: error: {src}: --graft-hands works on skeleton-only files (BVH, USD "
                                   f"without skinned meshes): this file has skinned meshes, which would need new "
                                   f"skin weights\n")
    assert not out.exists()


def test_graft_hands_on_a_usd_skeleton_rebuilds_the_removed_fingers(sample_assets, capsys, tmp_path):
    from usdhands.formats.io import write_asset
    from usdhands.model.asset import Asset
    from usdhands.model.hand_detection import detect_hands

    full = read_clip(sample_assets / "conversation_bodyonly.usdc")
    sk = full.skeleton
    hm = detect_hands(sk)
    fingers = {sk.index(j) for h in hm.sides for j in h.finger_joints}
    keep = [j for j in range(sk.num_joints) if not fingers.intersection(sk.chain_to_root(j))]
    sub = sk.subset(keep)
    body = full.replace(skeleton=sub, rotations=full.rotations[:, keep], translations=full.translations[:, keep],
                        scales=full.scales[:, keep])
    src = tmp_path / "body_without_fingers.usda"
    write_asset(Asset("memory", [sub], [body], []), src)
    status, _, err = _run(capsys, "synthesize", src, "-o", tmp_path / "layer.usda", "--graft-hands", "--as-layer")
    assert status == 2 and err == (f"usdhands: error: {src}: --as-layer cannot add joints to the skeleton it overrides; "
                                   f"with --graft-hands the output is a new file (drop --as-layer)\n")
    assert not (tmp_path / "layer.usda").exists()
    status, out, err = _run(capsys, "synthesize", src, "-o", tmp_path / "grafted.usda", "--graft-hands", "--json")
    assert status == 0, err
    report = json.loads(out)
    assert len(report["grafted_joints"]) == sk.num_joints - len(keep) == 40
    back = read_clip(tmp_path / "grafted.usda")
    assert back.skeleton.up_axis == sk.up_axis and back.skeleton.meters_per_unit == sk.meters_per_unit
    names = back.skeleton.short_names
    # the database's hand is the generated humanoid's: the grafted joints are the removed ones, in place
    assert sorted(names) == sorted(sk.short_names)
    order = [names.index(n) for n in sk.short_names]
    assert np.abs(back.skeleton.rest_world_positions()[order] - sk.rest_world_positions()).max() < 1e-9
    kept = [names.index(n) for n in sub.short_names]
    assert np.array_equal(back.rotations[:, kept], body.rotations) or \
        np.abs(back.rotations[:, kept] - body.rotations).max() < 1e-6
    new = [names.index(sk.short_names[j]) for j in sorted(fingers)]
    assert np.ptp(back.rotations[:, new], axis=0).max() > 0.05


def test_graph_plot_of_a_large_k_draws_at_most_eight_candidates_per_row(tmp_path):
    from types import SimpleNamespace

    import matplotlib.image

    from usdhands.jobs.plots.synthesis import plot_graph

    k = 400
    res = SimpleNamespace(side="right", candidates=np.arange(3 * k).reshape(3, k),
                          segment_costs=np.sort(np.random.default_rng(0).random((3, k)) * 100, axis=1),
                          path=np.array([0, 250, 3]))
    labels = [f"type{i % 7}" for i in range(3 * k)]
    small = plot_graph(SimpleNamespace(**{**vars(res), "candidates": res.candidates[:, :8],
                                          "segment_costs": res.segment_costs[:, :8], "path": np.array([0, 7, 3])}),
                       labels, tmp_path / "k8.png")
    big = plot_graph(res, labels, tmp_path / "k400.png")
    assert matplotlib.image.imread(big).shape == matplotlib.image.imread(small).shape
    assert big.stat().st_size < 150_000


def test_db_build_warns_about_a_body_only_clip_with_frozen_fingers(sample_assets, capsys, tmp_path):
    frozen, real = sample_assets / "conversation_bodyonly.glb", sample_assets / "conversation.glb"
    status, _, err = _run(capsys, "db", "build", frozen, real, "-o", tmp_path / "db")
    assert status == 0
    assert err == (f"usdhands: warning: {frozen}: the left and right hand's fingers never move (a body-only clip?); "
                   f"its frozen fingers go into the database as they are\n")
    assert load_database(tmp_path / "db").clips[0]["source"] == str(frozen)


def test_db_info_of_the_bundled_database(capsys):
    import jsonschema

    from usdhands.algorithms.synthesis.database import database_schema
    from usdhands.jobs.inputs import bundled_database_path

    status, out, _ = _run(capsys, "db", "info")
    assert status == 0
    assert out.splitlines()[0] == (f"database {bundled_database_path()}: 64 clips, 128 hand tracks, 347 segments, "
                                   f"10560 frames at 30 fps (5.9 min), 45 finger DOFs, reach 110.5 cm")
    assert out.splitlines()[1].split() == ["label", "left", "segments", "right", "segments"]
    assert [ln.split()[0] for ln in out.splitlines()[3:]] == ["attention", "big", "doubt_shrug", "ok",
                                                              "palm_presentation", "small", "turn", "wipe"]
    status, out, _ = _run(capsys, "db", "info", bundled_database_path(), "--json")
    manifest = json.loads(out)
    jsonschema.validate(manifest, database_schema())
    assert manifest["format"] == "usdhands-finger-database" and manifest["version"] == 2
    assert manifest["counts"] == {"clips": 64, "tracks": 128, "segments": 347, "frames": 10560}


def test_an_input_segment_with_no_candidate_within_the_length_factor_widens_it():
    from usdhands.algorithms.synthesis.synthesize import db_side_segments, synthesize_hand
    from usdhands.jobs.inputs import bundled_database_path

    db = load_database(bundled_database_path())
    right = db_side_segments(db, "right")
    lengths = db.segments[right, 1] - db.segments[right, 0]
    s = int(right[np.nonzero(lengths == 11)[0][0]])
    a = int(db.segments[s, 0])
    # 6 frames: every database segment (>= 10 frames) is beyond the factor 1.5 (9 frames), but
    # those up to 11 frames can still be warped (steps of 2): the 11-frame one taken every other frame
    rows = a + np.arange(0, 11, 2)
    res = synthesize_hand(np.asarray(db.features[rows], dtype=np.float64), db, "right")
    assert res.search.candidates[0] == 0  # nothing within the factor
    assert res.chosen.tolist() == [s] and res.segment_costs[0, 0] == pytest.approx(0.0, abs=1e-9)
    # the same motion within a tolerance: every other frame of the segment, steps of two frames
    # limited to the database's 99.5th-percentile step
    got, target = res.curves[:, db.dof_index], np.asarray(db.fingers[rows], dtype=np.float64)
    assert np.allclose(got[0], target[0], atol=1e-5)
    assert np.abs(got - target).mean() < 0.5 and (np.abs(np.diff(got, axis=0)) <= db.step_limits(99.5) + 1e-9).all()


def test_hands_right_leaves_the_left_fingers_as_they_were(sample_assets, capsys, tmp_path):
    from usdhands.model.hand_detection import detect_hands

    src = sample_assets / "conversation.glb"  # fingers animated: the left ones must survive
    status, out, err = _run(capsys, "synthesize", src, "-o", tmp_path / "o.glb", "--hands", "right", "--json")
    assert status == 0, err
    assert list(json.loads(out)["hands"]) == ["right"]
    a, b = read_clip(src), read_clip(tmp_path / "o.glb")
    hm = detect_hands(a.skeleton)
    left = [a.skeleton.index(j) for j in hm.left.finger_joints]
    right = [a.skeleton.index(j) for j in hm.right.finger_joints]
    assert np.array_equal(a.rotations[:, left], b.rotations[:, left])
    assert not np.allclose(a.rotations[:, right], b.rotations[:, right], atol=1e-4)


def test_synthesize_warns_when_its_segmentation_differs_from_the_databases(sample_assets, capsys, tmp_path):
    src = sample_assets / "conversation_bodyonly.glb"
    cfg = tmp_path / "seg.json"
    cfg.write_text('{"segmentation": {"speed_threshold_cm_s": 4}, "segment_cost": {"k": 3}}')
    status, _, err = _run(capsys, "synthesize", src, "-o", tmp_path / "a.glb", "--config", cfg)
    assert status == 0
    assert err == ("usdhands: warning: the input is segmented with other values than the database was "
                   "(speed_threshold_cm_s 4 here, 8 there); rebuild the database with the same --config for like "
                   "segments\n")
    cfg.write_text('{"segment_cost": {"k": 3}}')  # other values than segmentation: no warning
    status, _, err = _run(capsys, "synthesize", src, "-o", tmp_path / "b.glb", "--config", cfg)
    assert status == 0 and err == ""


def test_db_build_from_every_animation_of_a_file(shared_assets, capsys, tmp_path):
    from usdhands.formats.io import read_asset

    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    status, out, err = _run(capsys, "db", "build", src, "-o", tmp_path / "db", "--animation", "all",
                            "--labels", r"^(\w+)Expressive", "--json")
    assert status == 0, err
    asset = read_asset(src)
    db = load_database(tmp_path / "db")
    assert [c["name"] for c in db.clips] == [c.name for c in asset.clips] and len(db.clips) == 14
    assert {c["label"] for c in db.clips} == {"Robot"} and {c["source"] for c in db.clips} == {str(src)}
    assert len(db.tracks) == 28
    # the hand-keyed clips that never bend the fingers are named in the warnings; ThumbsUp and
    # Wave bend the right hand's (an idle left hand is normal in a one-handed gesture)
    warned = re.findall(r"\(animation '(\w+)'\): the left and right hand's fingers never move", err)
    assert sorted(warned) == sorted(c.name for c in asset.clips if c.name not in ("ThumbsUp", "Wave"))
    assert err.count("\n") == 12
    # a track holds its animation's frames at 30 fps
    wave = [c.name for c in asset.clips].index("Wave")
    t = db.tracks[db.tracks[:, 2] == wave][0]
    assert t[1] - t[0] == int(np.floor(asset.clips[wave].duration * 30 + 1e-6)) + 1


def test_synthesize_every_animation_of_a_gltf(shared_assets, capsys, tmp_path, gltf_validator):
    from usdhands.formats.io import read_asset
    from usdhands.model.hand_detection import detect_hands

    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    out = tmp_path / "all.glb"
    status, text, err = _run(capsys, "synthesize", src, "-o", out, "--animation", "all", "--json")
    assert status == 0, err
    report = json.loads(text)
    names = [r["animation"] for r in report["animations"]]
    a, b = read_asset(src), read_asset(out)
    assert names == [c.name for c in a.clips] == [c.name for c in b.clips] and len(names) == 14
    assert report["output"] == str(out) and sorted(p.name for p in tmp_path.iterdir()) == ["all.glb"]
    hm = detect_hands(a.skeletons[0])
    fingers = sorted(a.clips[0].skeleton.index(j) for s in hm.sides for j in s.finger_joints)
    body = [j for j in range(a.clips[0].num_joints) if j not in fingers]
    for ca, cb in zip(a.clips, b.clips):
        assert np.array_equal(ca.rotations[:, body], cb.rotations[:, body]), ca.name
        assert np.array_equal(ca.translations, cb.translations), ca.name
        assert not np.allclose(ca.rotations[:, fingers], cb.rotations[:, fingers], atol=1e-3), ca.name
    # each animation as synthesizing it alone gives
    assert _run(capsys, "synthesize", src, "-o", tmp_path / "wave.glb", "--animation", "Wave")[0] == 0
    wave = [c.name for c in a.clips].index("Wave")
    assert np.array_equal(read_asset(tmp_path / "wave.glb").clips[wave].rotations, b.clips[wave].rotations)
    before, after = gltf_validator(src, out)
    assert after["numErrors"] <= before["numErrors"]
    status, _, err = _run(capsys, "synthesize", src, "-o", tmp_path / "x.glb", "--animation", "all", "--graft-hands")
    assert status == 2 and err == f"usdhands: error: {src}: --animation all works without --graft-hands and --as-layer\n"


def test_a_long_hold_is_cut_in_its_middle_whatever_its_noise():
    from usdhands.algorithms.synthesis.segmentation import segment_by_speed

    rng = np.random.default_rng(5)
    base = np.r_[np.full(20, 40.0), np.zeros(100), np.full(20, 40.0)]  # a 3.3 s hold between motions
    cuts = set()
    for _ in range(20):
        noisy = base + np.where(base == 0, rng.uniform(0, 1e-4, len(base)), 0.0)
        cuts.add(tuple(segment_by_speed(noisy, 30, 8.0, 0.33, 2.0).tolist()))
    assert cuts == {(0, 20, 70, 120, 140)}
    # a real minimum still wins over the middle
    dip = base.copy()
    dip[20:120] = 3.0
    dip[75] = 0.5  # the middle is frame 70
    assert segment_by_speed(dip, 30, 8.0, 0.33, 2.0).tolist() == [0, 20, 75, 120, 140]


def test_the_same_motion_from_gltf_bvh_and_usd_gets_the_same_fingers(sample_assets):
    from usdhands.algorithms.synthesis.synthesize import synthesize_clip
    from usdhands.jobs.inputs import bundled_database_path
    from usdhands.model.hand_detection import detect_hands

    db = load_database(bundled_database_path())
    results = []
    for ext in ("glb", "bvh", "usdc"):  # float32, 6-decimal text, float32: holds differ by noise
        clip = read_clip(sample_assets / f"conversation_bodyonly.{ext}")
        results.append(synthesize_clip(clip, detect_hands(clip.skeleton), db))
    for side in ("left", "right"):
        first = results[0].hands[side]
        for other in results[1:]:
            assert np.array_equal(first.bounds, other.hands[side].bounds)
            # what matters is the motion, not which of two near-equal candidates is taken (rest
            # segments of an idle hand cost ~0 alike): the same finger curves within a tolerance
            diff = np.abs(first.curves - other.hands[side].curves)
            assert diff.mean() < 0.1 and np.percentile(diff.max(axis=1), 99) < 1.0, side


def test_unlabelled_database_says_no_label(shared_assets, capsys, tmp_path):
    leap = shared_assets / "leap_hands"
    status, out, _ = _run(capsys, "db", "build", leap, "-o", tmp_path / "db")
    assert status == 0 and out.splitlines()[-1].split()[:2] == ["(no", "label)"]
    status, out, _ = _run(capsys, "synthesize", leap / "fingers-ok.bvh", "-o", tmp_path / "o.bvh", "--db", tmp_path / "db")
    assert status == 0 and out.splitlines()[2].split()[2:4] == ["(no", "label)"]
    assert "None" not in out


def test_a_plot_folder_that_is_a_file_fails_before_any_work(sample_assets, capsys, tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    out = tmp_path / "o.glb"
    status, _, err = _run(capsys, "synthesize", sample_assets / "conversation_bodyonly.glb", "-o", out, "--plot", afile)
    assert status == 2 and err == f"usdhands: error: {afile}: --plot needs a folder; this is a file\n"
    assert not out.exists()
    status, _, err = _run(capsys, "evaluate", sample_assets / "gestures", "--labels", r"^([a-z_]+)_\d+",
                          "--plot", afile / "sub")
    assert status == 2 and err == f"usdhands: error: {afile / 'sub'}: --plot folder cannot be made: '{afile}' is a file\n"


def test_synthesize_uses_the_hand_map_recorded_in_a_usd_file(sample_assets, tmp_path, capsys):
    """A UsdHandsHandMapAPI map naming only the right hand: the left hand's fingers stay as they were."""
    from usdhands.formats.io import write_clip
    from usdhands.model.hand_detection import detect_hands
    from usdhands.model.handmap import HandMap

    src = sample_assets / "conversation_bodyonly.usdc"
    clip = read_clip(src)
    detected = detect_hands(clip.skeleton)
    marked = write_clip(src, clip, tmp_path / "marked.usdc", hand_map=HandMap(right=detected.right))
    out = tmp_path / "out.usdc"
    status, _, err = _run(capsys, "synthesize", marked, "-o", out)
    assert status == 0, err
    result = read_clip(out)
    left = [clip.skeleton.index(j) for j in detected.left.finger_joints]
    right = [clip.skeleton.index(j) for j in detected.right.finger_joints]
    np.testing.assert_array_equal(result.rotations[:, left], clip.rotations[:, left])
    assert np.abs(result.rotations[:, right] - clip.rotations[:, right]).max() > 0.1

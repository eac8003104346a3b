"""K-fold held-out synthesis (``evaluate --folds``): windows, baselines, feature sets, the command."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from synthesis_data import gesture_set, tiny_handmap

from usdhands.algorithms.synthesis.database import DatabaseClip
from usdhands.algorithms.synthesis.kfold import METHODS, kfold_evaluation, parse_feature_set, window_bounds
from usdhands.cli import main
from usdhands.formats.io import write_asset
from usdhands.model import HandMap
from usdhands.model.asset import Asset


def _run(capsys, *argv):
    status = main([str(a) for a in argv])
    out = capsys.readouterr()
    return status, out.out, out.err


def test_windows_cover_the_take_once():
    e = window_bounds(10, 113, 5)
    assert e[0] == 10 and e[-1] == 113 and (np.diff(e) >= 20).all() and (np.diff(e) <= 21).all()


def test_feature_set_names_parse():
    assert parse_feature_set("wrist_pos+0.5rot") == [("wrist_pos", 1.0), ("wrist_rot", 0.5)]
    assert parse_feature_set("wrist_pos+0.1*vel+0.5other_wrist_pos+rot") == [
        ("wrist_pos", 1.0), ("wrist_vel", 0.1), ("other_wrist_pos", 0.5), ("other_wrist_rot", 1.0)]
    assert parse_feature_set("elbow_pos+wrist_rot") == [("elbow_pos", 1.0), ("wrist_rot", 1.0)]
    with pytest.raises(ValueError, match=r"Cannot read feature set 'hand_pos': term 'hand_pos' is not"):
        parse_feature_set("hand_pos")
    with pytest.raises(ValueError, match=r"term 'pos' names no joint"):
        parse_feature_set("pos")


@pytest.fixture(scope="module")
def twins():
    """Three gestures each recorded twice identically: every held-out take has its twin in the database."""
    items = []
    for label, clip in gesture_set(1, seed=2)[:3]:
        items.append(DatabaseClip(clip, tiny_handmap(), label))
        items.append(DatabaseClip(clip.replace(name=clip.name + "_twin"), tiny_handmap(), label))
    return items


def test_a_take_whose_twin_is_in_the_database_is_found_again(twins):
    # short takes are held out whole, in fold (take index mod K): with 2 folds a take and its
    # twin (next index) are never held out together
    r = kfold_evaluation(twins, folds=2)
    total = sum(it.clip.resample(30.0).num_frames for it in twins) * 2  # two hands each
    assert r["frames"] == total and r["windows"] == len(twins) * 2 and set(r["methods"]) == set(METHODS)
    m = r["methods"]
    assert m["nearest_frame"]["error_deg"] < 1e-3  # the twin's frame, exactly
    assert m["synthesis"]["error_deg"] < 0.2 * m["mean_pose"]["error_deg"]
    assert m["mean_pose"]["repeated_share"] == 1.0 and m["mean_pose"]["speed_deg_s"] == pytest.approx(0, abs=1e-9)
    assert m["synthesis"]["largest_jump_deg"] <= 1.01 * r["truth"]["largest_jump_deg"]
    assert 0.7 < m["synthesis"]["speed_ratio"] < 1.3
    assert m["synthesis"]["repeated_share"] <= r["truth"]["repeated_share"] + 0.05
    # the most expressive quarter is farther from the mean pose than the whole
    assert m["mean_pose"]["expressive_error_deg"] > m["mean_pose"]["error_deg"]
    assert r["ratios"]["to_mean_pose"] == pytest.approx(m["synthesis"]["error_deg"] / m["mean_pose"]["error_deg"])
    w = r["worst_window"]
    assert len(w["dofs"]) == 3 and np.shape(w["truth"]) == np.shape(w["synthesis"]) == (3, w["frames"][1] - w["frames"][0])


def test_long_takes_are_cut_into_windows_and_feature_sets_compare(twins):
    hm = tiny_handmap()
    no_shoulder = HandMap(*(dataclasses.replace(h, shoulder=None) for h in (hm.left, hm.right)))
    long = [DatabaseClip(it.clip, no_shoulder, it.label) for it in twins]
    r = kfold_evaluation(long, folds=3, min_window_s=0.5,
                         feature_sets=["wrist_pos+0.5rot", "wrist_pos+0.5rot+0.5elbow_pos", "shoulder_pos"])
    assert r["windows"] == 3 * 2 * len(long)
    fs = r["feature_sets"]
    # the configuration's own features (db features) give the same synthesis
    assert fs["wrist_pos+0.5rot"]["error_deg"] == pytest.approx(r["methods"]["synthesis"]["error_deg"], rel=0.02)
    assert set(fs) == {"wrist_pos+0.5rot", "wrist_pos+0.5rot+0.5elbow_pos"}
    assert r["feature_sets_left_out"] == ["shoulder_pos"]  # this hand map has no shoulder


def test_kfold_refuses_too_few_folds(twins):
    with pytest.raises(ValueError, match="at least 2 folds"):
        kfold_evaluation(twins, folds=1)
    with pytest.raises(ValueError, match="need more than one take"):
        kfold_evaluation(twins[:1], folds=3)


def test_evaluate_folds_command(tmp_path, capsys):
    paths = []
    for label, clip in gesture_set(1, seed=1)[:4]:
        p = tmp_path / f"{clip.name}.bvh"
        write_asset(Asset("memory", [clip.skeleton], [clip], []), p)
        paths.append(p)
    status, out, err = _run(capsys, "evaluate", "--folds", "2", *paths, "--json", "--plot", tmp_path / "plots",
                            "--feature-sets", "wrist_pos+0.5rot+0.05vel")
    assert status == 0, err
    r = json.loads(out)
    assert r["folds"] == 2 and set(r["methods"]) == set(METHODS) and list(r["feature_sets"]) == ["wrist_pos+0.5rot+0.05vel"]
    assert [p.rsplit("/", 1)[1] for p in r["plots"]] == ["kfold_errors.png", "kfold_worst_window.png"]
    assert all((tmp_path / "plots" / n).stat().st_size > 1000 for n in ("kfold_errors.png", "kfold_worst_window.png"))
    status, out, err = _run(capsys, "evaluate", "--folds", "2", *paths)
    assert status == 0, err
    lines = out.splitlines()
    assert lines[0].startswith("2-fold held-out synthesis over")
    assert [ln.split()[0] for ln in lines[3:9]] == list(METHODS)
    assert lines[9].startswith("synthesis / mean pose ")
    for argv, message in ((["--folds", "1"], "--folds must be at least 2, got 1"),
                          (["--feature-sets", "wrist_pos"], "--feature-sets needs --folds K"),
                          (["--folds", "2", "--holdout"], "give --holdout or --folds, not both"),
                          (["--folds", "2", "--feature-sets", "hand_pos"], "Cannot read feature set 'hand_pos'")):
        status, out, err = _run(capsys, "evaluate", *paths, *argv)
        assert status == 2 and out == "" and err.startswith(f"usdhands: error: {message}"), (argv, err)


def test_nothing_of_the_held_out_take_reaches_synthesis():
    """K-fold synthesizes with ``segments=`` (the segments outside the held-out windows): the
    result must be exactly that of a database built without the held-out take, although
    the held-out take's fingers jitter by ±30° every frame and so raise the step limits
    (and the moving DOFs) of the whole database: a statistic taken from all frames leaks."""
    from usdhands.algorithms.synthesis.config import SynthesisConfig
    from usdhands.algorithms.synthesis.database import build_database
    from usdhands.algorithms.synthesis.synthesize import synthesize_hand
    from usdhands.model.rotations import euler_deg_to_quat, quat_multiply

    clips = [c for _, c in gesture_set(2, seed=3)]
    held = clips[0]
    rot = held.rotations.copy()
    jitter = np.zeros((len(rot), 3))
    jitter[:, 2] = np.where(np.arange(len(rot)) % 2 == 0, 30.0, -30.0)  # flexion of this rig's fingers
    jitter[:, 0] = jitter[:, 2] / 30  # and a twist, which never moves in the other takes
    for j, name in enumerate(held.skeleton.joint_names):
        if name.startswith("RightHand") and name[-1].isdigit():
            rot[:, j] = quat_multiply(rot[:, j], euler_deg_to_quat(jitter, "XYZ"))
    hm = tiny_handmap()
    items = [DatabaseClip(held.replace(rotations=rot), hm, "held")] + [DatabaseClip(c, hm, "x") for c in clips[1:]]
    full, clean = build_database(items), build_database(items[1:])
    cfg = SynthesisConfig().with_values(stitching={"step_percentile": 90.0})
    t = int(np.nonzero((full.tracks[:, 2] == 0) & (full.tracks[:, 3] == 1))[0][0])
    a, b = full.tracks[t, :2]
    feats = np.asarray(full.features[a:b], dtype=np.float64)
    outside = full.segment_clip() != 0
    got = synthesize_hand(feats, full, "right", cfg, segments=outside)
    want = synthesize_hand(feats, clean, "right", cfg)
    np.testing.assert_allclose(got.curves, want.curves, atol=1e-9)
    # the case is one where a leak changes the result: the jitter moves DOFs that never move
    # elsewhere and raises the step limits, and the limits bind in the synthesized motion
    frames = full.segment_frames(outside)
    assert full.moving_dofs().sum() > full.moving_dofs(frames).sum()
    assert (full.moving_dofs(frames) == clean.moving_dofs()).all()
    leaky, own = full.step_limits(90.0), full.step_limits(90.0, frames)
    np.testing.assert_allclose(own, clean.step_limits(90.0))
    steps = np.abs(np.diff(got.curves[:, full.dof_index], axis=0)).max(axis=0)
    binding = np.isclose(steps, own, rtol=0, atol=1e-9) & (own > 0)
    assert binding.any() and (leaky[binding] > own[binding] + 0.1).all()
    # leave-one-out (exclude_clips) is held to the same rule
    np.testing.assert_allclose(synthesize_hand(feats, full, "right", cfg, exclude_clips=(0,)).curves, want.curves,
                               atol=1e-9)

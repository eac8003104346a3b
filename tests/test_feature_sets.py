"""Feature sets behind the segment cost, chosen by configuration (``segment_cost.features``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from synthesis_data import gesture_set, tiny_handmap

from usdhands.algorithms.synthesis.config import SynthesisConfig, load_synthesis_config
from usdhands.algorithms.synthesis.database import DatabaseClip, build_database, load_database, save_database
from usdhands.algorithms.synthesis.feature_sets import hand_columns, mirror_columns, parse_feature_set
from usdhands.algorithms.synthesis.kfold import kfold_evaluation
from usdhands.algorithms.synthesis.synthesize import db_weighted_features, synthesize_clip
from usdhands.cli import main
from usdhands.errors import ConfigError
from usdhands.formats.io import write_asset
from usdhands.model.asset import Asset
from usdhands.model.rotations import euler_deg_to_quat, quat_angle_deg, quat_multiply


def test_config_names_a_feature_set_or_the_wrist_weights_not_both(tmp_path):
    cfg = SynthesisConfig.from_dict({"segment_cost": {"features": "wrist_pos+0.5rot+0.5other_wrist_vel"}})
    assert cfg.segment_cost.features == "wrist_pos+0.5rot+0.5other_wrist_vel"
    with pytest.raises(ValueError, match="without w_position and w_rotation"):
        SynthesisConfig.from_dict({"segment_cost": {"features": "wrist_pos", "w_rotation": 0.5}})
    with pytest.raises(ValueError, match="Cannot read feature set 'wrist_pos\\+hand_rot'"):
        SynthesisConfig.from_dict({"segment_cost": {"features": "wrist_pos+hand_rot"}})
    bad = tmp_path / "bad.json"
    for value, message in (("hand_pos", "invalid synthesis configuration at segment_cost.features"),
                           (3, "invalid synthesis configuration at segment_cost.features"),
                           ("pos", "names no joint")):
        bad.write_text(json.dumps({"segment_cost": {"features": value}}))
        with pytest.raises(ConfigError, match=message):
            load_synthesis_config(bad)
    assert parse_feature_set("wrist_pos+0.5rot+wrist_pos") == [("wrist_pos", 2.0), ("wrist_rot", 0.5)]


@pytest.fixture(scope="module")
def takes():
    return [DatabaseClip(c, tiny_handmap(), label) for label, c in gesture_set(2, seed=4)]


def test_database_stores_the_named_columns_mirrored_and_round_trips(takes, tmp_path):
    keys = ["elbow_pos", "other_wrist_vel", "elbow_rot"]
    db = build_database(takes[:3], mirror=True, arm_features=keys)
    assert db.arm_feature_names == tuple(keys) and db.arm_features.shape == (db.num_frames, 3 + 3 + 9)
    item = takes[0]
    want = hand_columns(item.clip, item.handmap, "right", keys, db.reach_cm)
    t = int(np.nonzero((db.tracks[:, 2] == 0) & (db.tracks[:, 3] == 1) & (db.tracks[:, 4] == 0))[0][0])
    a, b = db.tracks[t, :2]
    np.testing.assert_allclose(db.arm_features[a:b], np.concatenate([want[k] for k in keys], axis=1), atol=1e-3)
    # the right hand's mirrored twin is a left track whose columns are the mirrored ones
    m = int(np.nonzero((db.tracks[:, 2] == 0) & (db.tracks[:, 3] == 0) & (db.tracks[:, 4] == 1))[0][0])
    ma, mb = db.tracks[m, :2]
    np.testing.assert_allclose(db.arm_features[ma:mb], np.concatenate([mirror_columns(k, want[k]) for k in keys], 1),
                               atol=1e-3)
    # velocity is the derivative of the other hand's position (cm/s)
    other = hand_columns(item.clip, item.handmap, "left", ["wrist_pos"], db.reach_cm)["wrist_pos"]
    np.testing.assert_allclose(want["other_wrist_vel"], np.gradient(other, axis=0) * 30.0)
    path = save_database(db, tmp_path / "db")
    manifest = json.loads((path / "manifest.json").read_text())
    assert manifest["arm_features"] == keys and manifest["arrays"]["arm_features"]["shape"] == [db.num_frames, 15]
    back = load_database(path)
    assert back.arm_feature_names == tuple(keys) and np.array_equal(back.arm_features, db.arm_features)
    np.save(path / "arm_features.npy", np.zeros((db.num_frames, 12), np.float32))
    manifest["arrays"]["arm_features"]["shape"] = [db.num_frames, 12]
    (path / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ConfigError, match=r"array 'arm_features' has shape \[\d+, 12\], the features"):
        load_database(path)
    plain = build_database(takes[:3])
    assert plain.arm_features is None and "arm_features" not in plain.manifest()
    with pytest.raises(ValueError, match="holds no 'elbow_pos' features"):
        db_weighted_features(plain, SynthesisConfig.from_dict({"segment_cost": {"features": "wrist_pos+elbow_pos"}}))


def _variant(clip, donor):
    """``clip`` with the left arm of ``donor`` and the right fingers curled 40° further."""
    sk = clip.skeleton
    rot = clip.rotations.copy()
    for name in ("LeftArm", "LeftForeArm", "LeftHand"):
        j = sk.index(name)
        rot[:, j] = donor.rotations[:len(rot), j]
    curl = np.zeros((len(rot), 3))
    curl[:, 2] = 40.0
    right = [j for j, n in enumerate(sk.joint_names) if n.startswith("RightHand") and n[-1].isdigit()]
    for j in right:
        rot[:, j] = quat_multiply(rot[:, j], euler_deg_to_quat(curl, "XYZ"))
    return clip.replace(rotations=rot, name=clip.name + "_b"), right


def test_the_other_hand_tells_apart_what_the_wrist_cannot(takes):
    """Two takes whose right wrists move alike to the bit, with other right fingers and another
    left arm: the paper's wrist features cannot tell them apart (tied costs, so the mix of
    candidates lands between them), the other wrist's position can (the own take costs 0)."""
    a = takes[0].clip
    donor = next(it.clip for it in takes[1:] if it.clip.num_frames >= a.num_frames and it.label != takes[0].label)
    b, right = _variant(a, donor)
    hm = tiny_handmap()
    cfg = SynthesisConfig.from_dict({"segment_cost": {"features": "wrist_pos+0.5rot+other_wrist_pos"}})
    paper = SynthesisConfig()
    errors = {}
    for name, c in (("paper", paper), ("other", cfg)):
        db = build_database([DatabaseClip(a, hm, "a"), DatabaseClip(b, hm, "b")],
                            arm_features=["other_wrist_pos"] if c is cfg else ())
        out = synthesize_clip(b, hm, db, c, hands=("right",)).clip
        errors[name] = float(quat_angle_deg(out.rotations[:, right], b.rotations[:, right]).mean())
    # (not 0: where the wrist holds still, DTW ties between holding and stepping, and the played
    # warp of the own take drifts by a few frames)
    assert errors["other"] < 0.1 * errors["paper"] and errors["paper"] > 8.0, errors
    # the paper's weights written as a feature set are the paper's synthesis
    db = build_database([DatabaseClip(a, hm, "a"), DatabaseClip(b, hm, "b")])
    same = SynthesisConfig.from_dict({"segment_cost": {"features": "wrist_pos+0.5rot"}})
    np.testing.assert_allclose(synthesize_clip(b, hm, db, same).clip.rotations,
                               synthesize_clip(b, hm, db, paper).clip.rotations, atol=1e-12)


def test_kfold_synthesizes_with_the_configured_features(takes):
    cfg = SynthesisConfig.from_dict({"segment_cost": {"features": "wrist_pos+0.5rot+0.05vel"}})
    r = kfold_evaluation(takes, cfg, folds=2, feature_sets=["wrist_pos+0.5rot+0.05vel", "wrist_pos+0.5rot"])
    fs = r["feature_sets"]
    assert r["methods"]["synthesis"]["error_deg"] == pytest.approx(fs["wrist_pos+0.5rot+0.05vel"]["error_deg"],
                                                                   rel=0.02)
    assert fs["wrist_pos+0.5rot"]["error_deg"] != pytest.approx(fs["wrist_pos+0.5rot+0.05vel"]["error_deg"], rel=1e-6)


def _run(capsys, *argv):
    status = main([str(x) for x in argv])
    out = capsys.readouterr()
    return status, out.out, out.err


def test_db_build_and_synthesize_take_the_features_from_the_config(takes, tmp_path, capsys):
    files = []
    for item in takes[:4]:
        p = tmp_path / f"{item.clip.name}.bvh"
        write_asset(Asset("memory", [item.clip.skeleton], [item.clip], []), p)
        files.append(p)
    cfg = tmp_path / "elbow.json"
    cfg.write_text(json.dumps({"segment_cost": {"features": "wrist_pos+0.5rot+0.5elbow_pos"}}))
    status, out, err = _run(capsys, "db", "build", *files, "-o", tmp_path / "db", "--config", cfg, "--json")
    assert status == 0, err
    assert json.loads((tmp_path / "db" / "manifest.json").read_text())["arm_features"] == ["elbow_pos"]
    status, out, err = _run(capsys, "synthesize", files[0], "-o", tmp_path / "out.bvh", "--db", tmp_path / "db",
                            "--config", cfg)
    assert status == 0 and (tmp_path / "out.bvh").exists(), err
    # the bundled database holds the wrist features only: one line, nothing written
    status, out, err = _run(capsys, "synthesize", files[0], "-o", tmp_path / "out2.bvh", "--config", cfg)
    assert status == 2 and not (tmp_path / "out2.bvh").exists()
    assert err.startswith("usdhands: error: ") and "holds no elbow_pos features" in err and len(err.splitlines()) == 1

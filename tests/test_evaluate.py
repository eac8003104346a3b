"""``usdhands evaluate``, ``db build`` and ``synthesize`` on files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from synthesis_data import gesture_set, tiny_handmap

from usdhands.algorithms.synthesis.database import load_database
from usdhands.algorithms.synthesis.evaluation import (
    DEFAULT_PREDICTORS, evaluate_predictors, parse_predictor, prepare_eval_set,
)
from usdhands.cli import main
from usdhands.formats.io import read_clip, write_asset
from usdhands.model.asset import Asset


@pytest.fixture(scope="module")
def gesture_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("gestures")
    paths = []
    for label, clip in gesture_set(3, seed=1):
        p = folder / f"{clip.name}.bvh"
        write_asset(Asset("memory", [clip.skeleton], [clip], []), p)
        paths.append(p)
    return folder, paths


def _run(capsys, *argv):
    status = main([str(a) for a in argv])
    out = capsys.readouterr()
    return status, out.out, out.err


def test_predictor_names_parse():
    assert parse_predictor("wrist_pos+0.5rot") == [("wrist_pos", 1.0), ("wrist_rot", 0.5)]
    assert parse_predictor("0.25*elbow_rot + wrist_pos") == [("elbow_rot", 0.25), ("wrist_pos", 1.0)]
    with pytest.raises(ValueError, match=r"Cannot read predictor 'hand_pos': term 'hand_pos' is not"):
        parse_predictor("hand_pos")
    with pytest.raises(ValueError, match=r"term '0.5rot' names no joint"):
        parse_predictor("0.5rot")


def test_evaluate_json_matches_the_library_on_the_same_files(gesture_files, capsys, tmp_path):
    folder, paths = gesture_files
    status, out, err = _run(capsys, "evaluate", *paths, "--labels", r"^([a-z]+)_\d+", "--json",
                            "--plot", tmp_path / "plots")
    assert status == 0, err
    r = json.loads(out)
    # the layout of the issue: {"k", "segments", "predictors", "best", "confusion": {"labels", "matrix"}}
    assert [key for key in r if key in ("k", "segments", "predictors", "best", "confusion")] == [
        "k", "segments", "predictors", "best", "confusion"]
    assert r["k"] == 5 and list(r["predictors"]) == list(DEFAULT_PREDICTORS)
    assert "wrist_pos+0.5rot" in r["predictors"] and all(0 <= v <= 1 for v in r["predictors"].values())
    n_labels = len(r["confusion"]["labels"])
    matrix = np.array(r["confusion"]["matrix"])
    assert matrix.shape == (n_labels, n_labels) and np.allclose(matrix.sum(axis=1), 1.0)
    assert r["best"] == max(r["predictors"], key=r["predictors"].get)
    assert r["confusion"]["labels"] == sorted({p.name.split("_")[0] for p in paths})
    hm = tiny_handmap()
    items = [(p.name.split("_")[0], read_clip(p), hm) for p in paths]
    lib = evaluate_predictors(prepare_eval_set(items), DEFAULT_PREDICTORS, 5)
    assert r["segments"] == lib["segments"]
    for name, share in lib["predictors"].items():
        assert r["predictors"][name] == pytest.approx(share)
    assert r["predictors"]["wrist_pos+0.5rot"] > r["chance"]
    for png in ("predictors.png", "confusion.png"):
        f = tmp_path / "plots" / png
        assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and f.stat().st_size < 150_000


def test_evaluate_table_and_label_errors(gesture_files, capsys):
    folder, paths = gesture_files
    status, out, _ = _run(capsys, "evaluate", folder, "--labels", r"^([a-z]+)_", "--predictors",
                          "wrist_rot,wrist_pos+0.5rot", "--k", "3")
    assert status == 0
    assert "wrist_pos+0.5rot" in out and "(chance)" in out and "confusion (wrist_pos+0.5rot)" in out
    status, _, err = _run(capsys, "evaluate", *paths[:2], "--labels", r"^(\d+)_")
    assert status == 2
    assert err.strip() == f"usdhands: error: {paths[0]}: --labels '^(\\d+)_' does not match the file name '{paths[0].name}'"
    status, _, err = _run(capsys, "evaluate", *paths[:2])
    assert status == 2 and "evaluate needs --labels REGEX or --labels-file CSV" in err


def test_evaluate_labels_file(gesture_files, capsys, tmp_path):
    folder, paths = gesture_files
    csv = tmp_path / "labels.csv"
    csv.write_text("".join(f"{p.name},{p.name.split('_')[0]}\n" for p in paths))
    status, out, _ = _run(capsys, "evaluate", *paths, "--labels-file", csv, "--json", "--predictors", "wrist_pos+0.5rot")
    status2, out2, _ = _run(capsys, "evaluate", *paths, "--labels", r"^([a-z]+)_", "--json", "--predictors",
                            "wrist_pos+0.5rot")
    assert status == status2 == 0
    assert json.loads(out) == json.loads(out2)


def test_holdout_beats_the_baselines(gesture_files, capsys):
    folder, paths = gesture_files
    status, out, err = _run(capsys, "evaluate", "--holdout", *paths, "--json")
    assert status == 0, err
    r = json.loads(out)
    m = r["methods"]
    assert set(m) == {"synthesis", "mean_pose", "random_segments", "nearest_wrist"}
    assert m["synthesis"]["error_deg"] < m["mean_pose"]["error_deg"]
    assert m["synthesis"]["error_deg"] < m["random_segments"]["error_deg"]
    assert m["mean_pose"]["speed_deg_s"] == pytest.approx(0.0, abs=1e-6)
    assert r["clips"] == len(paths)
    # the mean angular speed of the fingers, against the ground truth's: synthesis moves like
    # the truth, the frame-by-frame nearest neighbour flickers between takes
    truth = r["ground_truth_speed_deg_s"]
    assert truth > 1.0
    assert abs(m["synthesis"]["speed_deg_s"] - truth) < abs(m["nearest_wrist"]["speed_deg_s"] - truth)
    assert abs(m["synthesis"]["speed_deg_s"] - truth) < 0.5 * truth
    status, out, err = _run(capsys, "evaluate", "--holdout", *paths)
    assert status == 0, err
    lines = out.splitlines()
    assert lines[0].startswith(f"held-out synthesis over {len(paths)} clips") and "ground truth mean angular speed" in lines[0]
    assert [ln.split()[0] for ln in lines[3:7]] == ["synthesis", "mean_pose", "random_segments", "nearest_wrist"]
    assert f"({r['frames']} hand-frames, k=5)" in lines[0] and r["k"] == 5
    # --k reaches the synthesis of the held-out clips (it was ignored): one candidate per segment
    status, out, err = _run(capsys, "evaluate", "--holdout", *paths, "--json", "--k", "1")
    assert status == 0, err
    r1 = json.loads(out)
    assert r1["k"] == 1 and r1["methods"]["mean_pose"] == r["methods"]["mean_pose"]
    assert r1["methods"]["synthesis"] != r["methods"]["synthesis"]


def test_db_build_and_synthesize_files(gesture_files, capsys, tmp_path):
    folder, paths = gesture_files
    db_path = tmp_path / "db"
    status, out, err = _run(capsys, "db", "build", *paths[1:], "-o", db_path, "--labels", r"^([a-z]+)_",
                            "--mirror", "--json")
    assert status == 0, err
    info = json.loads(out)
    db = load_database(db_path)
    assert info["tracks"] == 2 * 2 * (len(paths) - 1) == len(db.tracks)
    assert {c["source"] for c in db.clips} == {str(p) for p in paths[1:]}
    # synthesize the held-out first file: the body stays, fingers come from the database
    src = paths[0]
    out_file = tmp_path / "out.bvh"
    status, out, err = _run(capsys, "synthesize", src, "-o", out_file, "--db", db_path, "--k", "3",
                            "--plot", tmp_path / "plots")
    assert status == 0, err
    a, b = read_clip(src), read_clip(out_file)
    hm = tiny_handmap()
    fingers = sorted(a.skeleton.index(j) for s in hm.sides for j in s.finger_joints)
    body = [j for j in range(a.num_joints) if j not in fingers]
    from usdhands.model.rotations import quat_angle_deg

    assert quat_angle_deg(a.rotations[:, body], b.rotations[:, body]).max() < 1e-3
    assert np.allclose(a.translations[:, 0], b.translations[:, 0], atol=1e-4)
    # the held-out clip is an 'attention' gesture: its fingers come back close to the truth
    err_deg = quat_angle_deg(a.rotations[:, fingers], b.rotations[:, fingers]).mean()
    assert err_deg < 10.0
    pngs = sorted(p.name for p in (tmp_path / "plots").iterdir())
    assert pngs == ["left_fingers.png", "left_graph.png", "left_segments.png",
                    "right_fingers.png", "right_graph.png", "right_segments.png"]


def test_synthesize_needs_finger_joints(capsys, tmp_path):
    from synthesis_data import tiny_skeleton

    sk = tiny_skeleton()
    keep = [j for j, n in enumerate(sk.short_names) if "Hand" not in n or n.endswith("Hand")]
    sub = sk.subset(keep)
    from usdhands.model import Clip

    clip = Clip(sub, 30, np.broadcast_to(sub.rest_rotations, (20, sub.num_joints, 4)))
    src = tmp_path / "nofingers.bvh"
    write_asset(Asset("memory", [sub], [clip], []), src)
    status, _, err = _run(capsys, "synthesize", src, "-o", tmp_path / "o.bvh")
    assert status == 2
    assert err.startswith(f"usdhands: error: {src}: no hand found in skeleton 'nofingers'; looked for finger joints")
    assert err.rstrip().endswith("saw 8 joints: Hips, Spine, LeftArm, LeftForeArm, LeftHand, RightArm, RightForeArm, RightHand")
    assert not (tmp_path / "o.bvh").exists()


def test_synthesize_grafts_hands_onto_a_skeleton_without_fingers(gesture_files, capsys, tmp_path):
    from synthesis_data import tiny_skeleton

    folder, paths = gesture_files
    db_path = tmp_path / "db"
    assert _run(capsys, "db", "build", *paths, "-o", db_path, "--labels", r"^([a-z]+)_")[0] == 0
    full = read_clip(paths[0])
    sk = tiny_skeleton()
    keep = [j for j, n in enumerate(sk.short_names) if "Hand" not in n or n.endswith("Hand")]
    sub = full.skeleton.subset(keep)
    body = full.replace(skeleton=sub, rotations=full.rotations[:, keep], translations=full.translations[:, keep],
                        scales=full.scales[:, keep])
    src = tmp_path / "bare.bvh"
    write_asset(Asset("memory", [sub], [body], []), src)
    status, _, err = _run(capsys, "synthesize", src, "-o", tmp_path / "o.bvh", "--db", db_path)
    assert status == 2 and "no hand found" in err
    status, out, err = _run(capsys, "synthesize", src, "-o", tmp_path / "o.bvh", "--db", db_path, "--graft-hands")
    assert status == 0, err
    assert "grafted 30 finger joints from the database's hands" in out
    back = read_clip(tmp_path / "o.bvh")
    from usdhands.model.hand_detection import detect_hands
    from usdhands.model.rotations import quat_angle_deg

    hm = detect_hands(back.skeleton)
    assert [len(h.finger_joints) for h in hm.sides] == [15, 15]
    idx = [back.skeleton.index(n) for n in sub.short_names]
    assert quat_angle_deg(back.rotations[:, idx], body.rotations).max() < 1e-3
    fj = [back.skeleton.index(j) for j in hm.left.finger_joints]
    assert np.ptp(back.rotations[:, fj], axis=0).max() > 0.05  # the grafted fingers move


def test_evaluate_needs_only_the_joints_its_predictors_name(capsys, tmp_path):
    from usdhands.model import HandMap, HandSide

    hm = tiny_handmap()
    no_shoulder = HandMap(**{s: HandSide(s, hm[s].wrist, hm[s].forearm, None, hm[s].root, hm[s].fingers)
                             for s in ("left", "right")})
    items = [(lab, c, no_shoulder) for lab, c in gesture_set(2, seed=3)]
    es = prepare_eval_set(items, predictors=["wrist_pos+0.5rot", "elbow_rot"])
    assert sorted(es.features) == ["elbow_pos", "elbow_rot", "wrist_pos", "wrist_rot"]
    with pytest.raises(ValueError, match="Hand 'left' of clip 'attention_00' has no shoulder joint for the predictors"):
        prepare_eval_set(items, predictors=["shoulder_rot"])
    status, _, err = _run(capsys, "evaluate", "--samples", "--predictors", "wrist_pos+hand_rot")
    assert status == 2 and "term 'hand_rot' is not" in err


def test_evaluate_body_only_files_without_finger_joints(gesture_files, capsys, tmp_path):
    folder, paths = gesture_files
    bare_dir = tmp_path / "bare"
    bare_dir.mkdir()
    for p in paths:
        c = read_clip(p)
        keep = [j for j, n in enumerate(c.skeleton.short_names) if "Hand" not in n or n.endswith("Hand")]
        sub = c.skeleton.subset(keep)
        b = c.replace(skeleton=sub, rotations=c.rotations[:, keep], translations=c.translations[:, keep],
                      scales=c.scales[:, keep])
        write_asset(Asset("memory", [sub], [b], []), bare_dir / p.name)
    args = ["--labels", r"^([a-z]+)_", "--json"]
    s1, out1, err1 = _run(capsys, "evaluate", folder, *args)
    s2, out2, err2 = _run(capsys, "evaluate", bare_dir, *args)
    assert s1 == s2 == 0, err2
    # the tiny rig's finger layout gives the same hand frame as the guess from the forearm
    assert json.loads(out2)["predictors"] == pytest.approx(json.loads(out1)["predictors"])


def test_default_predictors_leave_out_joints_the_hand_maps_lack(gesture_files, capsys, tmp_path):
    folder, paths = gesture_files
    hm = tiny_handmap()
    override = {s: {"wrist": hm[s].wrist, "forearm": hm[s].forearm, "shoulder": None, "root": hm[s].root,
                    "fingers": {f: list(c) for f, c in hm[s].fingers.items()}} for s in ("left", "right")}
    hm_file = tmp_path / "handmap.json"
    hm_file.write_text(json.dumps(override))
    status, out, err = _run(capsys, "evaluate", *paths, "--labels", r"^([a-z]+)_", "--handmap", hm_file, "--json")
    assert status == 0, err
    r = json.loads(out)
    assert r["left_out_predictors"] == ["shoulder_pos", "shoulder_rot"]
    assert list(r["predictors"]) == [p for p in DEFAULT_PREDICTORS if not p.startswith("shoulder")]
    status, out, _ = _run(capsys, "evaluate", *paths, "--labels", r"^([a-z]+)_", "--json")
    full = json.loads(out)
    assert "left_out_predictors" not in full
    assert r["predictors"] == pytest.approx({k: v for k, v in full["predictors"].items() if k in r["predictors"]})
    status, out, _ = _run(capsys, "evaluate", *paths, "--labels", r"^([a-z]+)_", "--handmap", hm_file)
    assert status == 0 and "left out (joints missing from a hand map): shoulder_pos, shoulder_rot" in out
    # asked for by name, a predictor the rig cannot answer is an error
    status, _, err = _run(capsys, "evaluate", *paths, "--labels", r"^([a-z]+)_", "--handmap", hm_file,
                          "--predictors", "shoulder_rot")
    assert status == 2 and "has no shoulder joint for the predictors asked for" in err


def test_evaluate_refuses_sets_it_cannot_judge(gesture_files, capsys, sample_assets):
    folder, paths = gesture_files
    label = r"^([a-z]+)_\d+"
    status, _, err = _run(capsys, "evaluate", paths[0], "--labels", label)
    assert status == 2 and err == "usdhands: error: leave-one-out needs at least two clips\n"
    same = [p for p in paths if p.name.startswith("ok_")]
    status, _, err = _run(capsys, "evaluate", *same, "--labels", label)
    assert status == 2 and err == "usdhands: error: leave-one-out needs at least two labels; every clip is 'ok'\n"
    bodyonly = sample_assets / "gestures_bodyonly"
    status, _, err = _run(capsys, "evaluate", "--holdout", bodyonly)
    assert status == 2 and "the fingers never move in any of these clips: --holdout needs clips with finger" in err
    status, _, err = _run(capsys, "evaluate", "--holdout", bodyonly, *paths[:2], "--json")
    assert status == 0 and err.startswith("usdhands: warning: the fingers never move in 3 of 5 clips (")



def test_evaluate_predictors_reports_progress_per_predictor(gesture_files):
    _, paths = gesture_files
    hm = tiny_handmap()
    es = prepare_eval_set([(p.name.split("_")[0], read_clip(p), hm) for p in paths])
    calls = []
    shares = evaluate_predictors(es, DEFAULT_PREDICTORS[:3], 5, progress=lambda *a: calls.append(a))["predictors"]
    assert calls == [(i + 1, 3, p) for i, p in enumerate(DEFAULT_PREDICTORS[:3])]
    assert shares == evaluate_predictors(es, DEFAULT_PREDICTORS[:3], 5)["predictors"]


def test_evaluate_job_reports_what_the_command_prints(gesture_files, capsys):
    """The command parses, calls the evaluate job and prints: the same JSON for leave-one-out and holdout."""
    from usdhands.jobs.evaluation import EvaluateOptions, evaluate

    folder, paths = gesture_files
    status, out, err = _run(capsys, "evaluate", *paths, "--labels", r"^([a-z]+)_\d+", "--json",
                            "--predictors", "wrist_rot,wrist_pos+0.5rot")
    assert status == 0, err
    result = evaluate(paths, EvaluateOptions(labels=r"^([a-z]+)_\d+", predictors=("wrist_rot", "wrist_pos+0.5rot")))
    assert result.analysis == "leave-one-out" and result.clips == len(paths)
    assert json.loads(json.dumps(result.to_json())) == json.loads(out)
    status, out, err = _run(capsys, "evaluate", "--holdout", *paths[:4], "--json", "--k", "2")
    assert status == 0, err
    held = evaluate(paths[:4], EvaluateOptions(holdout=True, k=2))
    assert held.analysis == "holdout" and json.loads(json.dumps(held.to_json())) == json.loads(out)
    assert capsys.readouterr().out == ""  # the job prints nothing


def test_db_build_job_writes_the_commands_folder(gesture_files, capsys, tmp_path):
    from usdhands.jobs.database import BuildDbOptions, build_db, database_info

    folder, paths = gesture_files
    status, out, err = _run(capsys, "db", "build", *paths[:4], "-o", tmp_path / "cli", "--labels", r"^([a-z]+)_",
                            "--mirror", "--json")
    assert status == 0, err
    summary = build_db(paths[:4], tmp_path / "job", BuildDbOptions(labels=r"^([a-z]+)_", mirror=True))
    cli_files = sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert cli_files == sorted(p.name for p in (tmp_path / "job").iterdir()) and "manifest.json" in cli_files
    for name in cli_files:
        assert (tmp_path / "cli" / name).read_bytes() == (tmp_path / "job" / name).read_bytes(), name
    assert json.loads(out) == json.loads(json.dumps(summary.to_json()).replace(str(tmp_path / "job"),
                                                                               str(tmp_path / "cli")))
    info = database_info(tmp_path / "job")
    assert info.manifest == summary.manifest
    assert sum(left + right for _, left, right in info.segments_by_label) == summary.counts["segments"]

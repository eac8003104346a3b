"""Synthesis end to end on the generated gesture database, the bundled database and real rigs."""

from __future__ import annotations

import numpy as np
import pytest

from usdhands.algorithms.synthesis.database import DatabaseClip, build_database, load_database
from usdhands.algorithms.synthesis.finger_transfer import hand_rig, canonical_curves
from usdhands.algorithms.synthesis.evaluation import (
    PAPER_PREDICTOR, SINGLE_JOINT_PREDICTORS, evaluate_predictors, prepare_eval_set,
)
from usdhands.algorithms.synthesis.synthesize import synthesize_clip
from usdhands.algorithms.synthesis.config import SynthesisConfig
from usdhands.cli import main
from usdhands.jobs.inputs import bundled_database_path
from usdhands.model.hand_detection import detect_hands
from usdhands.samples.gestures import body_only, conversation_clip, gesture_database, gesture_hands


@pytest.fixture(scope="module")
def gestures():
    items = gesture_database(seed=0)
    return items, detect_hands(items[0][1].skeleton)


@pytest.fixture(scope="module")
def gesture_db(gestures):
    items, hm = gestures
    return build_database([DatabaseClip(c, hm, lab, c.name) for lab, c in items], fps=30)


def test_leave_one_out_reaches_the_papers_80_percent(gestures):
    items, hm = gestures
    es = prepare_eval_set([(lab, c, hm) for lab, c in items])
    r = evaluate_predictors(es, [*SINGLE_JOINT_PREDICTORS, PAPER_PREDICTOR], k=5)
    share = r["predictors"][PAPER_PREDICTOR]
    assert share >= 0.80
    for p in SINGLE_JOINT_PREDICTORS:
        assert share > r["predictors"][p], (p, r["predictors"])
    assert share > r["chance"] + 0.5
    m = np.array(r["confusion"]["matrix"])
    assert m.shape == (8, 8) and np.allclose(m.sum(axis=1), 1.0)
    assert np.diag(m).mean() == pytest.approx(share, abs=0.1)


def _active(items):
    """(clip index, label, active sides) of every take."""
    out = []
    for ci, (label, clip) in enumerate(items):
        take = int(clip.name.rsplit("_", 1)[-1])
        out.append((ci, label, gesture_hands(label, take)))
    return out


def test_heldout_synthesis_picks_segments_of_its_own_type(gestures, gesture_db):
    items, hm = gestures
    labels = gesture_db.segment_labels()
    right = total = 0
    for ci, label, sides in _active(items)[::2]:  # every other take keeps the test quick
        res = synthesize_clip(body_only(items[ci][1]), hm, gesture_db, hands=tuple(sides), exclude_clips=(ci,))
        for side in sides:
            h = res.hands[side]
            assert not any(gesture_db.segment_clip()[h.chosen] == ci)  # never its own motion
            got = [labels[s] for s in h.chosen]
            right += sum(g == label for g in got)
            total += len(got)
    assert total > 60
    assert right / total >= 0.80, right / total


def test_output_changes_only_fingers_is_deterministic_and_smooth_at_seams(gestures, gesture_db):
    items, hm = gestures
    clip = body_only(conversation_clip())
    cfg = SynthesisConfig()
    a = synthesize_clip(clip, hm, gesture_db, cfg)
    b = synthesize_clip(clip, hm, gesture_db, cfg)
    assert np.array_equal(a.clip.rotations, b.clip.rotations)
    for bound in ("keogh", "none"):  # the pruning bound changes nothing but speed
        c = synthesize_clip(clip, hm, gesture_db, cfg.with_values(segment_cost={"lower_bound": bound}))
        assert np.array_equal(a.clip.rotations, c.clip.rotations)
    fingers = sorted(clip.skeleton.index(j) for side in hm.sides for j in side.finger_joints)
    body = [j for j in range(clip.num_joints) if j not in fingers]
    assert np.array_equal(a.clip.rotations[:, body], clip.rotations[:, body])
    assert np.array_equal(a.clip.translations, clip.translations)
    assert np.array_equal(a.clip.scales, clip.scales)
    assert not np.allclose(a.clip.rotations[:, fingers], clip.rotations[:, fingers])
    st = cfg.stitching
    for side in ("left", "right"):
        h = a.hands[side]
        assert len(h.seams.frame) == len(h.bounds) - 2 > 10
        # most candidates are never aligned in full; the end-point bound alone skips many
        assert h.search.skipped_share > 0.5 and h.search.pruned_share > 0.2
        curves = canonical_curves(a.clip, hand_rig(clip.skeleton, hm[side]))[:, gesture_db.dof_index]
        for f in h.seams.frame:
            jump = np.abs(curves[f] - curves[f - 1])
            assert jump.mean() <= st.blend_mean_deg and jump.max() <= st.blend_max_deg, (side, f, jump.max())


def test_bundled_database_holds_the_generated_gesture_set(gestures):
    # rebuilt with `usdhands db build --samples -o usdhands/data/gesture_db`
    items, _ = gestures
    db = load_database(bundled_database_path())
    assert [(c["name"], c["label"]) for c in db.clips] == [(c.name, lab) for lab, c in items]
    assert all(c["source"] == f"samples:gestures/{c['name']}" for c in db.clips)
    assert len(db.tracks) == 2 * len(items) and set(db.tracks[:, 3]) == {0, 1}
    assert len(db.dof_index) == 45  # 5 fingers x 3 joints x 3 axes
    assert set(db.hands) == {"left", "right"}  # hand templates for --graft-hands
    assert len(db.hands["left"]["joints"]) == 20  # 15 finger joints and 5 end joints
    assert sum(f.stat().st_size for f in bundled_database_path().iterdir()) < 5e6


def test_bundled_database_on_robot_expressive(shared_assets, tmp_path, gltf_validator, capsys):
    from usdhands.formats.io import read_clip

    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    clip = read_clip(src, animation="ThumbsUp")
    hm = detect_hands(clip.skeleton)
    res = synthesize_clip(clip, hm, load_database(bundled_database_path()))
    m = res.mapping["left"]
    assert sorted(m["dropped"]) == ["pinky.d0", "pinky.d1", "pinky.d2", "thumb.d2"]
    assert m["no_source"] == []
    assert dict((j.rsplit("/", 1)[-1], s) for j, s in m["mapped"])["Palm1.L"] == "index.d2"
    fingers = sorted(clip.skeleton.index(j) for side in hm.sides for j in side.finger_joints)
    body = [j for j in range(clip.num_joints) if j not in fingers]
    assert np.array_equal(res.clip.rotations[:, body], clip.rotations[:, body])
    out = tmp_path / "robot.glb"
    assert main(["synthesize", str(src), "--animation", "ThumbsUp", "-o", str(out), "--json"]) == 0
    capsys.readouterr()
    # the source already fails one rule (skin weights that do not sum to 1): no new errors
    before, after = gltf_validator(src, out)
    assert after["numErrors"] <= before["numErrors"]
    assert {m["code"] for m in after["messages"] if m["severity"] == 0} <= {"ACCESSOR_WEIGHTS_NON_NORMALIZED"}
    back = read_clip(out, animation="ThumbsUp")
    from usdhands.model.rotations import quat_angle_deg

    assert quat_angle_deg(back.rotations[:, fingers], res.clip.rotations[:, fingers]).max() < 0.01
    assert quat_angle_deg(back.rotations[:, body], clip.rotations[:, body]).max() < 0.01


def test_finger_reference_input_undoes_a_zero_pose_that_is_not_the_bind_pose(gestures, gesture_db):
    from usdhands.model import Skeleton

    items, hm = gestures
    clip = body_only(items[3][1])
    sk = clip.skeleton
    # what a BVH writer does with a rig that has rest rotations: same offsets, zero rotations
    zero = Skeleton(sk.joint_names, sk.parents, sk.rest_translations, np.tile([0.0, 0, 0, 1], (sk.num_joints, 1)),
                    meters_per_unit=sk.meters_per_unit, up_axis=sk.up_axis, name=sk.name)
    zclip = clip.replace(skeleton=zero)
    assert np.allclose(zclip.world_positions(), clip.world_positions())
    a = synthesize_clip(clip, hm, gesture_db)
    b = synthesize_clip(zclip, hm, gesture_db, finger_reference="input")
    c = synthesize_clip(zclip, hm, gesture_db)
    fingers = sorted(sk.index(j) for side in hm.sides for j in side.finger_joints)
    pa, pb, pc = (r.clip.world_positions_cm()[:, fingers] for r in (a, b, c))
    assert np.abs(pa - pb).max() < 1e-6
    assert np.abs(pa - pc).max() > 1.0  # relative to the zero pose the thumbs point elsewhere

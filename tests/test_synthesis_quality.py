"""The issue-11 method changes: output warp, step limit, wrap-free rotations, moving DOFs, normalised terms."""

from __future__ import annotations

import numpy as np
import pytest
from synthesis_data import gesture_set, tiny_handmap, tiny_skeleton

from usdhands.algorithms.synthesis.database import DatabaseClip, build_database
from usdhands.algorithms.synthesis.motion_graph import least_cost_path, term_scale, transition_costs
from usdhands.algorithms.synthesis.output_warp import limit_steps, sample_rows, smooth_warp, step_limits
from usdhands.algorithms.synthesis.segment_cost import dtw_align
from usdhands.algorithms.synthesis.wrist_features import (
    ROTATION_SCALE, mirror_features, rotation_features, world_rotations, wrist_features,
)
from usdhands.model.rotations import euler_deg_to_quat, quat_multiply, quat_to_matrix


def test_smoothed_warp_is_monotone_spans_the_segment_and_has_no_holds_or_skips():
    # a path that holds and skips in turn (steps 0, 2, 0, 2, ...), as the asymmetric DTW gives
    n, m = 41, 41
    path = np.minimum(2 * (np.arange(n) // 2), m - 1)
    path[-1] = m - 1
    w = smooth_warp(path, m, 30.0, 0.2)
    assert w[0] == 0 and w[-1] == m - 1
    assert (np.diff(w) >= 0).all()
    # a 6-frame moving average of alternating 0/2 steps: every step is 1 within the middle
    inner = np.diff(w)[6:-6]
    assert np.allclose(inner, 1.0, atol=0.2)
    # a path that waits on one frame for a second still moves (a quarter of the straight warp)
    wait = np.concatenate([np.zeros(30), np.arange(1, 31)]).astype(int)
    w = smooth_warp(wait, 31, 30.0, 0.2)
    assert (np.diff(w) >= 0.25 * 30 / 59 - 1e-9).all() and w[0] == 0 and w[-1] == 30
    assert np.allclose(smooth_warp(path, m, 30.0, 0.0), path)  # no smoothing: the path itself


def test_smoothed_warp_of_a_real_alignment_follows_it():
    rng = np.random.default_rng(3)
    d = np.cumsum(rng.normal(size=(60, 4)), axis=0)
    true = np.clip(np.round(np.linspace(0, 59, 45) ** 1.1 / 59 ** 0.1), 0, 59).astype(int)
    _, path = dtw_align(d[true], d, 1.0)
    w = smooth_warp(path, 60, 30.0, 0.2)
    assert np.abs(w - path).max() < 3 and (np.diff(w) >= 0).all()


def test_sample_rows_interpolates_between_neighbours():
    rows = np.array([[0.0, 10.0], [2.0, 20.0], [4.0, 0.0]])
    got = sample_rows(rows, np.array([0.0, 0.5, 1.0, 1.25, 2.0]))
    assert np.allclose(got, [[0, 10], [1, 15], [2, 20], [2.5, 15], [4, 0]])


def test_step_limits_are_percentiles_inside_tracks_only():
    # track 0: steps 1, 1, ..., 1 then one of 5; track 1 starts 100 degrees away (not a step)
    a = np.concatenate([np.arange(200.0), [204.0]])
    b = np.full(50, 1000.0)
    fingers = np.concatenate([a, b])[:, None] * np.array([1.0, 0.0])  # second DOF never moves
    tracks = np.array([[0, len(a)], [len(a), len(a) + len(b)]])
    lim = step_limits(fingers, tracks, 100.0)
    assert lim.tolist() == [5.0, 0.0]
    lim = step_limits(fingers, tracks, 50.0)
    assert lim[0] == pytest.approx(1.0)
    # a DOF that moves in fewer frames than the percentile leaves out gets its largest step
    rare = np.zeros((400, 1))
    rare[200:] = 3.0
    assert step_limits(rare, np.array([[0, 400]]), 99.5).tolist() == [3.0]


def test_step_limits_column_by_column_equal_the_percentiles_of_the_whole_array():
    """The limits, computed a column at a time, against NumPy's percentile along axis 0 of all the steps at once
    (what they were before), to the bit: float32 and float64 curves, still and rarely moving DOFs, NaN, tracks
    and a frame selection; and the errors of bad shapes."""
    rng = np.random.default_rng(7)
    curves = np.cumsum(rng.normal(size=(3000, 9)) * rng.uniform(0.1, 20, 9), axis=0)
    curves[:, 2] = 4.0  # never moves
    curves[:, 5] = np.where(np.arange(3000) > 2990, 7.0, 0.0)  # moves once
    curves[1234, 7] = np.nan
    tracks = np.array([[0, 700], [700, 1900], [1900, 3000]])
    frames = rng.uniform(size=3000) > 0.2

    def whole(f, percentile, frames=None):
        f = np.asarray(f, dtype=np.float64)
        steps = np.abs(np.diff(f, axis=0))
        inside = np.ones(len(steps), bool)
        inside[tracks[:, 1][:-1] - 1] = False
        if frames is not None:
            inside &= frames[:-1] & frames[1:]
        steps = steps[inside]
        lim = np.percentile(steps, percentile, axis=0)
        return np.where(lim > 0, lim, steps.max(axis=0))

    for f in (curves, curves.astype(np.float32)):
        for percentile in (50.0, 90.0, 97.5, 100.0):
            for sel in (None, frames):
                expected = whole(f, percentile, sel)
                got = step_limits(f, tracks, percentile, sel)
                assert got.dtype == np.float64 and got.shape == (9,)
                assert np.array_equal(got, expected, equal_nan=True), (percentile, sel is None)
    assert step_limits(np.zeros((0, 3)), np.zeros((0, 2), int), 90.0).tolist() == [0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match=r"Expected frames \(3000,\) bool, got \(5,\)"):
        step_limits(curves, tracks, 90.0, np.ones(5, bool))
    with pytest.raises(ValueError, match=r"Expected fingers \(F, C\), got \(3000,\)"):
        step_limits(curves[:, 0], tracks, 90.0)


def test_limit_steps_turns_a_pop_into_a_ramp_and_leaves_smooth_curves_alone():
    smooth = np.cumsum(np.full((30, 2), 0.5), axis=0)
    assert np.array_equal(limit_steps(smooth, np.array([1.0, 1.0])), smooth)
    pop = np.zeros((20, 1))
    pop[5:] = 10.0
    got = limit_steps(pop, np.array([2.0]))
    assert got[:, 0].tolist() == [0.0] * 5 + [2.0, 4.0, 6.0, 8.0] + [10.0] * 11


def _turning_clip(degrees_per_frame: float, frames: int):
    from synthesis_data import gesture_clip

    sk, hm = tiny_skeleton(), tiny_handmap()
    clip = gesture_clip(sk, "ok", np.random.default_rng(0))
    clip = clip.resample(clip.fps)
    w = sk.index(hm.left.wrist)
    rot = np.repeat(np.asarray(clip.rotations[:1]), frames, axis=0)
    tr = np.repeat(np.asarray(clip.translations[:1]), frames, axis=0)
    sc = np.repeat(np.asarray(clip.scales[:1]), frames, axis=0)
    angles = np.zeros((frames, 3))
    angles[:, 0] = degrees_per_frame * np.arange(frames)  # turn about the wrist's X axis, full circles
    rot[:, w] = quat_multiply(rot[:, w], euler_deg_to_quat(angles))
    return clip.replace(rotations=rot, translations=tr, scales=sc), hm


def test_wrist_rotation_features_never_wrap():
    # the hand turns through two full circles: a rotation vector relative to a fixed reference
    # would jump by up to 360 degrees twice; the matrix features move by 2 sin(theta/2) per frame
    step = 7.0
    clip, hm = _turning_clip(step, 110)
    f = wrist_features(clip, hm.left)
    d = np.linalg.norm(np.diff(f[:, 3:], axis=0), axis=1)
    expected = np.degrees(2 * np.sin(np.radians(step) / 2))
    assert np.allclose(d, expected, rtol=1e-6)
    assert expected < step
    # the scale makes the distance the angle for small differences: |dM| * scale ~ theta
    assert ROTATION_SCALE * np.sqrt(2) == pytest.approx(np.degrees(1.0))


def test_rotation_features_and_their_mirror():
    rng = np.random.default_rng(5)
    q = rng.normal(size=(10, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    R = quat_to_matrix(q)
    M = np.diag([-1.0, 1.0, 1.0])
    f = np.concatenate([rng.normal(size=(10, 3)), rotation_features(R)], axis=1)
    mirrored = np.concatenate([f[:, :3] * [-1, 1, 1], rotation_features(M @ R @ M)], axis=1)
    assert np.allclose(mirror_features(f), mirrored)
    assert np.allclose(mirror_features(mirror_features(f)), f)
    assert np.allclose(world_rotations(np.tile(np.eye(4), (2, 1, 1)) * 2), np.eye(3))


def test_transition_cost_averages_over_moving_dofs_only():
    rng = np.random.default_rng(1)
    ea, va, sb, vb = (rng.normal(size=(3, 4)) for _ in range(4))
    pad = lambda x: np.concatenate([x, np.zeros((len(x), 6))], axis=1)  # noqa: E731  six constant DOFs
    mask = np.array([True] * 4 + [False] * 6)
    moving = transition_costs(ea, va, sb, vb, 1.0, 0.5)
    assert np.allclose(transition_costs(pad(ea), pad(va), pad(sb), pad(vb), 1.0, 0.5, mask), moving)
    assert np.allclose(transition_costs(pad(ea), pad(va), pad(sb), pad(vb), 1.0, 0.5), moving * 4 / 10)


def test_database_knows_its_moving_dofs_and_step_limits():
    items = [DatabaseClip(c, tiny_handmap(), lab) for lab, c in gesture_set(1)]
    db = build_database(items)
    f = np.asarray(db.fingers)
    assert db.moving_dofs().tolist() == (np.ptp(f, axis=0) > 1e-3).tolist()
    lim = db.step_limits(99.5)
    assert lim.shape == (f.shape[1],) and (lim[db.moving_dofs()] > 0).all()
    assert lim is db.step_limits(99.5)  # computed once


def test_normalised_terms_let_transitions_count():
    # raw scales: segment costs ~1000, transitions ~10. Unnormalised, the cheapest segment wins
    # every row; normalised, the smooth path (node 1 throughout) wins
    cs = np.array([[1000.0, 1100.0], [1000.0, 1100.0], [1000.0, 1100.0]])
    jumpy = np.array([[30.0, 30.0], [30.0, 0.0]])
    trans = [jumpy, jumpy]
    raw, _ = least_cost_path(cs, trans, 1.0, 0.5)
    assert raw.tolist() == [0, 0, 0]
    norm, cost = least_cost_path(cs, trans, 1.0, 0.5, normalize=True)
    assert norm.tolist() == [1, 1, 1]
    scaled, cost2 = least_cost_path(cs / term_scale([cs]), [t / term_scale(trans) for t in trans], 1.0, 0.5)
    assert scaled.tolist() == norm.tolist() and cost2 == pytest.approx(cost)
    assert term_scale([np.array([np.inf, 2.0, 4.0])]) == 3.0 and term_scale([np.zeros(3)]) == 1.0


def test_heldout_synthesis_has_no_pops_and_holds_no_more_than_the_truth():
    from usdhands.algorithms.synthesis.synthesize import synthesize_hand

    items = [DatabaseClip(c, tiny_handmap(), lab) for lab, c in gesture_set(3)]
    db = build_database(items)
    moving = db.moving_dofs()
    held, held_truth = [], []
    for t in range(0, len(db.tracks), 3):
        a, b, c, s, _ = (int(x) for x in db.tracks[t])
        res = synthesize_hand(np.asarray(db.features[a:b], dtype=np.float64), db, ("left", "right")[s],
                              exclude_clips=(c,))
        out = res.curves[:, db.dof_index]
        # held out means held out: the limits come from the other clips' frames
        own_lim = db.step_limits(99.5, db.segment_frames(db.segment_clip() != c))
        assert (np.abs(np.diff(out, axis=0)) <= own_lim + 1e-9).all()
        truth = np.asarray(db.fingers[a:b], dtype=np.float64)
        held.extend(np.abs(np.diff(out[:, moving], axis=0)).max(axis=1) < 1e-6)
        held_truth.extend(np.abs(np.diff(truth[:, moving], axis=0)).max(axis=1) < 1e-6)
    # the generator holds the fingers still in about a third of its frames; copying frames along
    # the DTW path held many more (steps of 0)
    assert np.mean(held) <= np.mean(held_truth) + 0.03


def _padded(clip, n):
    """The clip with its first and last poses held for n more frames at each end."""
    idx = np.concatenate([np.zeros(n, int), np.arange(clip.num_frames), np.full(n, clip.num_frames - 1)])
    return clip.replace(rotations=np.asarray(clip.rotations)[idx], translations=np.asarray(clip.translations)[idx],
                        scales=np.asarray(clip.scales)[idx])


def test_leave_one_out_trims_rest_and_reports_each_hand():
    from usdhands.algorithms.synthesis.evaluation import evaluate_predictors, prepare_eval_set

    items = [(lab, c, tiny_handmap()) for lab, c in gesture_set(2, seed=4)]
    padded = [(lab, _padded(c, 60), hm) for lab, c, hm in items]
    plain = prepare_eval_set(items, predictors=["wrist_pos"])
    trimmed = prepare_eval_set(padded, predictors=["wrist_pos"])
    kept = prepare_eval_set(padded, predictors=["wrist_pos"], trim_rest=False)
    # two seconds of rest at each end: kept, they add segments; trimmed, the segments are the
    # moving part's, as without the padding (the generator's own rest is trimmed too)
    assert len(kept.segments) > len(trimmed.segments)
    assert len(trimmed.segments) <= len(plain.segments)
    assert len(trimmed.features["wrist_pos"]) < len(plain.features["wrist_pos"]) + 2 * 60 * len(items)
    r = evaluate_predictors(trimmed, ["wrist_pos", "wrist_pos+0.5rot"])
    for p in ("wrist_pos", "wrist_pos+0.5rot"):
        hands = r["per_hand"][p]
        assert set(hands) == {"left", "right"}
        n = [int((trimmed.seg_side == s).sum()) for s in (0, 1)]
        # pooled = segment-weighted mean of the hands
        assert r["predictors"][p] == pytest.approx((hands["left"] * n[0] + hands["right"] * n[1]) / sum(n))


def test_transition_velocities_are_per_frame():
    from usdhands.algorithms.synthesis.synthesize import _candidate_ends

    items = [DatabaseClip(c, tiny_handmap(), lab) for lab, c in gesture_set(1)]
    db = build_database(items)
    f = np.asarray(db.fingers, dtype=np.float64)
    s = 3
    a, b = int(db.segments[s, 0]), int(db.segments[s, 1])
    starts, ends, vstart, vend = _candidate_ends(db, np.array([[s, -1]]))
    assert np.allclose(starts[0, 0], f[a]) and np.allclose(ends[0, 0], f[b - 1])
    # degrees per frame (not per second: that would make the velocity term fps^2 times the angles')
    assert np.allclose(vstart[0, 0], f[a + 1] - f[a]) and np.allclose(vend[0, 0], f[b - 1] - f[b - 2])
    assert not vstart[0, 1].any() and not starts[0, 1].any()  # no candidate: zeros


def _play_case():
    rng = np.random.default_rng(1)
    df, qf = rng.normal(size=(400, 4)), rng.normal(size=(120, 4))
    fingers = rng.normal(size=(400, 6)).astype(np.float32)
    seg = np.array([[0, 20], [20, 50], [50, 52], [60, 140], [150, 151], [200, 230]])
    qb = np.array([[0, 25], [25, 26], [26, 60], [60, 120]])
    # pairs no warp fits (a 30-frame segment on one frame, 80 frames on 60 within a narrow band) are stretched
    cand = np.array([[0, 1, 5], [4, -1, 2], [1, 5, 0], [3, 5, -1]])
    weights = rng.uniform(0, 1, cand.shape)
    weights[0, 2] = 0
    bands = np.array([[0.3, 1.0, 0.3], [1.0, 1.0, 1.0], [0.3, 0.3, 1.0], [0.05, 1.0, 1.0]])
    return qf, df, fingers, seg, qb, cand, weights, bands


def test_played_segments_compiled_twin_matches_numpy():
    from usdhands.algorithms.synthesis.output_warp import play_segments, play_segments_fast

    args = _play_case()
    for smoothing_s in (0.2, 0.1, 0.0):  # windows of 6, 3 and no frames
        assert (play_segments_fast(*args, 30.0, smoothing_s) == play_segments(*args, 30.0, smoothing_s)).all()
    # one segment with weight 1: exactly its fingers sampled along the smoothed DTW warp
    qf, df, fingers, seg, qb, cand, weights, bands = args
    one = np.zeros_like(weights)
    one[2, 0] = 1.0
    _, warp = dtw_align(qf[26:60], df[20:50], 0.3)
    at = smooth_warp(warp, 30, 30.0, 0.2)
    got = play_segments_fast(qf, df, fingers, seg, qb, cand, one, bands, 30.0, 0.2)
    np.testing.assert_allclose(got[26:60], sample_rows(fingers[20:50], at), atol=1e-9)
    assert not got[:26].any() and not got[60:].any()
    with pytest.raises(ValueError, match="cand must name non-empty database segments"):
        play_segments_fast(qf, df, fingers, seg, qb, np.full_like(cand, 6), weights, bands, 30.0, 0.2)


def test_limit_steps_compiled_twin_matches_numpy():
    from usdhands.algorithms.synthesis.output_warp import limit_steps_fast

    rng = np.random.default_rng(2)
    x = np.cumsum(rng.normal(size=(300, 5)) * 3, axis=0)
    lim = np.array([1.0, 2.0, 3.0, 0.5, 10.0])
    assert (limit_steps_fast(x, lim) == limit_steps(x, lim)).all()
    smooth = np.linspace(0, 1, 50)[:, None] * np.ones(3)
    assert (limit_steps_fast(smooth, np.ones(3)) == smooth).all()


def test_candidate_weights_fall_with_the_square_of_the_cost():
    from usdhands.algorithms.synthesis.synthesize import candidate_weights, played_weights

    np.testing.assert_allclose(candidate_weights(np.array([1.0, 2.0, np.inf, 4.0])),
                               np.array([1, 0.25, 0, 0.0625]) / 1.3125)
    assert candidate_weights(np.array([0.0, 3.0, 0.0])).tolist() == [0.5, 0.0, 0.5]
    assert candidate_weights(np.full(3, np.inf)).tolist() == [0.0, 0.0, 0.0]
    w = played_weights(np.array([[1.0, 2.0], [5.0, 5.0]]), np.array([[3, 4], [5, -1]]), np.array([1, 0]), 0.7)
    np.testing.assert_allclose(w, [[0.7 * 0.8, 0.3 + 0.7 * 0.2], [1.0, 0.0]])


def test_candidates_of_the_chosen_take_get_no_share_of_the_mix():
    """The mix averages out what each take holds of its own: the other candidates of the
    path's own take share it, so they are left out (a one-take database plays the path's alone)."""
    from usdhands.algorithms.synthesis.synthesize import played_weights

    costs = np.array([[1.0, 2.0, 4.0], [1.0, 2.0, 4.0]])
    cand = np.array([[10, 11, 12], [10, 11, 12]])
    takes = np.array([[0, 0, 1], [0, 0, 0]])  # row 0: candidate 1 is of the chosen's take; row 1: all are
    w = played_weights(costs, cand, np.array([0, 1]), 0.7, takes)
    np.testing.assert_allclose(w[0], [0.3 + 0.7 * 1 / 1.0625, 0.0, 0.7 * 0.0625 / 1.0625])
    np.testing.assert_allclose(w[1], [0.0, 1.0, 0.0])


def test_a_one_take_database_plays_the_chosen_candidate_alone():
    """K-fold on one long take (windows held out against the rest of it): every candidate is of
    the take itself, so the default mix synthesizes exactly what the paper's choice alone does."""
    from usdhands.algorithms.synthesis.config import SynthesisConfig
    from usdhands.algorithms.synthesis.kfold import kfold_evaluation
    from usdhands.model import Clip

    clips = [c for _, c in gesture_set(2, seed=3)]
    one = Clip(clips[0].skeleton, clips[0].fps, np.concatenate([c.rotations for c in clips]),
               np.concatenate([c.translations for c in clips]), name="one_take")
    items = [DatabaseClip(one, tiny_handmap(), None)]
    mixed = kfold_evaluation(items, SynthesisConfig(), folds=3, min_window_s=2.0)
    alone = kfold_evaluation(items, SynthesisConfig().with_values(stitching={"candidate_mix": 0.0}), folds=3,
                             min_window_s=2.0)
    assert mixed["windows"] == 6  # both hands, three windows of the one take
    assert mixed["methods"]["synthesis"] == alone["methods"]["synthesis"]
    assert mixed["methods"]["synthesis"]["error_deg"] < 0.8 * mixed["methods"]["mean_pose"]["error_deg"]


def test_mixing_the_candidates_beats_the_chosen_one_alone_on_held_out_takes():
    """Three takes of each gesture with their own finger variations: the held-out take's
    fingers are better predicted by the close candidates together than by one of them
    (the paper's choice, ``candidate_mix = 0``), at the real speed and without pops."""
    from usdhands.algorithms.synthesis.config import SynthesisConfig
    from usdhands.algorithms.synthesis.kfold import kfold_evaluation

    items = [DatabaseClip(c, tiny_handmap(), label) for label, c in gesture_set(3, seed=5)]
    alone = kfold_evaluation(items, SynthesisConfig().with_values(stitching={"candidate_mix": 0.0}), folds=3)
    mixed = kfold_evaluation(items, SynthesisConfig(), folds=3)
    a, m = alone["methods"]["synthesis"], mixed["methods"]["synthesis"]
    assert m["error_deg"] < 0.97 * a["error_deg"]
    assert 0.8 < m["speed_ratio"] < 1.2 and m["largest_jump_deg"] <= mixed["truth"]["largest_jump_deg"]


def test_stitching_compiled_twin_matches_numpy():
    from usdhands.algorithms.synthesis.stitching import stitch_fragments, stitch_fragments_fast

    rng = np.random.default_rng(0)
    lens = [1, 5, 2, 30, 1, 1, 40, 3]
    bounds = np.concatenate([[0], np.cumsum(lens)])
    jumps = np.repeat(rng.normal(size=(len(lens), 6)) * 30 * (np.arange(len(lens)) % 3 == 2)[:, None], lens, axis=0)
    x = np.cumsum(rng.normal(size=(bounds[-1], 6)), axis=0) * 0.5 + jumps  # some seams blend, some not
    mask = np.array([1, 1, 0, 1, 1, 1], dtype=bool)
    for m in (mask, None, np.zeros(6, dtype=bool)):
        want, seams = stitch_fragments([x[a:b] for a, b in zip(bounds[:-1], bounds[1:])], 30.0, 5, 20, 0.5, m)
        got, fast = stitch_fragments_fast(x, bounds, 30.0, 5, 20, 0.5, m)
        assert (got == want).all() and (fast.frame == seams.frame).all() and (fast.blended == seams.blended).all()
        np.testing.assert_allclose(fast.mean_deg, seams.mean_deg, rtol=1e-12)
        assert (fast.max_deg == seams.max_deg).all()
    assert stitch_fragments([x[a:b] for a, b in zip(bounds[:-1], bounds[1:])], 30.0, 5, 20, 0.5,
                            mask)[1].blended.sum() not in (0, len(lens) - 1)
    with pytest.raises(ValueError, match="increasing bounds from 0 to T"):
        stitch_fragments_fast(x, bounds[1:], 30.0)


def test_transitions_of_all_layers_at_once_equal_layer_by_layer():
    from usdhands.algorithms.synthesis.motion_graph import transition_costs_between

    rng = np.random.default_rng(4)
    ends, vend, starts, vstart = (rng.normal(size=(6, 5, 9)) * 10 for _ in range(4))
    mask = rng.uniform(size=9) > 0.3
    got = transition_costs_between(ends, vend, starts, vstart, 1.0, 0.5, mask)
    for i in range(6):
        assert (got[i] == transition_costs(ends[i], vend[i], starts[i], vstart[i], 1.0, 0.5, mask)).all()

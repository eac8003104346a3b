"""Splicing hand motion onto body motion (seed 001) against ground truth built here.

The hand sessions come from ``splice_synth.make_case``: the body performance replayed
through a known smooth non-linear monotone time warp, the arm's rotations about the
shoulder scaled by 0.5-0.8, a still trunk turned by 30 degrees, and 0.5 degrees of noise.
"""

from __future__ import annotations

import numpy as np
import pytest
from splice_synth import body_handside, hand_session, leap_handside, make_case, reaxis

from usdhands.algorithms.dtw import Band, Constraint
from usdhands.algorithms.splicing.markers import (
    MarkerOffsets, default_marker_offsets, markers_from_joints, markers_from_xforms, yup_cm_positions,
)
from usdhands.algorithms.splicing.costs import (
    FirstPassInput, _first_pass_runs, direction_angle_band_cost, direction_angle_cost, first_pass_band_cost, first_pass_cost,
    first_pass_cost_naive, fit_rotation, hand_angle_cost, hand_angle_cost_naive, hand_directions,
    hand_directions_from_xforms, hand_directions_numpy, sign_features, window_yaw_naive,
)
from usdhands.algorithms.splicing.splice import (
    SpliceOptions, align_hands, median_alignment, pair_finger_joints, phase_boundaries, splice_clips, transfer_fingers,
)
from usdhands.model import Clip, HandSide
from usdhands.model.rotations import quat_angle_deg, quat_conjugate, quat_multiply, quat_slerp, trs_to_xform
from usdhands.algorithms.splicing.sampling import one_hemisphere, relative_rotations, rest_times, sample_rotations
from usdhands.algorithms.splicing.kinematics import chain_xforms, local_xforms, partial_world_xforms

SIDES = ("left", "right")


@pytest.fixture(scope="module")
def case():
    return make_case(300, seed=1)


@pytest.fixture(scope="module")
def leap_case():
    return make_case(300, seed=2, style_body="ue", partial=True)


def _sides(case, partial=False):
    body = {s: body_handside(case.body.skeleton, s, case.style_body) for s in SIDES}
    hands = {s: (leap_handside(s) if partial else body_handside(case.hands.skeleton, s, case.style_hands))
             for s in SIDES}
    return body, hands


def _finger_error_deg(result, case):
    errs = []
    for s in SIDES:
        j = result.transfers[s].joints
        errs.append(quat_angle_deg(result.clip.rotations[:, j], case.body.rotations[:, j]))
    return np.concatenate([e.ravel() for e in errs])


# -- cost functions against their naive twins ------------------------------------------
def _random_pass_one(rng, n, m, trunk, half=2, markers=4):
    P = rng.normal(size=(n, markers, 3)) * 10
    Q = rng.normal(size=(m, markers, 3)) * 10
    vb, ab, evb, eab = sign_features(np.cumsum(P, 0), 30.0)
    vh, ah, evh, eah = sign_features(np.cumsum(Q, 0), 30.0)
    yb = rng.uniform(-180, 180, n) if trunk else None
    yh = rng.uniform(-180, 180, m) if trunk else None
    return FirstPassInput(P, Q, vb, ab, vh, ah, (evb, eab, evh, eah), half, yb, yh)


@pytest.mark.parametrize("trunk", [False, True])
@pytest.mark.parametrize("n, m, half", [(17, 23, 2), (9, 12, 0), (9, 12, 1), (11, 8, 3), (4, 3, 2), (3, 9, 2)])
def test_first_pass_cost_equals_naive_eq6(trunk, n, m, half):
    """Every cell, with whole windows (the kernel's precomputed centring sums) and
    windows cut by the clips' ends, and clips too short for any whole window."""
    rng = np.random.default_rng(0)
    inp = _random_pass_one(rng, n, m, trunk, half)
    full = first_pass_cost_naive(inp)
    i, j = np.mgrid[0:n, 0:m]
    fast = first_pass_cost(inp, i.ravel(), j.ravel()).reshape(n, m)
    np.testing.assert_allclose(fast, full, atol=1e-9)
    # values are counts of sign disagreements: 0, 1 or 4 per component
    assert set(np.unique(full)) <= set(range(0, 97))


def test_first_pass_costs_are_uint8_counts_up_to_ten_markers():
    """Eq. 6 counts up to 24 per marker: uint8 holds them for 10 markers, float64 beyond."""
    rng = np.random.default_rng(4)
    i, j = np.mgrid[0:12, 0:14]
    for markers, dtype in ((4, np.uint8), (10, np.uint8), (11, np.float64)):
        inp = _random_pass_one(rng, 12, 14, False, markers=markers)
        fast = first_pass_cost(inp, i.ravel(), j.ravel())
        assert fast.dtype == dtype
        naive = first_pass_cost_naive(inp).ravel()
        np.testing.assert_array_equal(fast, naive)
        assert naive.max() > 24  # counts of several markers


@pytest.mark.parametrize("trunk", [False, True])
def test_first_pass_cost_is_the_same_whatever_cells_are_asked(trunk):
    """The kernel works on runs of cells along a row: any order, split or single cells
    give the same costs, to the bit, as whole rows (which equal the naive twin above)."""
    rng = np.random.default_rng(3)
    inp = _random_pass_one(rng, 19, 26, trunk)
    i, j = np.mgrid[0:19, 0:26]
    full = first_pass_cost(inp, i.ravel(), j.ravel()).reshape(19, 26)
    np.testing.assert_allclose(full, first_pass_cost_naive(inp), atol=1e-9)
    order = rng.permutation(i.size)  # every cell alone or in accidental runs
    assert np.array_equal(first_pass_cost(inp, i.ravel()[order], j.ravel()[order]), full.ravel()[order])
    lo = np.array([max(0, r - 6) for r in range(19)])  # a band: runs of different lengths, clipped at the edges
    hi = np.array([min(25, r + 9) for r in range(19)])
    rows = np.concatenate([np.full(b - a + 1, r) for r, (a, b) in enumerate(zip(lo, hi))])
    cols = np.concatenate([np.arange(a, b + 1) for a, b in zip(lo, hi)])
    assert np.array_equal(first_pass_cost(inp, rows, cols), full[rows, cols])
    band = Band(lo, hi, 26)  # the same cells asked as a band's rows
    assert np.array_equal(first_pass_band_cost(inp, band), full[rows, cols])
    if not trunk:  # the kernel keeps eq. 7's products for a few rows only: runs come row after row
        with pytest.raises(ValueError, match="row after row"):
            _first_pass_runs(inp, np.array([5, 4]), np.array([0, 0]), np.array([3, 3]))
    ub, uh = rng.normal(size=(19, 3)), rng.normal(size=(26, 3))
    ub /= np.linalg.norm(ub, axis=1, keepdims=True)
    uh /= np.linalg.norm(uh, axis=1, keepdims=True)
    assert np.array_equal(direction_angle_band_cost(ub, uh, band), direction_angle_cost(ub, uh, rows, cols))


def test_window_yaw_recovers_a_known_turn():
    rng = np.random.default_rng(1)
    P = rng.normal(size=(20, 4, 3)) * 10
    th = np.radians(37.0)
    R = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
    Q = P @ R + np.array([5.0, 2.0, -3.0])  # rows: p' = R^T p, plus a shift
    assert np.degrees(window_yaw_naive(P, Q, 10, 10)) == pytest.approx(37.0, abs=1e-9)
    inp = FirstPassInput(P, Q, *(np.zeros((20, 4, 3)),) * 4, (0.0,) * 4, 2, None, None)
    assert first_pass_cost(inp, np.array([10]), np.array([10]))[0] == 0.0


def test_hand_angle_cost_equals_scipy_alignment():
    rng = np.random.default_rng(2)
    unit = lambda v: v / np.linalg.norm(v, axis=-1, keepdims=True)
    fb, hb, fh, hh = (unit(rng.normal(size=(k, 3))) for k in (9, 9, 11, 11))
    fh[3] = -fb[2]  # opposite forearms take the half-turn branch
    i, j = np.mgrid[0:9, 0:11]
    fast = hand_angle_cost(fb, hb, fh, hh, i.ravel(), j.ravel()).reshape(9, 11)
    naive = hand_angle_cost_naive(fb, hb, fh, hh)
    ok = np.ones_like(fast, bool)
    ok[2, 3] = False  # a half turn about any perpendicular axis aligns opposite vectors: no unique answer
    np.testing.assert_allclose(fast[ok], naive[ok], atol=1e-6)
    # there, the answer must be that of one of those half turns: within the range they give
    p = np.cross(fh[3], [1.0, 0, 0])
    p /= np.linalg.norm(p)
    q = np.cross(fh[3], p)
    t = np.linspace(0, np.pi, 3601)[:, None]
    axes = np.cos(t) * p + np.sin(t) * q  # every axis perpendicular to the hand's forearm
    turned = 2 * (axes @ hh[3])[:, None] * axes - hh[3]  # hh[3] after a half turn about each
    possible = np.degrees(np.arccos(np.clip(turned @ hb[2], -1, 1)))
    assert possible.min() - 1e-6 <= fast[2, 3] <= possible.max() + 1e-6
    assert possible.max() - possible.min() > 10  # (the range is a real constraint here)
    # a hand vector along its forearm has one answer: after any half turn it points along fb
    hh2 = hh.copy()
    hh2[3] = fh[3]
    along = hand_angle_cost(fb, hb, fh, hh2, np.array([2]), np.array([3]))[0]
    assert along == pytest.approx(np.degrees(np.arccos(np.dot(hb[2], fb[2]))), abs=1e-6)


def test_direction_angle_cost_is_the_angle_in_degrees():
    u = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    assert direction_angle_cost(u, u, np.array([0, 0, 1]), np.array([0, 1, 1])).tolist() == [0.0, 90.0, 0.0]


# -- markers -----------------------------------------------------------------------------
def test_chain_xforms_are_the_clips_world_transforms_to_the_bit(case, leap_case):
    """The compiled local transforms repeat trs_to_xform's arithmetic in its order, and the
    chain's products are NumPy's: the same bits as the whole character's forward kinematics."""
    rng = np.random.default_rng(5)
    for clip in (case.body, case.hands, leap_case.hands):
        sk = clip.skeleton
        q = rng.normal(size=clip.rotations.shape)  # not unit: the normalisation is part of it
        varied = Clip(sk, clip.fps, q, clip.translations, rng.uniform(0.5, 2.0, clip.translations.shape))
        for c in (clip, varied):
            joints = list(range(sk.num_joints))
            loc = trs_to_xform(c.translations, c.rotations, c.scales)
            assert np.array_equal(local_xforms(c, joints), loc.transpose(1, 0, 2, 3))
            world = c.world_xforms()
            some = [sk.num_joints - 1, sk.num_joints // 2]
            chains = chain_xforms(c, some)
            assert set(chains) == {a for j in some for a in sk.chain_to_root(j)}
            for j, x in chains.items():
                assert np.array_equal(x, world[:, j]), sk.joint_names[j]
            part = partial_world_xforms(c, some)
            assert np.array_equal(part[:, sorted(chains)], world[:, sorted(chains)])
            assert not part[:, [j for j in range(sk.num_joints) if j not in chains]].any()
    q = np.array(case.hands.rotations)
    q[3, 2] = 0.0  # a zero quaternion (Clip.validate refuses it; the clip itself holds it)
    with pytest.raises(ValueError, match="Found zero norm quaternions"):
        trs_to_xform(np.zeros(3), q[3, 2])
    with pytest.raises(ValueError, match="Found zero norm quaternions"):
        local_xforms(Clip(case.hands.skeleton, 30.0, q), [1, 2])


def test_yup_cm_positions_are_time_major(case):
    """(T, len(joints), 3): NumPy puts a list index that a slice separates from another
    index first, which once gave (len(joints), T, 3) here."""
    sk = case.body.skeleton
    joints = [sk.index("RightArm"), sk.index("Hips"), sk.index("LeftHand")]
    world = case.body.world_xforms()
    got = yup_cm_positions(case.body, joints, world)
    assert got.shape == (case.body.num_frames, 3, 3)
    np.testing.assert_array_equal(got[7, 1], world[7, joints[1], :3, 3] * (sk.meters_per_unit * 100.0))


def test_markers_and_hand_directions_equal_their_numpy_expressions_to_the_bit(case, leap_case):
    """The compiled markers and forearm-frame hand vectors against the einsum expressions
    they replace, on the synthetic rigs and on scaled, sheared random transforms."""
    rng = np.random.default_rng(9)
    for clip, side in ((case.body, "left"), (case.hands, "right"), (leap_case.hands, "right")):
        sides = _sides(leap_case, partial=True)[1] if clip is leap_case.hands else _sides(case)[0]
        hs = sides[side]
        sk = clip.skeleton
        w = chain_xforms(clip, [sk.index(hs.wrist), sk.index(hs.forearm)])
        off = default_marker_offsets(sk, hs)
        pairs = [(w[sk.index(hs.wrist)], w[sk.index(hs.forearm)])]
        pairs.append(tuple(np.concatenate([rng.normal(size=(50, 3, 4)), np.tile([0, 0, 0, 1.0], (50, 1, 1))], 1)
                           for _ in range(2)))
        for wrist, forearm in pairs:
            frames = np.stack([wrist, wrist, forearm, wrist], axis=1)
            o4 = np.concatenate([off.as_array(), np.ones((4, 1))], axis=1)
            want = np.einsum("tkab,kb->tka", frames, o4)[..., :3] * (sk.meters_per_unit * 100.0)
            assert np.array_equal(markers_from_xforms(wrist, forearm, off, sk), want)
            assert np.array_equal(hand_directions_from_xforms(wrist, forearm, off),
                                  hand_directions_numpy(wrist, forearm, off))


def test_transfer_sampling_equals_the_numpy_expressions_to_the_bit(case):
    """The compiled steps of the finger transfer against the NumPy they replace: rotations
    relative to rest and back, one hemisphere by cumprod of signs, slerp at fractional frames
    (ends, exact frames, and pairs on opposite hemispheres and nearly equal)."""
    rng = np.random.default_rng(8)
    q = rng.normal(size=(120, 7, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q[10:14, 2] = q[9, 2]  # held: slerp between equal quaternions (the small-angle branch)
    q[20, 3] = -q[19, 3]
    rest = rng.normal(size=(7, 4))
    rest /= np.linalg.norm(rest, axis=-1, keepdims=True)
    assert np.array_equal(relative_rotations(q, rest), quat_multiply(quat_conjugate(rest)[None], q))
    assert np.array_equal(rest_times(rest, q), quat_multiply(rest[None], q))
    rel = np.array(q)
    step = np.where(np.sum(rel[1:] * rel[:-1], axis=-1) < 0, -1.0, 1.0)
    rel[1:] *= np.cumprod(step, axis=0)[..., None]
    mine = np.array(q)
    one_hemisphere(mine)
    assert np.array_equal(mine, rel) and not np.array_equal(mine, q)
    t = np.concatenate([[0.0, 119.0, 130.0, -2.0, 12.5, 20.0], rng.uniform(0, 119, 300)])
    tc = np.clip(t, 0.0, 119)
    i0 = np.minimum(np.floor(tc).astype(int), 118)
    w = (tc - i0)[:, None] * np.ones(7)
    for r in (q, rel):  # with and without opposite neighbours
        assert np.array_equal(sample_rotations(r, t), quat_slerp(r[i0], r[i0 + 1], w))
    one = sample_rotations(q[:1], np.array([0.0, 0.7]))  # a one-frame clip: that frame
    assert np.array_equal(one, quat_slerp(q[[0, 0]], q[[0, 0]], np.zeros((2, 7))))
    np.testing.assert_allclose(one, np.repeat(q[:1], 2, axis=0), atol=1e-15)


def test_default_markers_sit_on_wrist_knuckle_and_towards_the_elbow(case):
    sk = case.body.skeleton
    side = body_handside(sk, "right")
    off = default_marker_offsets(sk, side)
    rest = sk.rest_world_positions()
    wrist, knuckle, elbow = (rest[sk.index(n)] for n in ("RightHand", "RightHandMiddle1", "RightForeArm"))
    m = markers_from_joints(Clip(sk, 30.0, np.tile([0.0, 0, 0, 1], (1, sk.num_joints, 1))), side, off)[0]
    length = np.linalg.norm(knuckle - wrist)
    np.testing.assert_allclose(m[3], knuckle, atol=1e-9)
    np.testing.assert_allclose(0.5 * (m[0] + m[1]), wrist, atol=1e-9)
    assert np.linalg.norm(m[0] - m[1]) == pytest.approx(0.5 * length)
    np.testing.assert_allclose(m[2], wrist + (elbow - wrist) / np.linalg.norm(elbow - wrist) * length, atol=1e-9)


def test_markers_follow_given_offsets(case):
    sk = case.body.skeleton
    side = body_handside(sk, "left")
    off = MarkerOffsets((0, 1, 0), (0, -1, 0), (-10, 0, 0), (8, 0, 0))
    m = markers_from_joints(case.body, side, off)
    world = case.body.world_xforms()
    w = world[:, sk.index("LeftHand")]
    np.testing.assert_allclose(m[:, 3], (w @ [8.0, 0, 0, 1])[:, :3], atol=1e-9)


def test_hand_directions_agree_across_rigs_up_to_one_fitted_rotation(leap_case):
    body_sides, hand_sides = _sides(leap_case, partial=True)
    j = np.round(leap_case.truth).astype(int)
    angle = lambda a, b: np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1, 1)))
    turned = reaxis(leap_case.hands, seed=5)
    for s in SIDES:
        ub = hand_directions(leap_case.body, body_sides[s])
        uh = hand_directions(leap_case.hands, hand_sides[s])
        # at the true correspondence both rigs give the same wrist bend, noise aside
        assert np.median(angle(ub, uh[j])) < 3.0
        # a rig with other joint axes reads differently, until the constant rotation is fitted
        ut = hand_directions(turned, hand_sides[s])
        assert np.median(angle(ub, ut[j])) > 20.0
        R = fit_rotation(ub, ut[j])
        assert np.median(angle(ub, ut[j] @ R.T)) < 3.0


def test_fit_rotation_recovers_a_rotation():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(9)
    b = rng.normal(size=(50, 3))
    R = Rotation.random(random_state=2).as_matrix()
    np.testing.assert_allclose(fit_rotation(b @ R.T, b), R, atol=1e-9)


# -- the splice against ground truth ----------------------------------------------------------
def test_splice_recovers_the_warp_and_the_fingers_both_hands(case):
    body_sides, hand_sides = _sides(case)
    r = splice_clips(case.body, case.hands, body_sides, hand_sides)
    for s in SIDES:
        err = np.abs(r.sides[s].alignment - case.truth)
        assert err.mean() <= 1.5, (s, err.mean())
        assert r.sides[s].second.cost < r.sides[s].second.cell_costs.mean() * 300
    fe = _finger_error_deg(r, case)
    assert fe.mean() < 2.0 and np.percentile(fe, 95) < 5.0
    # non-finger joints are the body's own
    fingers = sorted(j for s in SIDES for j in r.transfers[s].joints)
    others = np.setdiff1d(np.arange(case.body.num_joints), fingers)
    np.testing.assert_array_equal(r.clip.rotations[:, others], case.body.rotations[:, others])
    # the phases found are matched near the truth by the first pass
    ph = r.sides["right"].phases
    assert len(ph) >= 5
    assert np.median(np.abs(ph[:, 1] - case.truth[ph[:, 0].astype(int)])) < 6.0


def test_splice_without_the_second_pass_is_worse(case):
    """The first pass alone only matches phases; the second pass is what gets within 1.5 frames."""
    body_sides, hand_sides = _sides(case)
    r = splice_clips(case.body, case.hands, {"right": body_sides["right"]}, {"right": hand_sides["right"]})
    first = median_alignment(r.sides["right"].first.path, case.body.num_frames)
    assert np.abs(first - case.truth).mean() > np.abs(r.sides["right"].alignment - case.truth).mean() + 1.0


def test_splice_onto_partial_hand_skeleton_with_other_joint_names(leap_case):
    body_sides, hand_sides = _sides(leap_case, partial=True)
    assert body_sides["left"].wrist == "hand_l" and hand_sides["left"].wrist == "lHand"
    r = splice_clips(leap_case.body, leap_case.hands, body_sides, hand_sides)
    for s in SIDES:
        assert np.abs(r.sides[s].alignment - leap_case.truth).mean() <= 1.5
        assert ("index_02_l" if s == "left" else "index_02_r", f"{s[0]}Index2") in r.pairs[s]
    fe = _finger_error_deg(r, leap_case)
    assert fe.mean() < 2.0


def test_rig_with_other_joint_axes_needs_the_hand_frame_transfer(leap_case):
    hands = reaxis(leap_case.hands, seed=3)
    np.testing.assert_allclose(hands.world_positions(), leap_case.hands.world_positions(), atol=1e-9)
    body_sides, hand_sides = _sides(leap_case, partial=True)
    local = splice_clips(leap_case.body, hands, body_sides, hand_sides, options=SpliceOptions(transfer="local"))
    hand = splice_clips(leap_case.body, hands, body_sides, hand_sides, options=SpliceOptions(transfer="hand"))
    auto = splice_clips(leap_case.body, hands, body_sides, hand_sides)
    same = splice_clips(leap_case.body, leap_case.hands, body_sides, hand_sides)
    assert auto.transfer_modes == {"left": "hand", "right": "hand"}
    assert same.transfer_modes == {"left": "local", "right": "local"}
    np.testing.assert_allclose(auto.clip.rotations, hand.clip.rotations)
    for s in SIDES:  # the alignment does not depend on joint axes
        assert np.abs(hand.sides[s].alignment - leap_case.truth).mean() <= 1.5
    assert _finger_error_deg(hand, leap_case).mean() < 2.0
    assert _finger_error_deg(local, leap_case).mean() > 30.0


def test_paper_forearm_vector_alignment_and_trunk_yaw_options(case):
    body_sides, hand_sides = _sides(case)
    one = lambda d: {"left": d["left"]}
    vec = splice_clips(case.body, case.hands, one(body_sides), one(hand_sides),
                       options=SpliceOptions(forearm_align="vector"))
    assert np.abs(vec.sides["left"].alignment - case.truth).mean() <= 2.5
    trunk = splice_clips(case.body, case.hands, one(body_sides), one(hand_sides),
                         options=SpliceOptions(yaw="trunk"))
    assert np.abs(trunk.sides["left"].alignment - case.truth).mean() <= 1.5


def test_constraints_hold_exactly_and_within_tolerance(case):
    body_sides, hand_sides = _sides(case)
    # pairs away from the truth, so the warp has to bend to meet them
    t = case.truth
    cons = [Constraint(60, int(round(t[60])) + 8), Constraint(150, int(round(t[150])) - 6, 0),
            Constraint(240, int(round(t[240])) + 9, 3)]
    r = splice_clips(case.body, case.hands, {"right": body_sides["right"]}, {"right": hand_sides["right"]},
                     constraints=cons)
    a = r.sides["right"]
    for c in cons:
        for path in (a.first.path, a.second.path):
            cols = path[path[:, 0] == c.body, 1]
            assert np.all(np.abs(cols - c.hand) <= c.tolerance), (c, cols)
        assert abs(a.alignment[c.body] - c.hand) <= c.tolerance
    assert a.alignment[60] == t[60].round() + 8


def test_median_alignment_takes_the_median_of_matched_columns():
    path = np.array([[0, 0], [0, 1], [0, 2], [1, 3], [2, 3], [2, 4], [3, 5]])
    np.testing.assert_array_equal(median_alignment(path, 4), [1.0, 3.0, 3.5, 5.0])


def test_phase_boundaries_where_the_velocity_sign_pattern_changes():
    v = np.zeros((40, 3))
    v[:10, 0] = 5.0   # out
    v[10:12, 0] = -5  # a two-frame blip: too short to be a phase
    v[12:20, 0] = 5.0
    v[20:30, 0] = -5.0  # back
    # 30..39: hold
    np.testing.assert_array_equal(phase_boundaries(v, 1.0, 4), [20, 30])


def test_transfer_fingers_is_relative_to_rest_and_blends_jumps(case):
    body, hands = case.body, case.hands
    pairs = [("RightHandIndex2", "RightHandIndex2")]
    n = body.num_frames
    ident = np.arange(n, dtype=float)
    tr = transfer_fingers(body, hands.slice(0, n), pairs, ident, blend_window=0)
    j = hands.skeleton.index("RightHandIndex2")
    assert quat_angle_deg(tr.rotations[:, 0], hands.rotations[:n, j]).max() < 1e-6
    # a jump of 20 hand frames at body frame 100 is cross-faded over the window
    a = ident.copy()
    a[101:] += 20
    hard = transfer_fingers(body, hands, pairs, a, blend_window=0)
    soft = transfer_fingers(body, hands, pairs, a, blend_window=6)
    assert soft.seams.tolist() == [100] and hard.seams.tolist() == [100]
    step = lambda r: quat_angle_deg(r.rotations[1:, 0], r.rotations[:-1, 0])
    assert step(soft)[94:107].max() < 0.5 * step(hard)[100]
    np.testing.assert_allclose(soft.rotations[:94], hard.rotations[:94])
    np.testing.assert_allclose(soft.rotations[108:], hard.rotations[108:])


def test_finger_joints_pair_from_the_fingertip():
    body = HandSide("left", "hand_l", fingers={"index": ("index_metacarpal_l", "index_01_l", "index_02_l",
                                                           "index_03_l"), "pinky": ("pinky_01_l",)})
    hand = HandSide("left", "lHand", fingers={"index": ("lIndex1", "lIndex2", "lIndex3"), "thumb": ("lThumb1",)})
    pairs, bu, hu = pair_finger_joints(body, hand)
    assert pairs == [("index_01_l", "lIndex1"), ("index_02_l", "lIndex2"), ("index_03_l", "lIndex3")]
    assert bu == ["index_metacarpal_l", "pinky_01_l"] and hu == ["lThumb1"]


def test_bad_input_is_rejected(case):
    body_sides, hand_sides = _sides(case)
    with pytest.raises(ValueError, match=r"Expected clips at the same frame rate, got 30.0 and 60.0"):
        splice_clips(case.body, case.hands.replace(fps=60.0), body_sides, hand_sides)
    with pytest.raises(ValueError, match=r"Expected the same non-empty sides, got \['left', 'right'\] and \['left'\]"):
        splice_clips(case.body, case.hands, body_sides, {"left": hand_sides["left"]})
    no_forearm = HandSide("right", "RightHand", fingers=body_sides["right"].fingers)
    with pytest.raises(ValueError, match="hand 'right' has no forearm joint; markers need one"):
        splice_clips(case.body, case.hands, {"right": body_sides["right"]}, {"right": no_forearm})
    with pytest.raises(ValueError, match=r"constraint 5:400: hand frame 400 is out of range 0..329"):
        align_hands(np.zeros((300, 4, 3)), np.zeros((330, 4, 3)), 30.0, constraints=[Constraint(5, 400)])
    with pytest.raises(ValueError, match="Expected yaw 'window', 'trunk' or 'none', got 'up'"):
        SpliceOptions(yaw="up")


# -- command line -----------------------------------------------------------------------------
def _write_bvh(clip, path):
    from usdhands.formats.io import write_asset
    from usdhands.model.asset import Asset

    write_asset(Asset("synthetic", (clip.skeleton,), (clip,), ()), path)
    return path


@pytest.fixture(scope="module")
def bvh_case(tmp_path_factory):
    d = tmp_path_factory.mktemp("splice")
    c = make_case(240, seed=3, partial=True)
    return c, _write_bvh(c.body, d / "body.bvh"), _write_bvh(c.hands, d / "hands.bvh"), d


def _run(argv, capsys):
    from usdhands.cli import main

    status = main(argv)
    out = capsys.readouterr()
    return status, out.out, out.err


def test_cli_splices_bvh_files_against_the_known_warp(bvh_case, capsys):
    import json

    from usdhands.formats.io import read_clip

    c, body, hands, d = bvh_case
    out = d / "out.bvh"
    status, stdout, err = _run(["splice", str(body), str(hands), "-o", str(out), "--json",
                                "--plot", str(d / "plots")], capsys)
    assert status == 0, err
    rep = json.loads(stdout)
    for s in SIDES:
        a = np.array(rep["alignment"][s])
        assert a.shape == (240,) and np.abs(a - c.truth).mean() <= 1.5
        assert rep["costs"][s]["second_pass_mean_deg"] < 5.0 and rep["phases"][s]
    assert ["RightHandIndex2", "rIndex2"] in rep["pairs"]["right"]
    assert (d / "plots" / "splice_left.png").stat().st_size > 10_000
    spliced = read_clip(out)
    names = [n for n in spliced.skeleton.joint_names if "Hand" in n and n[-1] in "123" and "_end" not in n]
    bj = [spliced.skeleton.index(n) for n in names]
    oj = [c.body.skeleton.index(n) for n in names]
    err_deg = quat_angle_deg(spliced.rotations[:, bj], c.body.rotations[:, oj])
    assert len(names) == 30 and err_deg.mean() < 2.0


def test_cli_real_leap_recording_onto_a_body_resamples_and_transfers_relative_to_rest(bvh_case, shared_assets,
                                                                                      capsys):
    import json

    from usdhands.formats.io import read_clip
    from usdhands.model.rotations import quat_conjugate, quat_multiply

    c, body, _, d = bvh_case
    leap = shared_assets / "leap_hands" / "gesture-typing.bvh"
    out = d / "leap_out.bvh"
    status, stdout, err = _run(["splice", str(body), str(leap), "-o", str(out), "--json"], capsys)
    assert status == 0, err
    # the Leap rig's joint axes differ from the body's: auto carries rotations through the hands' axes
    assert json.loads(stdout)["transfer"] == {"right": "hand"}
    assert "right hand: the finger joints of BODY and HANDS have other axis conventions" in err
    status, stdout, err = _run(["splice", str(body), str(leap), "-o", str(out), "--json", "--transfer", "local"],
                               capsys)
    assert status == 0, err
    assert "HANDS is at 37.04 fps and BODY at 30 fps: HANDS resampled to 30 fps (317 -> 256 frames); --match and " \
           "the reported alignment use HANDS's own frame numbers (constraints hold to within one resampled frame)" in err
    assert "HANDS finger joints without a counterpart" not in err
    assert "usdhands: note: HANDS has no left hand: BODY's left hand keeps its own motion" in err
    rep = json.loads(stdout)
    assert list(rep["alignment"]) == ["right"]  # the recording has a right hand only
    a = np.array(rep["alignment"]["right"])
    assert a[0] == 0 and a[-1] == pytest.approx(255 * 37.037037 / 30, abs=0.01) and np.all(np.diff(a) >= 0)
    # where the aligned frame is a whole frame of the resampled clip, the finger equals
    # rest_body * rest_hand^-1 * q_hand
    hands = read_clip(leap).resample(30.0)
    spliced = read_clip(out)
    r = a * 30 / 37.037037  # frames of the resampled recording
    seams = np.array(rep["seams"]["right"] or [-100])
    whole = [i for i in range(240) if abs(r[i] - round(r[i])) < 1e-3 and np.abs(seams - i).min() > 5]
    assert whole
    k = whole[len(whole) // 2]
    t = int(round(r[k]))
    hj = hands.skeleton.index("rIndex2")
    bj = spliced.skeleton.index("RightHandIndex2")
    want = quat_multiply(spliced.skeleton.rest_rotations[bj],
                         quat_multiply(quat_conjugate(hands.skeleton.rest_rotations[hj]), hands.rotations[t, hj]))
    assert quat_angle_deg(spliced.rotations[k, bj], want) < 0.5


@pytest.mark.parametrize("extra, message", [
    (["--match", "10:400"], "--match: constraint 10:400: hand frame 400 is out of range 0..263 "
                            "(BODY has 240 frames, HANDS 264)"),
    (["--match", "250:10"], "--match: constraint 250:10: body frame 250 is out of range 0..239"),
    (["--match", "50:60", "--match", "40:70"], "--match: constraints out of order: 40:70 after 50:60"),
    (["--match", "50-60"], "bad --match '50-60': expected BODY_FRAME:HAND_FRAME[:TOLERANCE] with 0-based"),
    (["--band", "0.3"], "bad --band '0.3': expected two positive fractions W1,W2 such as 0.3,0.1"),
    (["--side", "left", "--hands-handmap", "{right_only}"], "HANDS has no left hand (found: right)"),
    (["--as-layer"], "bad.bvh: --as-layer needs a USD output (.usd, .usda, .usdc)"),
])
def test_cli_bad_input_exits_2_with_one_line(bvh_case, capsys, extra, message):
    import json

    c, body, hands, d = bvh_case
    right_only = d / "right_only.json"
    right_only.write_text(json.dumps({"left": None, "right": leap_handside("right").to_dict()}))
    extra = [e.replace("{right_only}", str(right_only)) for e in extra]
    status, stdout, err = _run(["splice", str(body), str(hands), "-o", str(d / "bad.bvh"), *extra], capsys)
    assert status == 2
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (d / "bad.bvh").exists()


def test_cli_hands_without_forearm_is_an_error(bvh_case, capsys):
    import json

    c, body, hands, d = bvh_case
    hm = d / "no_forearm.json"
    side = leap_handside("right").to_dict()
    side["forearm"] = None
    hm.write_text(json.dumps({"left": None, "right": side}))
    status, _, err = _run(["splice", str(body), str(hands), "-o", str(d / "bad.bvh"), "--hands-handmap", str(hm)],
                          capsys)
    assert status == 2
    assert f"{hands}: HANDS: the right hand (wrist 'rHand') has no forearm joint; splicing needs a forearm and " \
           "a wrist" in err


def test_cli_hands_file_without_hands_names_the_file(bvh_case, shared_assets, capsys):
    c, body, hands, d = bvh_case
    cesium = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    status, _, err = _run(["splice", str(body), str(cesium), "-o", str(d / "bad.bvh")], capsys)
    assert status == 2
    assert err.startswith(f"usdhands: error: {cesium}: HANDS: no hand found in skeleton")


def test_cli_usd_body_gets_an_override_layer_with_the_spliced_fingers(bvh_case, capsys):
    from usdhands.formats.io import read_clip, write_asset
    from usdhands.model.asset import Asset

    c, _, hands, d = bvh_case
    body_usd = d / "body.usda"
    write_asset(Asset("synthetic", (c.body.skeleton,), (c.body,), ()), body_usd)
    out = d / "spliced.usda"
    status, _, err = _run(["splice", str(body_usd), str(hands), "-o", str(out), "--layer", "--side", "left"],
                          capsys)
    assert status == 0, err
    assert "subLayers" in out.read_text()[:400]
    from usdhands.formats.usd_validate import usd_compliance_errors

    assert usd_compliance_errors(out) == []
    spliced = read_clip(out)
    names = [n for n in spliced.skeleton.joint_names if n.rsplit("/", 1)[-1].startswith("LeftHand")
             and n[-1] in "123"]
    bj = [spliced.skeleton.index(n) for n in names]
    oj = [c.body.skeleton.index(n.rsplit("/", 1)[-1]) for n in names]
    assert len(names) == 15
    assert quat_angle_deg(spliced.rotations[:, bj], c.body.rotations[:, oj]).mean() < 2.0


def test_cli_sample_conversation_glb_with_a_bvh_hand_take(sample_assets, tmp_path, capsys, gltf_validator):
    """A body clip with fingers from the samples, its hand take made with the known warp."""
    import json

    from usdhands.formats.io import read_clip
    from usdhands.model.hand_detection import detect_hands

    src = sample_assets / "conversation.glb"
    if not src.exists():
        pytest.skip(f"{src} not found")
    body = read_clip(src)
    hm = detect_hands(body.skeleton)
    hands, truth = hand_session(body, hm.sides, seed=1)
    hands_path = _write_bvh(hands.with_meters_per_unit(0.01), tmp_path / "hands.bvh")
    out = tmp_path / "spliced.glb"
    status, stdout, err = _run(["splice", str(src), str(hands_path), "-o", str(out), "--json"], capsys)
    assert status == 0, err
    rep = json.loads(stdout)
    for s in SIDES:
        assert np.abs(np.array(rep["alignment"][s]) - truth).mean() <= 1.5
    spliced = read_clip(out)
    fingers = [body.skeleton.index(j) for h in hm.sides for j in h.finger_joints]
    assert quat_angle_deg(spliced.rotations[:, fingers], body.rotations[:, fingers]).mean() < 2.0
    report, = gltf_validator(out)
    assert report["numErrors"] == 0, report["messages"][:3]


def test_cli_constraints_are_in_the_hands_file_frames_when_resampled(bvh_case, shared_assets, capsys):
    import json

    c, body, _, d = bvh_case
    leap = shared_assets / "leap_hands" / "gesture-typing.bvh"
    status, stdout, err = _run(["splice", str(body), str(leap), "-o", str(d / "leap_c.bvh"), "--json",
                                "--match", "100:150", "--match", "200:260:4"], capsys)
    assert status == 0, err
    a = np.array(json.loads(stdout)["alignment"]["right"])
    step = 37.037037 / 30  # one frame of the resampled recording, in the recording's frames
    assert abs(a[100] - 150) <= step / 2 + 1e-6
    assert abs(a[200] - 260) <= 4 + step
    status, _, err = _run(["splice", str(body), str(leap), "-o", str(d / "leap_c.bvh"), "--match", "100:317"], capsys)
    assert status == 2 and "hand frame 317 is out of range 0..316 (BODY has 240 frames, HANDS 317)" in err


def test_cli_reports_finger_joints_without_counterpart(bvh_case, capsys):
    import json

    c, body, hands, d = bvh_case
    side = leap_handside("right").to_dict()
    side["fingers"]["pinky"] = ["rPinky2", "rPinky3"]
    side["fingers"]["thumb"] = []
    hm = d / "short_pinky.json"
    hm.write_text(json.dumps({"left": None, "right": side}))
    status, stdout, err = _run(["splice", str(body), str(hands), "-o", str(d / "short.bvh"), "--json",
                                "--hands-handmap", str(hm)], capsys)
    assert status == 0, err
    assert ("right hand: BODY finger joints without a counterpart in HANDS keep their own motion: "
            "RightHandThumb1, RightHandThumb2, RightHandThumb3, RightHandPinky1") in err
    rep = json.loads(stdout)
    assert ["RightHandPinky2", "rPinky2"] in rep["pairs"]["right"] and len(rep["pairs"]["right"]) == 11


def _write_markers_csv(path, markers: dict, frame_column=True):
    names = ("wrist_a", "wrist_b", "forearm", "hand")
    sides = list(markers)
    header = (["frame"] if frame_column else []) + [f"{s}.{mk}.{a}" for s in sides for mk in names for a in "xyz"]
    T = next(iter(markers.values())).shape[0]
    lines = [",".join(header)]
    for t in range(T):
        vals = [f"{markers[s][t, k, a]:.6f}" for s in sides for k in range(4) for a in range(3)]
        lines.append(",".join(([str(t)] if frame_column else []) + vals))
    path.write_text("\n".join(lines) + "\n")
    return path


def _real_markers(clip, sides_map, seed):
    """Markers elsewhere than the joint-derived ones (wider wrist bar, forearm marker further back), with jitter."""
    rng = np.random.default_rng(seed)
    out = {}
    for s, side in sides_map.items():
        off = default_marker_offsets(clip.skeleton, side, wrist_width=0.4, forearm_distance=1.5)
        out[s] = markers_from_joints(clip, side, off) + rng.normal(scale=0.2, size=(clip.num_frames, 4, 3))
    return out


def test_cli_real_marker_positions_from_csv(bvh_case, capsys):
    import json

    from usdhands.formats.io import read_clip
    from usdhands.model.hand_detection import detect_hands

    c, body, hands, d = bvh_case
    bclip, hclip = read_clip(body), read_clip(hands)
    bmap, hmap = detect_hands(bclip.skeleton), detect_hands(hclip.skeleton)
    bm = _real_markers(bclip, {s: bmap[s] for s in SIDES}, 1)
    hm = _real_markers(hclip, {s: hmap[s] for s in SIDES}, 2)
    bcsv = _write_markers_csv(d / "body_markers.csv", bm)
    hcsv = _write_markers_csv(d / "hand_markers.csv", hm, frame_column=False)
    status, stdout, err = _run(["splice", str(body), str(hands), "-o", str(d / "m.bvh"), "--json"], capsys)
    assert status == 0, err
    plain = json.loads(stdout)
    status, stdout, err = _run(["splice", str(body), str(hands), "-o", str(d / "m.bvh"), "--json",
                                "--body-markers", str(bcsv), "--hands-markers", str(hcsv)], capsys)
    assert status == 0, err
    rep = json.loads(stdout)
    assert rep["markers"] == {"body": str(bcsv), "hands": str(hcsv)} and plain["markers"] == {"body": "joints",
                                                                                           "hands": "joints"}
    # the markers were used (the first pass compares them) and give the library's result with them
    lib = splice_clips(bclip, hclip, {s: bmap[s] for s in SIDES}, {s: hmap[s] for s in SIDES},
                       body_markers=bm, hand_markers=hm)
    for s in SIDES:
        assert rep["costs"][s]["first_pass"] != plain["costs"][s]["first_pass"]
        assert rep["costs"][s]["first_pass"] == pytest.approx(lib.sides[s].first.cost, abs=1e-3)
        assert np.allclose(rep["alignment"][s], np.round(lib.sides[s].alignment, 3))
        assert np.abs(np.array(rep["alignment"][s]) - c.truth).mean() <= 1.5


def test_cli_real_markers_of_a_resampled_hand_take(bvh_case, shared_assets, capsys):
    import json

    from usdhands.formats.io import read_clip
    from usdhands.model.hand_detection import detect_hands

    c, body, _, d = bvh_case
    leap = shared_assets / "leap_hands" / "gesture-typing.bvh"
    lclip = read_clip(leap)
    hm = {"right": markers_from_joints(lclip, detect_hands(lclip.skeleton).right)}
    csv = _write_markers_csv(d / "leap_markers.csv", hm)  # 317 rows at 37.04 fps, the recording's frames
    status, stdout, err = _run(["splice", str(body), str(leap), "-o", str(d / "lm.bvh"), "--json"], capsys)
    plain = json.loads(stdout)
    status, stdout, err = _run(["splice", str(body), str(leap), "-o", str(d / "lm.bvh"), "--json",
                                "--hands-markers", str(csv)], capsys)
    assert status == 0, err
    rep = json.loads(stdout)
    # the same positions as the joint-derived markers, resampled linearly instead of by slerp: nearly the same costs
    assert rep["costs"]["right"]["first_pass"] == pytest.approx(plain["costs"]["right"]["first_pass"], rel=0.05)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("right.hand.z", "right.palm.z"), "unknown column 'right.palm.z': expected "
                                                           "<side>.<marker>.<axis> with side left or right"),
    (lambda t: "\n".join(t.splitlines()[:-1]) + "\n", "239 rows of markers for a clip of 240 frames"),
    (lambda t: t.replace(",right.hand.z", "").replace(t.splitlines()[1], t.splitlines()[1].rsplit(",", 1)[0]),
     "the right hand's markers lack columns right.hand.z"),
    (lambda t: t.replace(t.splitlines()[3], t.splitlines()[3].rsplit(",", 1)[0] + ",nan"),
     "bad_markers.csv: row 4: column 'right.hand.z': expected a finite number, got 'nan'"),
    (lambda t: "\n".join(["frame," + ",".join(f"right.{m}.{a}" for m in ("wrist_a", "wrist_b", "forearm", "hand") for a in "xyz")]
               + [f"{k + 1}," + ",".join(["0"] * 12) for k in range(240)]) + "\n",
     "bad_markers.csv: row 2: frame column: expected 0, got '1'"),
])
def test_cli_bad_marker_files_exit_2(bvh_case, capsys, edit, message):
    c, body, hands, d = bvh_case
    good = _write_markers_csv(d / "good.csv", {"right": np.zeros((240, 4, 3))})
    bad = d / "bad_markers.csv"
    bad.write_text(edit(good.read_text()))
    status, _, err = _run(["splice", str(body), str(hands), "-o", str(d / "bad.bvh"), "--body-markers", str(bad)],
                          capsys)
    assert status == 2 and message in err and err.count("\n") == 1, err
    assert not (d / "bad.bvh").exists()


def test_cli_markers_for_no_spliced_hand_is_an_error(bvh_case, capsys):
    c, body, hands, d = bvh_case
    only_right = _write_markers_csv(d / "right_markers.csv", {"right": np.zeros((240, 4, 3))})
    status, _, err = _run(["splice", str(body), str(hands), "-o", str(d / "bad.bvh"), "--side", "left",
                           "--body-markers", str(only_right)], capsys)
    assert status == 2
    assert err == f"usdhands: error: {only_right}: no markers for the left hand spliced from BODY\n"


def test_cli_notes_clips_of_very_different_durations(bvh_case, capsys):
    from usdhands.formats.io import read_clip, write_clip

    c, body, hands, d = bvh_case
    short = d / "short_hands.bvh"
    write_clip(hands, read_clip(hands).slice(0, 40), short)
    status, _, err = _run(["splice", str(body), str(short), "-o", str(d / "short_out.bvh")], capsys)
    assert status == 0, err
    assert "usdhands: note: BODY lasts 7.97 s and HANDS 1.3 s: the path runs from the first to the last frames of " \
           "both (fixed ends)" in err
    status, _, err = _run(["splice", str(body), str(hands), "-o", str(d / "short_out.bvh")], capsys)
    assert status == 0 and "lasts" not in err


def test_cli_usd_sample_body_full_copy_with_a_usd_hand_take(sample_assets, tmp_path, capsys):
    """humanoid.usda as BODY, its hand take (known warp) as a USD file of its own: USD in, USD out."""
    import json

    from usdhands.formats.io import read_clip, write_asset
    from usdhands.formats.usd_validate import usd_compliance_errors
    from usdhands.model.asset import Asset
    from usdhands.model.hand_detection import detect_hands

    src = sample_assets / "humanoid.usda"
    body = read_clip(src)
    hm = detect_hands(body.skeleton)
    hands, truth = hand_session(body, hm.sides, seed=4)
    hands_path = tmp_path / "hands.usdc"
    write_asset(Asset(path=None, skeletons=(hands.skeleton,), clips=(hands,)), hands_path)
    out = tmp_path / "spliced.usda"
    status, stdout, err = _run(["splice", str(src), str(hands_path), "-o", str(out), "--json"], capsys)
    assert status == 0, err
    rep = json.loads(stdout)
    # the sample's left arm hangs still (its wrist moves 1.2 cm): it takes the right hand's timing
    assert rep["timing_from"] == {"left": "right", "right": "right"}
    assert "usdhands: note: left hand: its wrist barely moves (range 1.2 cm in BODY" in err
    for s in SIDES:
        assert np.abs(np.array(rep["alignment"][s]) - truth).mean() <= 1.5
    assert "subLayers" not in out.read_text()[:400] and usd_compliance_errors(out) == []
    spliced = read_clip(out)
    fingers = [body.skeleton.index(j) for h in hm.sides for j in h.finger_joints]
    assert quat_angle_deg(spliced.rotations[:, fingers], body.rotations[:, fingers]).mean() < 2.0
    others = [j for j in range(body.skeleton.num_joints) if j not in fingers]
    assert quat_angle_deg(spliced.rotations[:, others], body.rotations[:, others]).max() < 1e-4


def test_a_still_hand_takes_the_other_hands_timing(sample_assets):
    from usdhands.formats.io import read_clip
    from usdhands.model.hand_detection import detect_hands

    body = read_clip(sample_assets / "humanoid.usda")
    hm = detect_hands(body.skeleton)
    hands, truth = hand_session(body, hm.sides, seed=4)
    sides = {s: hm[s] for s in SIDES}
    shared = splice_clips(body, hands, sides, sides)
    alone = splice_clips(body, hands, sides, sides, options=SpliceOptions(still_range_cm=0.0))
    assert shared.timing_from == {"left": "right", "right": "right"} and alone.timing_from == {"left": "left",
                                                                                                 "right": "right"}
    assert shared.wrist_range_cm["left"][0] < 5.0 < shared.wrist_range_cm["right"][0]
    err = lambda r, s: np.abs(r.sides[s].alignment - truth).mean()
    assert err(shared, "left") == err(shared, "right") <= 1.5 < err(alone, "left")
    assert np.array_equal(shared.sides["left"].alignment, alone.sides["right"].alignment)


def test_cli_still_hand_alone_gets_a_note(sample_assets, tmp_path, capsys):
    from usdhands.formats.io import read_clip, write_asset
    from usdhands.model.asset import Asset
    from usdhands.model.hand_detection import detect_hands

    src = sample_assets / "humanoid.usda"
    body = read_clip(src)
    hands, _ = hand_session(body, detect_hands(body.skeleton).sides, seed=4)
    hands_path = tmp_path / "hands.usdc"
    write_asset(Asset(path=None, skeletons=(hands.skeleton,), clips=(hands,)), hands_path)
    status, _, err = _run(["splice", str(src), str(hands_path), "-o", str(tmp_path / "o.usda"), "--side", "left"],
                          capsys)
    assert status == 0, err
    assert "usdhands: note: left hand: its wrist barely moves (range 1.2 cm in BODY, 22 cm in HANDS): the " \
           "alignment has little to go on; splice both hands, or add --match constraints" in err
    status, _, err = _run(["splice", str(src), str(hands_path), "-o", str(tmp_path / "o.usda"), "--side", "right"],
                          capsys)
    assert status == 0 and "barely moves" not in err


@pytest.mark.parametrize("frames", [5, 6, 7, 30, 569])
def test_sign_features_derivatives_equal_scipy_savgol_filter(frames):
    """sign_features caches the Savitzky-Golay operators (coefficients, and the end frames'
    cubic fits as matrices): the same derivatives as scipy's savgol_filter with mode="interp"."""
    from scipy.signal import savgol_filter

    x = np.cumsum(np.random.default_rng(frames).normal(size=(frames, 4, 3)), axis=0) * 10
    vel, acc, eps_v, eps_a = sign_features(x, 30.0)
    w = min(7, frames if frames % 2 else frames - 1)
    for got, deriv in ((vel, 1), (acc, 2)):
        want = savgol_filter(x, w, 3, deriv=deriv, delta=1 / 30, axis=0, mode="interp")
        h = w // 2
        assert np.array_equal(got[h:frames - h], want[h:frames - h])  # the same convolution
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())  # the end fits
    assert eps_v == pytest.approx(0.05 * np.sqrt(np.mean(vel ** 2)), rel=1e-12)


def test_a_body_that_walks_aligns_as_one_that_stands(case):
    """The first pass subtracts the shoulder at every frame (paper sec. 4.1): a body that
    walks forward 1.5 m/s and bobs 3 cm gets the phases of the same body standing still.
    Subtracting only the first frame's shoulder gave the walk's own signs to every marker."""
    body_sides, hand_sides = _sides(case)
    body = case.body
    sk = body.skeleton
    root = [j for j in range(sk.num_joints) if sk.parents[j] < 0][0]
    t = np.arange(body.num_frames) / body.fps
    per_metre = 1.0 / sk.meters_per_unit
    trans = np.array(body.translations if body.translations is not None else
                     np.broadcast_to(sk.rest_translations, body.rotations.shape[:2] + (3,)), dtype=np.float64)
    trans[:, root, 2] += 1.5 * t * per_metre
    trans[:, root, 1] += 0.03 * np.sin(2 * np.pi * 1.8 * t) * per_metre
    walking = Clip(sk, body.fps, body.rotations, trans)
    for s in SIDES:
        still = splice_clips(body, case.hands, {s: body_sides[s]}, {s: hand_sides[s]}).sides[s]
        walks = splice_clips(walking, case.hands, {s: body_sides[s]}, {s: hand_sides[s]}).sides[s]
        first_still = median_alignment(still.first.path, body.num_frames)
        first_walks = median_alignment(walks.first.path, body.num_frames)
        assert np.abs(first_walks - first_still).mean() < 0.25, s
        assert np.abs(walks.alignment - case.truth).mean() <= 1.5, s

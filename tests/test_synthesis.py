"""Synthesis building blocks: segmentation, eq. 1 search, eq. 2–3 graph, stitching, transfer, database."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest
from synthesis_data import gesture_clip, gesture_set, tiny_handmap, tiny_skeleton

from usdhands.algorithms.synthesis.database import DatabaseClip, build_database, load_database, save_database
from usdhands.algorithms.synthesis.finger_transfer import (
    NUM_DOFS, apply_canonical_curves, canonical_curves, hand_rig, mirror_curves,
)
from usdhands.algorithms.synthesis.motion_graph import least_cost_path, transition_costs
from usdhands.algorithms.synthesis.segment_cost import (
    band_window, dtw_align, dtw_align_fast, knn_segments, lb_keogh, weight_features,
)
from usdhands.algorithms.synthesis.segmentation import segment_by_speed, wrist_speed
from usdhands.algorithms.synthesis.stitching import stitch_fragments
from usdhands.algorithms.synthesis.config import SynthesisConfig, load_synthesis_config
from usdhands.algorithms.synthesis.wrist_features import arm_features, mirror_features, reach_cm, wrist_features
from usdhands.errors import ConfigError
from usdhands.model import Clip, HandMap, HandSide, Skeleton
from usdhands.model.rotations import euler_deg_to_quat, quat_angle_deg, quat_multiply

ROOT = Path(__file__).resolve().parent.parent


# -- configuration -----------------------------------------------------------------

def test_config_defaults_are_the_papers():
    c = SynthesisConfig()
    assert (c.segmentation.min_segment_s, c.segmentation.max_segment_s) == (0.33, 2.0)
    assert (c.segment_cost.w_position, c.segment_cost.w_rotation, c.segment_cost.length_factor, c.segment_cost.k) == (1, 0.5, 1.5, 5)
    assert (c.transition.w_joint, c.transition.w_velocity) == (1, 0.5)
    assert (c.path.w_segment, c.path.w_transition) == (1, 0.5)
    assert (c.stitching.blend_mean_deg, c.stitching.blend_max_deg) == (5, 20)


def test_config_file_round_trip_and_errors(tmp_path):
    p = tmp_path / "c.json"
    p.write_text(json.dumps({"segment_cost": {"k": 3, "w_rotation": 0.25}}))
    c = load_synthesis_config(p)
    assert c.segment_cost.k == 3 and c.segment_cost.w_rotation == 0.25 and c.path.w_transition == 0.5
    p.write_text(json.dumps(SynthesisConfig().to_dict()))
    assert load_synthesis_config(p) == SynthesisConfig()
    p.write_text(json.dumps({"segment_cost": {"kk": 3}}))
    with pytest.raises(ConfigError, match=r"c\.json: invalid synthesis configuration at segment_cost: Additional properties are not allowed \('kk' was unexpected\)"):
        load_synthesis_config(p)
    p.write_text(json.dumps({"segment_cost": {"lower_bound": "lb"}}))
    with pytest.raises(ConfigError, match=r"at segment_cost/lower_bound: 'lb' is not one of \['kim', 'keogh', 'none'\]"):
        load_synthesis_config(p)
    p.write_text(json.dumps({"stitching": {"blend_max_deg": -1}}))
    with pytest.raises(ConfigError, match="at stitching/blend_max_deg: -1 is less than the minimum of 0"):
        load_synthesis_config(p)


@pytest.mark.parametrize("name", ["synthesis_config.schema.json", "database.schema.json"])
def test_shipped_schemas_equal_sources(name):
    assert (ROOT / "schemas" / name).read_bytes() == (ROOT / "usdhands" / "schemas" / name).read_bytes()


# -- segmentation ------------------------------------------------------------------

def test_segmentation_cuts_at_threshold_crossings():
    fps = 30
    speed = np.r_[np.full(20, 50.0), np.full(15, 1.0), np.full(25, 40.0)]
    b = segment_by_speed(speed, fps, threshold=5, min_s=0.33, max_s=2.0)
    assert b.tolist() == [0, 20, 35, 60]


def test_segmentation_merges_short_and_splits_long_at_speed_minimum():
    fps = 30
    # a 4-frame hold is shorter than 0.33 s (10 frames): merged away
    speed = np.r_[np.full(30, 50.0), np.full(4, 1.0), np.full(30, 50.0)]
    b = segment_by_speed(speed, fps, 5, 0.33, 2.0)
    assert b.tolist() == [0, 34, 64]  # joined the (equally long) earlier neighbour
    # 3 s of motion with a dip at frame 50: split there
    speed = 50 + 40 * np.cos(np.linspace(0, 2 * np.pi, 90))
    speed[50] = 6.0  # lower than the cosine's own minimum (10 at frame 44.5)
    b = segment_by_speed(speed, fps, 5, 0.33, 2.0)
    assert b.tolist() == [0, 50, 90]


def test_segmentation_lengths_always_within_bounds():
    rng = np.random.default_rng(3)
    for _ in range(50):
        speed = np.abs(np.cumsum(rng.normal(0, 5, size=rng.integers(40, 400))))
        b = segment_by_speed(speed, 30, float(rng.uniform(1, 30)), 0.33, 2.0)
        lens = np.diff(b)
        assert b[0] == 0 and b[-1] == len(speed)
        assert (lens >= 10).all() and (lens <= 60).all()


def test_wrist_speed_of_known_motion():
    t = np.arange(60) / 30
    p = np.stack([30 * t, 0 * t, 0 * t], axis=1)  # 30 cm/s
    assert np.allclose(wrist_speed(p, 30), 30)


# -- eq. 1 and the search ------------------------------------------------------------

def test_band_window_numpy_equals_kernel():
    from usdhands.algorithms.synthesis import _dtw_kernel as kern

    for n, m, band in itertools.product(range(1, 25), range(1, 40), (0.1, 0.3, 1.0)):
        lo, hi = band_window(n, m, band)
        lo2, hi2 = np.empty(n, np.int64), np.empty(n, np.int64)
        kern.window(n, m, band, lo2, hi2)
        assert (lo == lo2).all() and (hi == hi2).all(), (n, m, band)


def test_dtw_recovers_a_known_warp():
    rng = np.random.default_rng(0)
    d = np.cumsum(rng.normal(size=(30, 6)), axis=0)
    # the input is the database segment played with a known warp: each frame of d
    # used by j(i) (steps 0, 1 or 2)
    steps = rng.choice([0, 1, 1, 2], size=35)
    j = np.concatenate([[0], np.cumsum(steps)])
    j = j[j < 30]
    j[-1] = 29
    q = d[j]
    cost, path = dtw_align(q, d, band=1.0)
    assert cost == pytest.approx(0.0, abs=1e-12)
    assert np.allclose(d[path], q)


def test_compiled_alignment_equals_numpy_twin():
    rng = np.random.default_rng(11)
    for _ in range(200):
        n, m = int(rng.integers(1, 30)), int(rng.integers(1, 45))
        q, d = rng.normal(size=(n, 6)), rng.normal(size=(m, 6))
        band = float(rng.choice([0.1, 0.3, 1.0]))
        c1, p1 = dtw_align(q, d, band)
        c2, p2 = dtw_align_fast(q, d, band)
        assert (c1 == c2 == float("inf")) or c1 == pytest.approx(c2)
        assert np.array_equal(p1, p2)


def test_weighted_cost_is_eq1():
    rng = np.random.default_rng(1)
    q, d = rng.normal(size=(12, 6)), rng.normal(size=(12, 6))
    w = [1, 1, 1, 0.5, 0.5, 0.5]
    cost, path = dtw_align(weight_features(q, w), weight_features(d, w), band=1.0)
    diff = q - d[path]
    expected = (1.0 * (diff[:, :3] ** 2).sum() + 0.5 * (diff[:, 3:] ** 2).sum()) / 12
    assert cost == pytest.approx(expected)
    assert path[0] == 0 and path[-1] == 11 and set(np.diff(path)) <= {0, 1, 2}


def _random_segments(rng, total, lo, hi):
    out, s = [], 0
    while True:
        L = int(rng.integers(lo, hi))
        if s + L > total:
            return np.array(out)
        out.append((s, s + L))
        s += L


@pytest.mark.parametrize("band,k", [(0.3, 5), (1.0, 3), (0.15, 1)])
def test_knn_kernel_equals_brute_force_numpy(band, k):
    rng = np.random.default_rng(int(band * 100) + k)
    q = np.cumsum(rng.normal(size=(300, 6)), axis=0)
    d = np.cumsum(rng.normal(size=(1500, 6)), axis=0)
    qb, ds = _random_segments(rng, 300, 10, 50), _random_segments(rng, 1500, 10, 50)
    groups = rng.integers(0, 4, size=len(ds))
    qgroups = rng.integers(0, 4, size=len(qb))
    res = knn_segments(q, qb, d, ds, k=k, band=band, query_groups=qgroups, db_groups=groups)
    full = knn_segments(q, qb, d, ds, k=k, band=band, query_groups=qgroups, db_groups=groups, bound="none")
    keogh = knn_segments(q, qb, d, ds, k=k, band=band, query_groups=qgroups, db_groups=groups, bound="keogh")
    for r in (res, keogh):
        assert (r.index == full.index).all() and np.allclose(r.cost, full.cost)
    assert full.pruned.sum() == 0 and full.aligned.sum() == full.candidates.sum()
    assert res.pruned.sum() <= keogh.pruned.sum() and keogh.pruned.sum() > 0  # Keogh is the tighter bound
    for i, (a, b) in enumerate(qb):
        found = []
        for c, (x, y) in enumerate(ds):
            n, m = b - a, y - x
            if groups[c] == qgroups[i] or m * 1.5 < n or m > n * 1.5:
                continue
            cost, _ = dtw_align(q[a:b], d[x:y], band)
            assert lb_keogh(q[a:b], d[x:y], band) <= cost + 1e-9
            if np.isfinite(cost):
                found.append((cost, c))
        found.sort()
        want = [c for _, c in found[:k]] + [-1] * (k - len(found[:k]))
        assert res.index[i].tolist() == want
        assert np.allclose(res.cost[i][: len(found[:k])], [v for v, _ in found[:k]])


def test_knn_ties_go_to_the_lower_index_whatever_the_bound():
    rng = np.random.default_rng(9)
    seg = np.cumsum(rng.normal(size=(20, 6)), axis=0)
    d = np.concatenate([seg, seg + 5.0, seg, seg])  # segments 0, 2, 3 are identical
    ds = np.array([[0, 20], [20, 40], [40, 60], [60, 80]])
    q = seg + rng.normal(0, 0.1, size=seg.shape)
    for bound in ("none", "kim", "keogh"):
        r = knn_segments(q, [[0, 20]], d, ds, k=2, bound=bound)
        assert r.index[0].tolist() == [0, 2] and r.cost[0, 0] == r.cost[0, 1]


def test_knn_twelve_features_unrolled_equal_the_generic_alignment_to_the_bit():
    """D = 12 (the wrist features) runs an unrolled twin of the alignment; a zero 13th column
    adds exactly 0.0 to every local cost, so the generic alignment must give the same bits."""
    rng = np.random.default_rng(12)
    q = np.cumsum(rng.normal(size=(300, 12)), axis=0)
    d = np.cumsum(rng.normal(size=(2000, 12)), axis=0)
    qb, ds = _random_segments(rng, 300, 5, 50), _random_segments(rng, 2000, 5, 50)
    pad = lambda a: np.concatenate([a, np.zeros((len(a), 1))], axis=1)  # noqa: E731
    for bound in ("none", "kim"):
        r12 = knn_segments(q, qb, d, ds, k=4, band=0.3, bound=bound)
        r13 = knn_segments(pad(q), qb, pad(d), ds, k=4, band=0.3, bound=bound)
        assert np.array_equal(r12.index, r13.index) and np.array_equal(r12.cost, r13.cost)
        assert np.array_equal(r12.aligned, r13.aligned) and np.array_equal(r12.abandoned, r13.abandoned)
        assert (r12.index >= 0).all()


def test_knn_rejects_bad_input():
    with pytest.raises(ValueError, match=r"Expected k >= 1, got 0"):
        knn_segments(np.zeros((10, 6)), [[0, 10]], np.zeros((10, 6)), [[0, 10]], k=0)
    with pytest.raises(ValueError, match=r"Expected bound in \('none', 'kim', 'keogh'\), got 'lb'"):
        knn_segments(np.zeros((10, 6)), [[0, 10]], np.zeros((10, 6)), [[0, 10]], bound="lb")
    with pytest.raises(ValueError, match=r"db_segments must hold non-empty ranges inside 0..10"):
        knn_segments(np.zeros((10, 6)), [[0, 10]], np.zeros((10, 6)), [[0, 11]])


# -- eq. 2 and eq. 3 -------------------------------------------------------------------

def test_transition_cost_is_eq2():
    rng = np.random.default_rng(2)
    ea, va, sb, vb = (rng.normal(size=(3, 25)) for _ in range(4))
    t = transition_costs(ea, va, sb, vb, 1.0, 0.5)
    for a in range(3):
        for b in range(3):
            exp = (((ea[a] - sb[b]) ** 2).sum() + 0.5 * ((va[a] - vb[b]) ** 2).sum()) / 25
            assert t[a, b] == pytest.approx(exp)


def test_least_cost_path_equals_exhaustive_search():
    rng = np.random.default_rng(4)
    for _ in range(20):
        L, K = int(rng.integers(1, 5)), int(rng.integers(1, 4))
        cs = rng.uniform(0, 10, size=(L, K))
        tr = [rng.uniform(0, 10, size=(K, K)) for _ in range(L - 1)]
        path, cost = least_cost_path(cs, tr, 1.0, 0.5)
        best = min(itertools.product(range(K), repeat=L),
                   key=lambda p: sum(cs[i, p[i]] for i in range(L)) + 0.5 * sum(tr[i][p[i], p[i + 1]] for i in range(L - 1)))
        exp = sum(cs[i, best[i]] for i in range(L)) + 0.5 * sum(tr[i][best[i], best[i + 1]] for i in range(L - 1))
        assert cost == pytest.approx(exp)
        assert tuple(path) == best


# -- stitching -------------------------------------------------------------------------

def test_small_seam_differences_become_offsets_large_ones_blend():
    a = np.zeros((10, 4))
    small = np.full((10, 4), 3.0)  # 3 deg everywhere: offset
    big = np.full((10, 4), 30.0)  # 30 deg: blend
    out, seams = stitch_fragments([a, small, big], fps=10, blend_duration_s=0.5)
    assert seams.blended.tolist() == [False, True]
    assert np.allclose(out[10:20], 0.0)  # offset brought the constant fragment onto the previous pose
    assert np.allclose(out[20], 0.0) and np.allclose(out[25:], 30.0)  # blended back over 5 frames
    assert np.abs(np.diff(out, axis=0)).max() <= 30.0 / 5 + 1e-9


# -- finger transfer -----------------------------------------------------------------

def _random_finger_clip(sk, hm, rng, T=20):
    rot = np.zeros((T, sk.num_joints, 4))
    rot[..., 3] = 1
    rot[:] = sk.rest_rotations
    for side in hm.sides:
        for j in side.finger_joints:
            e = rng.uniform(-40, 40, size=(T, 3))
            rot[:, sk.index(j)] = quat_multiply(sk.rest_rotations[sk.index(j)], euler_deg_to_quat(e))
    return Clip(sk, 30, rot)


def test_canonical_curves_round_trip():
    sk, hm = tiny_skeleton(), tiny_handmap()
    clip = _random_finger_clip(sk, hm, np.random.default_rng(5))
    rig = hand_rig(sk, hm.left)
    cur = canonical_curves(clip, rig)
    base = clip.replace(rotations=np.broadcast_to(sk.rest_rotations, clip.rotations.shape))
    back = apply_canonical_curves(base, rig, cur)
    fj = [sk.index(j) for j in hm.left.finger_joints]
    assert quat_angle_deg(back.rotations[:, fj], clip.rotations[:, fj]).max() < 1e-6


def test_canonical_to_local_equals_the_three_hamilton_products():
    """local = reference ⊗ C⁻¹ ⊗ canonical ⊗ C, done as one 4×4 matrix per slot: the same to rounding."""
    from usdhands.algorithms.synthesis.finger_transfer import canonical_to_local, euler_xyz_deg_to_quat
    from usdhands.model.rotations import quat_conjugate

    sk, hm = tiny_skeleton(), tiny_handmap()
    rng = np.random.default_rng(8)
    clip = _random_finger_clip(sk, hm, rng)
    for pose in (None, clip):  # relative to the rest pose, or to the first frame of the input
        rig = hand_rig(sk, hm.left, pose)
        curves = rng.uniform(-90, 90, size=(40, NUM_DOFS))
        slots = np.nonzero(rig.present)[0]
        can = euler_xyz_deg_to_quat(curves.reshape(40, -1, 3)[:, slots])
        C = rig.frame[slots]
        rel = quat_multiply(quat_multiply(quat_conjugate(C)[None], can), C[None])
        want = quat_multiply(rig.reference_rotations(sk, slots)[None], rel)
        got = canonical_to_local(sk, rig, curves)
        assert got.shape == want.shape and np.abs(got - want).max() < 1e-14


def _rotated_rest_rig(sk: Skeleton, rng) -> Skeleton:
    """The same rig with random joint-frame conventions (rest rotations), same rest positions."""
    world = sk.rest_world_xforms()
    J = sk.num_joints
    new_world_rot = np.array([euler_deg_to_quat(rng.uniform(-180, 180, 3)) for _ in range(J)])
    from usdhands.model.rotations import quat_conjugate, quat_to_matrix

    local_q = np.zeros((J, 4))
    local_t = np.zeros((J, 3))
    for j in range(J):
        p = sk.parents[j]
        if p < 0:
            local_q[j] = new_world_rot[j]
            local_t[j] = world[j, :3, 3]
        else:
            local_q[j] = quat_multiply(quat_conjugate(new_world_rot[p]), new_world_rot[j])
            local_t[j] = quat_to_matrix(quat_conjugate(new_world_rot[p])) @ (world[j, :3, 3] - world[p, :3, 3])
    return Skeleton(sk.joint_names, sk.parents, local_t, local_q, meters_per_unit=sk.meters_per_unit)


def test_transfer_between_rigs_with_other_joint_axes_keeps_world_finger_shapes():
    rng = np.random.default_rng(6)
    sk, hm = tiny_skeleton(), tiny_handmap()
    clip = _random_finger_clip(sk, hm, rng)
    other = _rotated_rest_rig(sk, rng)
    assert np.allclose(other.rest_world_positions(), sk.rest_world_positions())
    cur = canonical_curves(clip, hand_rig(sk, hm.left))
    rest_clip = Clip(other, 30, np.broadcast_to(other.rest_rotations, (clip.num_frames, other.num_joints, 4)))
    moved = apply_canonical_curves(rest_clip, hand_rig(other, hm.left), cur)
    fj = [sk.index(j) for j in hm.left.finger_joints]
    assert np.allclose(moved.world_positions()[:, fj], clip.world_positions()[:, fj], atol=1e-6)


def test_mirrored_finger_motion_maps_onto_the_other_hand():
    rng = np.random.default_rng(8)
    sk, hm = tiny_skeleton(), tiny_handmap()
    clip = _random_finger_clip(sk, hm, rng)
    # mirror the left hand's local rotations onto the right (identity rest, x-mirror: (a,b,c) -> (a,-b,-c))
    from usdhands.model.rotations import quat_to_euler_deg

    rot = np.array(clip.rotations)
    for jl, jr in zip(hm.left.finger_joints, hm.right.finger_joints):
        e = quat_to_euler_deg(clip.rotations[:, sk.index(jl)])
        e[:, 1:] *= -1
        rot[:, sk.index(jr)] = euler_deg_to_quat(e)
    mirrored = clip.replace(rotations=rot)
    left = canonical_curves(clip, hand_rig(sk, hm.left))
    right = canonical_curves(mirrored, hand_rig(sk, hm.right))
    assert np.allclose(mirror_curves(left), right, atol=1e-6)


def test_two_bone_fingers_map_from_the_distal_end():
    sk = tiny_skeleton()
    hm = tiny_handmap().left
    two = HandSide("left", hm.wrist, hm.forearm, hm.shoulder, hm.root,
                   fingers={f: hm.fingers[f][1:] for f in hm.fingers if f != "pinky"})
    rig = hand_rig(sk, two)
    names = [sk.joint_names[j] if j >= 0 else None for j in rig.slot_joint]
    assert names[4:8] == ["LeftHandIndex3", "LeftHandIndex2", None, None]
    assert names[16:20] == [None] * 4


# -- wrist features --------------------------------------------------------------------

def test_wrist_features_ignore_root_motion_and_mirror():
    sk, hm = tiny_skeleton(), tiny_handmap()
    clip = gesture_clip(sk, "ok", np.random.default_rng(1))
    f = wrist_features(clip, hm.left)
    # turn and move the whole character: the features stay
    rot = np.array(clip.rotations)
    turn = euler_deg_to_quat(np.array([0.0, 70.0, 0.0]))
    rot[:, 0] = quat_multiply(turn, rot[:, 0])
    tr = np.array(clip.translations)
    tr[:, 0] += [50, 0, -20]
    moved = clip.replace(rotations=rot, translations=tr)
    assert np.allclose(wrist_features(moved, hm.left), f, atol=1e-9)
    # the right hand of this clip mirrors the left one's arm up to random variation:
    # mirrored features of the left hand at rest equal the right hand's at rest
    fr = wrist_features(clip, hm.right)
    assert np.allclose(mirror_features(f)[:3], fr[:3], atol=1e-6)
    # at rest the wrist sits at the rig's geometry: 18 + 28 + 25 cm out, 45 cm up (arm down 75 deg)
    assert reach_cm(sk, hm.left) == pytest.approx(np.hypot(0, 40) + np.hypot(18, 5) + 28 + 25)


def test_body_size_scaling_makes_a_bigger_character_match():
    sk, big = tiny_skeleton(), tiny_skeleton(body_scale=1.3)
    hm = tiny_handmap()
    rng1, rng2 = np.random.default_rng(2), np.random.default_rng(2)
    a = gesture_clip(sk, "big", rng1)
    b = gesture_clip(big, "big", rng2)
    b = b.replace(translations=a.translations * 1.3)
    fa = wrist_features(a, hm.left, 1.0)
    fb = wrist_features(b, hm.left, reach_cm(sk, hm.left) / reach_cm(big, hm.left))
    assert np.allclose(fa, fb, atol=1e-6)


def test_arm_features_have_all_roles():
    sk, hm = tiny_skeleton(), tiny_handmap()
    clip = gesture_clip(sk, "ok", np.random.default_rng(1))
    f = arm_features(clip, hm.left)
    assert sorted(f) == ["elbow_pos", "elbow_rot", "shoulder_pos", "shoulder_rot", "wrist_pos", "wrist_rot"]
    assert all(v.shape == (clip.num_frames, 9 if k.endswith("_rot") else 3) for k, v in f.items())


# -- database -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def small_db():
    hm = tiny_handmap()
    items = [DatabaseClip(c, hm, lab, f"/data/{c.name}.bvh") for lab, c in gesture_set(2)]
    return build_database(items, fps=30, mirror=True)


def test_world_xforms_for_equals_full_forward_kinematics_on_the_arm_chains():
    """Only the chains to the arms are computed (joint-major, seen time-major); those equal Clip.world_xforms."""
    from usdhands.algorithms.synthesis.wrist_features import world_xforms_for

    sk, hm = tiny_skeleton(), tiny_handmap()
    rng = np.random.default_rng(4)
    rot = quat_multiply(sk.rest_rotations[None], euler_deg_to_quat(rng.uniform(-60, 60, (20, sk.num_joints, 3))))
    clip = Clip(sk, 30, rot, np.broadcast_to(sk.rest_translations, (20, sk.num_joints, 3)) + rng.normal(0, 1, (20, 1, 3)))
    full = clip.world_xforms()
    part = world_xforms_for(clip, [hm.left, hm.right])
    assert part.shape == full.shape
    need = sorted({j for h in (hm.left, hm.right) for name in (h.wrist, h.forearm, h.shoulder) if name
                   for j in sk.chain_to_root(sk.index(name))})
    assert np.array_equal(part[:, need], full[:, need])
    rest = [j for j in range(sk.num_joints) if j not in need]
    assert rest and not part[:, rest].any()


def test_database_round_trip_memory_mapped(small_db, tmp_path):
    path = save_database(small_db, tmp_path / "db")
    db = load_database(path)
    assert isinstance(db.fingers, np.memmap) and isinstance(db.features, np.memmap)
    assert np.array_equal(np.asarray(db.fingers), small_db.fingers)
    assert np.array_equal(db.segments, small_db.segments)
    assert db.labels == sorted({"attention", "big", "doubt", "ok", "pp", "small", "turn", "wipe"})
    assert db.clips[0]["source"] == "/data/attention_00.bvh"
    # mirrored twins: same frames, mirrored features, other side
    tr = small_db.tracks
    assert (tr[1::2, 4] == 1).all() and (tr[1::2, 3] == 1 - tr[0::2, 3]).all()
    a, b = tr[0, :2], tr[1, :2]
    assert np.allclose(small_db.features[b[0]:b[1]], mirror_features(small_db.features[a[0]:a[1]]), atol=1e-5)
    full = small_db.full_curves(slice(a[0], a[1]))
    assert full.shape[1] == NUM_DOFS
    assert np.allclose(small_db.full_curves(slice(b[0], b[1])), mirror_curves(full), atol=1e-4)


def test_database_rejects_bad_manifest(small_db, tmp_path):
    path = save_database(small_db, tmp_path / "db")
    mf = path / "manifest.json"
    m = json.loads(mf.read_text())
    m["version"] = 3
    mf.write_text(json.dumps(m))
    with pytest.raises(ConfigError, match=r"database version 3 is not supported \(this usdhands reads 2\)$"):
        load_database(path)
    m["version"] = 1  # rotation-vector features: rebuild
    mf.write_text(json.dumps(m))
    with pytest.raises(ConfigError, match=r"database version 1 is not supported \(this usdhands reads 2\); it stores "
                                          r"rotation-vector wrist features, which wrap: rebuild it .*'usdhands db build'"):
        load_database(path)
    m["version"] = 2
    m["arrays"]["fingers"]["shape"] = [1, 2]
    mf.write_text(json.dumps(m))
    with pytest.raises(ConfigError, match=r"array 'fingers' has shape \[\d+, 45\] and dtype float32, the manifest says \[1, 2\]"):
        load_database(path)
    del m["fps"]
    mf.write_text(json.dumps(m))
    with pytest.raises(ConfigError, match=r"invalid database manifest at \(top level\): 'fps' is a required property"):
        load_database(path)
    with pytest.raises(ConfigError, match="not a finger database: manifest.json is missing"):
        load_database(tmp_path)


def test_handmap_without_fingers_gives_no_database():
    hm = HandMap(left=HandSide("left", "LeftHand"))
    with pytest.raises(ValueError, match="No clip has a hand with finger joints"):
        build_database([DatabaseClip(gesture_set(1)[0][1], hm)])


# -- grafting hands --------------------------------------------------------------------

def _fingerless(sk):
    keep = [j for j, n in enumerate(sk.short_names) if "Hand" not in n or n.endswith("Hand")]
    return sk.subset(keep)


def test_grafted_hand_rebuilds_the_database_hand_on_the_same_rig():
    from usdhands.algorithms.synthesis.hand_graft import find_wrists, graft_hands, hand_template, mirror_template

    sk, hm = tiny_skeleton(), tiny_handmap()
    bare = _fingerless(sk)
    assert {s: bare.short_names[j] for s, j in find_wrists(bare).items()} == {"left": "LeftHand", "right": "RightHand"}
    clip = Clip(bare, 30, np.broadcast_to(bare.rest_rotations, (5, bare.num_joints, 4)))
    templates = {"left": hand_template(sk, hm.left), "right": mirror_template(hand_template(sk, hm.left))}
    wrists = {s: HandSide(s, f"{s.capitalize()}Hand", f"{s.capitalize()}ForeArm", f"{s.capitalize()}Arm", "Hips")
              for s in ("left", "right")}
    out, grafted, added = graft_hands(clip, wrists, templates)
    assert len(added) == 2 * 15 and out.num_joints == bare.num_joints + 30
    assert np.array_equal(out.rotations[:, :bare.num_joints], clip.rotations)
    want = sk.rest_world_positions()
    got = out.skeleton.rest_world_positions()
    for side in ("left", "right"):
        for f in ("thumb", "index", "pinky"):
            for a, b in zip(hm[side].fingers[f], grafted[side].fingers[f]):
                assert np.allclose(got[out.skeleton.index(b)], want[sk.index(a)], atol=1e-6), (side, a)
    # twice the body size: a hand twice as far from the wrist
    big = _fingerless(tiny_skeleton(body_scale=2.0))
    clip2 = Clip(big, 30, np.broadcast_to(big.rest_rotations, (5, big.num_joints, 4)))
    out2, g2, _ = graft_hands(clip2, {"left": wrists["left"]}, templates)
    p2 = out2.skeleton.rest_world_positions()
    tip, wrist = out2.skeleton.index(g2.left.fingers["index"][-1]), out2.skeleton.index("LeftHand")
    assert np.linalg.norm(p2[tip] - p2[wrist]) == pytest.approx(2 * np.linalg.norm(want[sk.index("LeftHandIndex3")] - want[sk.index("LeftHand")]))


def test_database_keeps_hand_templates(small_db):
    assert set(small_db.hands) == {"left", "right"}
    slots = [j["slot"] for j in small_db.hands["left"]["joints"]]
    assert slots[:3] == ["thumb.d2", "thumb.d1", "thumb.d0"] and len(slots) == 15


def test_z_up_character_has_the_same_features_as_its_y_up_twin():
    from usdhands.model.rotations import matrix_to_quat

    sk, hm = tiny_skeleton(), tiny_handmap()
    clip = gesture_clip(sk, "wipe", np.random.default_rng(4))
    V = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # Y-up -> Z-up, +90 deg about X
    qv = matrix_to_quat(V)
    rest_q = np.array(sk.rest_rotations)
    rest_t = np.array(sk.rest_translations)
    rest_q[0] = quat_multiply(qv, rest_q[0])
    rest_t[0] = V @ rest_t[0]
    zsk = Skeleton(sk.joint_names, sk.parents, rest_t, rest_q, meters_per_unit=sk.meters_per_unit, up_axis="Z")
    rot, tr = np.array(clip.rotations), np.array(clip.translations)
    rot[:, 0] = quat_multiply(qv[None], rot[:, 0])
    tr[:, 0] = tr[:, 0] @ V.T
    zclip = Clip(zsk, clip.fps, rot, tr)
    assert np.allclose(zclip.world_positions()[:, 5], clip.world_positions()[:, 5] @ V.T)
    for side in ("left", "right"):
        assert np.allclose(wrist_features(zclip, hm[side]), wrist_features(clip, hm[side]), atol=1e-6)
    f, fz = arm_features(clip, hm.left), arm_features(zclip, hm.left)
    assert all(np.allclose(f[k], fz[k], atol=1e-6) for k in f)


def test_frame_rates_equal_up_to_file_rounding():
    from usdhands.algorithms.synthesis.database import same_rate

    assert same_rate(1 / 0.033333, 30.0)  # a BVH frame time of 0.033333 s
    assert not same_rate(29.97, 30.0) and not same_rate(24.0, 30.0)


def test_metacarpals_without_database_counterpart_are_reported_and_left_alone(small_db):
    from usdhands.algorithms.synthesis.synthesize import synthesize_clip

    sk, hm = tiny_skeleton(metacarpals=True), tiny_handmap(metacarpals=True)
    clip = gesture_clip(sk, "ok", np.random.default_rng(2), with_fingers=False)
    res = synthesize_clip(clip, hm, small_db)
    m = res.mapping["left"]
    assert sorted(m["no_source"]) == [f"LeftHand{f}0" for f in ("Index", "Middle", "Pinky", "Ring")]
    assert len(m["mapped"]) == 15 and m["dropped"] == []
    assert dict(m["mapped"])["LeftHandIndex1"] == "index.d2"
    meta = [sk.index(f"{s}Hand{f}0") for s in ("Left", "Right") for f in ("Index", "Middle", "Ring", "Pinky")]
    assert np.array_equal(res.clip.rotations[:, meta], clip.rotations[:, meta])
    moved = [sk.index(j) for j in hm.left.finger_joints if not j.endswith("0")]
    assert np.ptp(res.clip.rotations[:, moved], axis=0).max() > 0.05


def test_saving_over_a_database_replaces_it_and_refuses_other_folders(small_db, tmp_path):
    path = save_database(small_db, tmp_path / "db")
    (tmp_path / ".db.old").mkdir()  # the name older versions moved the database to: may be a user's folder
    (tmp_path / ".db.old" / "x").write_text("x")
    save_database(small_db, path)
    assert sorted(f.name for f in path.iterdir()) == ["features.npy", "fingers.npy", "manifest.json",
                                                      "segments.npy", "tracks.npy"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [".db.old", "db"]  # left alone, nothing else left
    assert (tmp_path / ".db.old" / "x").read_text() == "x"
    other = tmp_path / "notes"
    other.mkdir()
    (other / "a.txt").write_text("keep")
    with pytest.raises(ConfigError, match="is a non-empty folder that is not a finger database; refusing to overwrite"):
        save_database(small_db, other)
    assert (other / "a.txt").read_text() == "keep"

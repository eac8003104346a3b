"""Collision correction: built cases with known penetration, the 0.5 mm guarantee measured with
trimesh independently of the fast path, touching not floating, joint limits, smoothing, and
fingers that are clear left bit-for-bit alone."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from interaction_data import (
    closing_hand_clip, colliders_for, cup_against_tip, curled_index_clip, cylinder_under_palm,
    exact_capsule_depth_mm, exact_capsule_gaps_mm,
)

from usdhands.algorithms.interaction.correction import chain_posers, correct_clip, penetration_depth_mm
from usdhands.algorithms.interaction.finger_geometry import InteractionConfig
from usdhands.algorithms.interaction.smoothing import bounded_smooth, rts_smooth, smoothness_weight
from usdhands.model.finger_dofs import finger_curves
from usdhands.model.prop import PropMesh
from usdhands.model.rotations import quat_angle_deg
from usdhands.samples.humanoid import humanoid_handmap

MUG = Path(__file__).resolve().parent.parent.parent / "shared" / "assets" / "mujoco_mug" / "mug.obj"


@pytest.fixture(scope="module")
def closing():
    clip = closing_hand_clip(frames=30, noise_deg=1.5)
    prop = cylinder_under_palm()
    hm = humanoid_handmap(clip.skeleton)
    cols = colliders_for(clip, prop)
    out, report = correct_clip(clip, hm, cols)
    gaps_before = exact_capsule_gaps_mm(clip, [prop], chain_posers(clip, hm, InteractionConfig()))
    gaps_after = exact_capsule_gaps_mm(out, [prop], chain_posers(out, hm, InteractionConfig()))
    return clip, prop, hm, cols, out, report, gaps_before, gaps_after


def _depth(gaps: np.ndarray) -> np.ndarray:
    return np.nan_to_num(np.maximum(-gaps, 0.0)).max(axis=0)


def test_cylinder_penetration_removed_to_half_a_millimetre_by_exact_measure(closing):
    clip, prop, hm, cols, out, report, gaps_before, gaps_after = closing
    before, after = _depth(gaps_before), _depth(gaps_after)
    assert before.max() > 15.0  # the fingers curl deep into the cylinder
    assert after.max() <= 0.5
    # the report's fast measure agrees with trimesh's within its resolution
    assert np.all(report.penetration_before_mm >= before - 1e-6) and np.all(report.penetration_before_mm <= before + 0.06)
    assert report.penetration_after_mm.max() <= 0.5
    d = report.to_dict()
    assert set(d) == {"penetration_before_mm", "penetration_after_mm", "frames_corrected", "jitter_before",
                      "jitter_after", "max_change_deg"}
    assert set(d["penetration_before_mm"]) == {"max", "mean", "frames"}
    assert d["frames_corrected"] > 0 and d["max_change_deg"] > 10


def test_penetrating_fingers_end_touching_not_floating(closing):
    clip, prop, hm, cols, out, report, gaps_before, gaps_after = closing
    before, after = gaps_before, gaps_after
    hit = before < 0
    assert hit.sum() > 40
    assert np.all(after[hit] >= -0.5) and np.all(after[hit] <= 2.0)


def test_joint_limits_never_exceeded(closing):
    clip, prop, hm, cols, out, report, gaps_before, gaps_after = closing
    for poser in chain_posers(out, hm, InteractionConfig()):
        js = list(poser.chain.joints)
        changed = np.any(out.rotations[:, js] != clip.rotations[:, js], axis=(1, 2))
        if not changed.any():
            continue
        e = finger_curves(out, js).values.reshape(out.num_frames, len(js), 3)[changed]
        e = (e + 180.0) % 360.0 - 180.0
        assert np.all(e >= poser.chain.limits[..., 0] - 1e-6) and np.all(e <= poser.chain.limits[..., 1] + 1e-6)


def test_smoothing_lowers_jitter_without_penetrating(closing):
    clip, prop, hm, cols, out, report, gaps_before, gaps_after = closing
    rough, rough_report = correct_clip(clip, hm, cols, smooth=False)
    assert report.jitter_after < rough_report.jitter_after
    assert report.jitter_after < report.jitter_before  # smoother than the noisy input, too
    assert _depth(gaps_after).max() <= 0.5
    assert exact_capsule_depth_mm(rough, [prop], chain_posers(rough, hm, InteractionConfig())).max() <= 0.5


def test_smoother_than_a_clean_input_too_and_clear_by_exact_measure():
    """Without capture noise the input is as smooth as it gets, and the correction still ends smoother
    (the whole curve of each corrected finger is smoothed, the contact as a bound)."""
    clip = closing_hand_clip(frames=60, noise_deg=0.0)
    prop = cylinder_under_palm()
    hm = humanoid_handmap(clip.skeleton)
    out, report = correct_clip(clip, hm, colliders_for(clip, prop))
    assert report.chains_corrected and report.jitter_after < report.jitter_before
    assert exact_capsule_depth_mm(clip, [prop], chain_posers(clip, hm, InteractionConfig())).max() > 15.0
    assert exact_capsule_depth_mm(out, [prop], chain_posers(out, hm, InteractionConfig())).max() <= 0.5


def test_the_whole_curve_of_a_corrected_finger_is_smoothed():
    """Frames far from any contact are smoothed too (the capture noise there goes), while the
    fingers that never touched keep their noise bit for bit."""
    clip = closing_hand_clip(frames=60, noise_deg=1.5)
    cyl = cylinder_under_palm()
    low = PropMesh("low", np.asarray(cyl.vertices) - [0.0, 1.5, 0.0], cyl.faces)  # touched only when well curled
    hm = humanoid_handmap(clip.skeleton)
    out, report = correct_clip(clip, hm, colliders_for(clip, low))
    posers = chain_posers(clip, hm, InteractionConfig())
    gaps = exact_capsule_gaps_mm(clip, [low], posers)
    i = [p.chain.name for p in posers].index("left index")
    assert "left index" in report.chains_corrected and gaps[i].min() < -5.0
    calm = np.nonzero(gaps[i] > 5.0)[0]  # the index well clear of the cylinder (the hand open)
    calm = calm[(calm > 1) & (calm < clip.num_frames - 2)]
    assert len(calm) >= 6
    index = list(posers[i].chain.joints)
    before = np.abs(np.diff(finger_curves(clip, index).values, 2, axis=0))[calm - 1].mean()
    after = np.abs(np.diff(finger_curves(out, index).values, 2, axis=0))[calm - 1].mean()
    assert after < 0.5 * before
    thumb = list(posers[[p.chain.name for p in posers].index("left thumb")].chain.joints)
    assert "left thumb" not in report.chains_corrected
    assert out.rotations[:, thumb].tobytes() == clip.rotations[:, thumb].tobytes()


def test_clear_fingers_are_bit_for_bit_unchanged(closing):
    clip, prop, hm, cols, out, report, gaps_before, gaps_after = closing
    untouched = [j for p in chain_posers(clip, hm, InteractionConfig()) if p.chain.name not in report.chains_corrected
                 for j in p.chain.joints]
    assert "left thumb" not in report.chains_corrected and untouched
    assert out.rotations[:, untouched].tobytes() == clip.rotations[:, untouched].tobytes()
    body = [j for j in range(clip.num_joints) if j not in {j for p in chain_posers(clip, hm, InteractionConfig())
                                                           for j in p.chain.joints}]
    assert out.rotations[:, body].tobytes() == clip.rotations[:, body].tobytes()


def test_a_far_prop_changes_nothing():
    clip = closing_hand_clip(frames=20)
    far = cylinder_under_palm()
    far = PropMesh("far", np.asarray(far.vertices) + [0.0, 0.0, 100.0], far.faces)  # a metre to the side
    out, report = correct_clip(clip, humanoid_handmap(clip.skeleton), colliders_for(clip, far))
    assert out.rotations.tobytes() == clip.rotations.tobytes()
    assert report.frames_corrected == 0 and report.penetration_before_mm.max() == 0.0


def test_sample_cup_with_a_known_penetration():
    clip = curled_index_clip()
    hm = humanoid_handmap(clip.skeleton)
    posers = chain_posers(clip, hm, InteractionConfig())
    index = next(p for p in posers if p.chain.name == "left index")
    angles = finger_curves(clip, index.chain.joints).values.reshape(clip.num_frames, 3, 3)
    _, b = index.capsules(np.array([0]), angles[:1])
    cup = cup_against_tip(b[0, -1], 0.4, index.chain.radii[-1])  # the tip 4 mm into the wall
    cols = colliders_for(clip, cup)
    assert exact_capsule_depth_mm(clip, [cup], posers)[0] == pytest.approx(4.0, abs=1e-6)
    assert 4.0 <= penetration_depth_mm(clip, posers, cols)[0] <= 4.05  # an upper bound within its resolution
    out, report = correct_clip(clip, hm, cols)
    assert report.chains_corrected == ["left index"]
    gaps = exact_capsule_gaps_mm(out, [cup], chain_posers(out, hm, InteractionConfig()))
    i = [p.chain.name for p in posers].index("left index")
    assert np.all(gaps[i] >= -0.5) and np.all(gaps[i] <= 2.0)


def test_margin_keeps_the_fingers_that_far_away(closing):
    clip, prop, hm, cols, out, report, gaps_before, gaps_after = closing
    kept, kept_report = correct_clip(clip, hm, cols, margin_mm=3.0)
    posers = chain_posers(kept, hm, InteractionConfig())
    gaps = exact_capsule_gaps_mm(kept, [prop], posers)
    names = [p.chain.name for p in posers]
    # the pinky, lower on the hand, passes 1.2 mm over the cylinder even straight: it cannot open further
    stuck = {(names.index(c), f) for c, f in kept_report.unresolved}
    assert {names[c] for c, _ in stuck} == {"left pinky"}
    free = np.ones(gaps.shape, dtype=bool)
    for c, f in stuck:
        free[c, f] = False
    assert np.nanmin(gaps[free]) >= 3.0 - 0.5
    assert np.nanmin(gaps[~free]) > 0.0  # unresolved within the margin, still not penetrating


def test_every_other_frame_bisected_the_frames_between_tried_at_their_neighbours_larger_bound():
    """least_opening(every=2), as the correction runs it: the even frames (and frames with no failing even
    neighbour) are bisected as before, bit for bit; an odd frame takes the larger bound of its neighbours
    where that pose is clear, else a bisection above it; every bound found is tested clear; fewer exact
    queries than bisecting every frame."""
    from usdhands.algorithms.interaction.correction import finger_angles

    clip = closing_hand_clip(frames=30, noise_deg=1.5)
    prop = cylinder_under_palm()
    hm = humanoid_handmap(clip.skeleton)
    mm = 0.001 / clip.skeleton.meters_per_unit
    res = 0.5 * mm
    tried = 0
    for poser in chain_posers(clip, hm, InteractionConfig()):
        frames = np.arange(clip.num_frames)
        base = finger_angles(clip, poser.chain.joints)
        cols = colliders_for(clip, prop)
        full, full_ok = poser.least_opening(cols, frames, base, 0.0, res)
        full_queries = sum(c.exact_queries for c in cols.items)
        cols = colliders_for(clip, prop)
        sparse, ok = poser.least_opening(cols, frames, base, 0.0, res, every=2)
        sparse_queries = sum(c.exact_queries for c in cols.items)
        np.testing.assert_array_equal(ok, full_ok)
        fail = np.nonzero(full > 0)[0]
        np.testing.assert_array_equal(np.nonzero(sparse > 0)[0], fail)
        if len(fail) < 4:
            continue
        assert sparse_queries < full_queries
        assert poser.clear(cols, fail, poser.angles(base[fail], sparse[fail]), 0.0, res).all()
        anchored = {f for f in fail if f % 2 == 0 or not ({f - 1, f + 1} & set(fail[fail % 2 == 0]))}
        for f in fail:
            if f in anchored:
                assert sparse[f] == full[f]
                continue
            cand = max(full[g] for g in (f - 1, f + 1) if g in anchored and g % 2 == 0 and g in set(fail))
            if poser.clear(cols, [f], poser.angles(base[[f]], np.array([cand])), 0.0, res)[0]:
                assert sparse[f] == cand
                tried += 1
            else:
                assert cand < sparse[f] <= 1.0
    assert tried > 10


def test_bounded_smoother_never_dips_below_its_bound_and_is_smoother():
    rng = np.random.default_rng(0)
    lower = np.zeros(400)
    lower[100:160] = 0.4 + 0.1 * rng.normal(size=60)
    lower = np.clip(lower, 0.0, 1.0)
    x = bounded_smooth(lower, np.ones(400), smoothness_weight(30.0, 0.1))
    assert np.all(x >= lower) and np.all(x <= 1.0)
    assert np.abs(np.diff(x, 2)).mean() < 0.2 * np.abs(np.diff(lower, 2)).mean()
    assert np.all(x[:60] < 1e-6) and np.all(x[-60:] < 1e-6)  # nothing far from the bound's bump


@pytest.mark.parametrize("T", [50, 400])
def test_rts_smoother_matches_a_per_curve_kalman_loop(T):
    """400 frames: the gains settle and both passes run as second-order recursions (lfilter)."""
    rng = np.random.default_rng(1)
    z = np.cumsum(rng.normal(size=(T, 3)), axis=0) + rng.normal(size=(T, 3))
    fast = rts_smooth(z, 30.0, 0.2)
    # the textbook filter and RTS pass, one curve at a time
    dt = 1 / 30.0
    F = np.array([[1, dt], [0, 1.0]])
    Q = 0.2 ** -4 * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
    H = np.array([[1.0, 0.0]])
    for c in range(3):
        xs, Ps, xp, Pp = [], [], [], []
        x = np.array([z[0, c], 0.0])
        P = np.diag([1.0, 1e6])
        for t in range(T):
            if t:
                x, P = F @ x, F @ P @ F.T + Q
            xp.append(x)
            Pp.append(P)
            K = P @ H.T / (H @ P @ H.T + 1.0)
            x = x + (K * (z[t, c] - H @ x)).ravel()
            P = (np.eye(2) - K @ H) @ P
            xs.append(x)
            Ps.append(P)
        out = [xs[-1]]
        for t in range(T - 2, -1, -1):
            G = Ps[t] @ F.T @ np.linalg.inv(Pp[t + 1])
            out.insert(0, xs[t] + G @ (out[0] - xp[t + 1]))
        np.testing.assert_allclose(fast[:, c], np.array(out)[:, 0], rtol=0, atol=1e-8 * (1 + np.abs(z).max()))


def test_second_order_recursion_equals_lfilter_to_the_bit():
    """The recursion behind the RTS smoother's steady stretch, compiled (numba's, and ahead of time where it
    was built) and in NumPy steps, is scipy's lfilter, bit for bit (signed zeros, coefficients of the
    smoother and arbitrary ones, one column and many)."""
    from scipy.signal import lfilter

    from usdhands.algorithms.interaction._recursion_kernel import second_order
    from usdhands.algorithms.interaction.smoothing import second_order_steps
    from usdhands.compiled import kernel_module

    built = kernel_module("algorithms.interaction._interaction_compiled")

    rng = np.random.default_rng(7)
    for n, C, a1, a2 in [(1801, 9, -1.8737, 0.8812), (5, 1, 0.3, -0.2), (400, 3, -1.999999, 0.9999991),
                         (64, 4, rng.normal(), rng.normal())]:
        x = rng.normal(scale=50.0, size=(n, C))
        x[::7] = 0.0
        x[1::11] = -0.0
        zi = rng.normal(size=(2, C))
        expected = lfilter([1.0], np.array([1.0, a1, a2]), x, axis=0, zi=zi)[0]
        assert second_order(x, a1, a2, zi).tobytes() == expected.tobytes()
        assert second_order_steps(x, a1, a2, zi).tobytes() == expected.tobytes()
        if built is not None:
            assert built.second_order(x, a1, a2, zi).tobytes() == expected.tobytes()


def test_rts_smoother_on_many_curves_gives_each_its_own_answer_to_the_bit():
    """The correction smooths every corrected chain's curves in one call: each column comes out as alone."""
    rng = np.random.default_rng(5)
    z = np.cumsum(rng.normal(size=(900, 12)), axis=0)
    together = rts_smooth(z, 30.0, 0.15)
    for cols in (slice(0, 9), slice(9, 12), slice(4, 5)):
        assert together[:, cols].tobytes() == rts_smooth(np.ascontiguousarray(z[:, cols]), 30.0, 0.15).tobytes()


def test_principal_bands_are_the_sparse_submatrix_s():
    """The bounded smoother's banded solves take the principal submatrix's bands gathered from the
    pentadiagonal matrix's diagonals: equal to slicing the sparse matrix, so the solves are unchanged."""
    from scipy import sparse

    from usdhands.algorithms.interaction.smoothing import _principal_bands

    rng = np.random.default_rng(9)
    for T in (3, 4, 7, 60):
        D = sparse.diags([np.ones(T - 2), -2 * np.ones(T - 2), np.ones(T - 2)], [0, 1, 2], shape=(T - 2, T))
        H = (sparse.diags(rng.uniform(1.0, 10.0, T), format="csr") + 1234.5 * (D.T @ D)).tocsr()
        bands = (H.diagonal(0), H.diagonal(1), H.diagonal(2))
        for _ in range(20):
            idx = np.nonzero(rng.random(T) < rng.uniform(0.2, 1.0))[0]
            if len(idx) == 0:
                continue
            sub = H[idx][:, idx]
            expected = np.zeros((3, len(idx)))
            expected[2] = sub.diagonal(0)
            if len(idx) > 1:
                expected[1, 1:] = sub.diagonal(1)
            if len(idx) > 2:
                expected[0, 2:] = sub.diagonal(2)
            assert _principal_bands(bands, idx).tobytes() == expected.tobytes()


def test_rts_smoother_needs_no_scipy_signal():
    """A correction's smoothing imports neither scipy.signal nor numba (each about 0.3 s of a fresh process)."""
    code = ("import sys, numpy as np\n"
            "from usdhands.algorithms.interaction.smoothing import rts_smooth\n"
            "rts_smooth(np.cumsum(np.ones((400, 3)), axis=0), 30.0, 0.2)\n"
            "print('scipy.signal' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)})
    assert out.stdout.strip() == "False False"


def test_ccd_turns_the_distal_joint_first_by_the_least_flexion_that_clears():
    """The curled index's tip 4 mm into the cup wall: CCD turns only the distal joint, only about its
    flexion axis, toward extension, within its limits, and no further than clears it (within 2 mm)."""
    clip = curled_index_clip()
    hm = humanoid_handmap(clip.skeleton)
    index = next(p for p in chain_posers(clip, hm, InteractionConfig()) if p.chain.name == "left index")
    angles = finger_curves(clip, index.chain.joints).values.reshape(clip.num_frames, 3, 3)
    _, b = index.capsules(np.array([0]), angles[:1])
    cup = cup_against_tip(b[0, -1], 0.4, index.chain.radii[-1])
    cols = colliders_for(clip, cup)
    frames = np.arange(clip.num_frames)
    mm = 0.1  # cm
    pose, done = index.ccd(cols, frames, angles, 0.0, 0.5 * mm)
    assert done.all() and index.clear(cols, frames, pose, 0.0, 0.5 * mm).all()
    moved = pose != angles
    flex = index.chain.axes[2, 0]
    assert moved[:, :2].sum() == 0 and moved[:, 2].sum() == moved[:, 2, flex].sum() == clip.num_frames
    extension = index.chain.flexion_sign[2] * (pose[:, 2, flex] - angles[:, 2, flex])
    assert np.all(extension < 0)  # toward extension
    assert np.all(pose >= index.chain.limits[..., 0]) and np.all(pose <= index.chain.limits[..., 1])
    rotations = np.array(clip.rotations)
    rotations[:, list(index.chain.joints)] = index.local_rotations(pose)
    out = clip.replace(rotations=rotations)
    i = [p.chain.name for p in chain_posers(clip, hm, InteractionConfig())].index("left index")
    gaps = exact_capsule_gaps_mm(out, [cup], chain_posers(out, hm, InteractionConfig()))[i]
    assert np.all(gaps >= -0.5) and np.all(gaps <= 2.0)


def test_ccd_correction_keeps_the_guarantee_and_changes_less_than_opening(closing):
    """``ik: ccd`` (least change) within the limits and the 0.5 mm guarantee, smoother than the noisy
    input, changing the fingers less on average than the default opening path."""
    clip, prop, hm, cols, out, report, gaps_before, gaps_after = closing
    cfg = InteractionConfig(ik="ccd")
    fixed, ccd_report = correct_clip(clip, hm, cols, config=cfg)
    posers = chain_posers(fixed, hm, cfg)
    gaps = exact_capsule_gaps_mm(fixed, [prop], posers)
    assert _depth(gaps).max() <= 0.5 and not ccd_report.unresolved
    for poser in posers:
        e = finger_curves(fixed, list(poser.chain.joints)).values.reshape(fixed.num_frames, -1, 3)
        e = (e + 180.0) % 360.0 - 180.0
        assert np.all(e >= poser.chain.limits[..., 0] - 1e-6) and np.all(e <= poser.chain.limits[..., 1] + 1e-6)
    touched = [j for p in posers if p.chain.name in ccd_report.chains_corrected for j in p.chain.joints]
    change = quat_angle_deg(clip.rotations[:, touched], fixed.rotations[:, touched]).mean()
    opening_change = quat_angle_deg(clip.rotations[:, touched], out.rotations[:, touched]).mean()
    assert change < opening_change
    assert ccd_report.jitter_after < ccd_report.jitter_before


def test_bounded_smoother_between_two_bounds_matches_a_general_solver():
    """The active-set solve on both bounds, with per-frame fit weights and a target, against
    scipy's bounded least squares on the same problem (small enough for the general solver)."""
    from scipy.optimize import lsq_linear

    rng = np.random.default_rng(3)
    T = 80
    lower = np.clip(np.convolve(rng.normal(size=T), np.ones(5) / 5, mode="same"), 0.0, None)
    upper = lower + np.where(rng.random(T) < 0.2, 0.01, 1.0)  # some frames barely above their floor
    target = lower + 0.3 * rng.random(T)
    fit = np.where(lower > 0, 10.0, 1.0)
    weight = smoothness_weight(30.0, 0.15)
    x = bounded_smooth(lower, upper, weight, fit=fit, target=target)
    assert np.all(x >= lower) and np.all(x <= upper)
    D = np.diff(np.eye(T), 2, axis=0)
    A = np.vstack([np.sqrt(fit)[:, None] * np.eye(T), np.sqrt(weight) * D])
    b = np.concatenate([np.sqrt(fit) * target, np.zeros(T - 2)])
    ref = lsq_linear(A, b, bounds=(lower, upper), tol=1e-12, max_iter=10000).x
    np.testing.assert_allclose(x, ref, atol=1e-6)


@pytest.mark.skipif(not MUG.exists(), reason="shared assets not present")
def test_correction_of_a_clip_differing_in_its_fingers_reuses_the_inputs_world_transforms():
    """synthesize --props hands the input's world transforms to the correction of the result: only the
    fingers are posed again, and the correction and its report are those of full forward kinematics."""
    from interaction_data import grasping_clip, grasping_mug_position

    from usdhands.algorithms.interaction.correction import with_fingers_posed
    from usdhands.formats.props import read_props

    source = grasping_clip(4.0)
    hm = humanoid_handmap(source.skeleton)
    fingers = [source.skeleton.index(j) for h in hm.sides for j in h.finger_joints]
    rotations = np.array(source.rotations)
    rotations[:, fingers] = np.roll(rotations[:, fingers], 9, axis=0)  # other fingers, the same body
    clip = source.replace(rotations=rotations)
    world = source.world_xforms()
    np.testing.assert_array_equal(with_fingers_posed(clip, hm, world), clip.world_xforms())
    (mug,) = read_props(MUG, meters_per_unit=0.01, up_axis="Y", prop_meters_per_unit=0.01)
    cols = colliders_for(clip, PropMesh(mug.name, np.asarray(mug.vertices) + grasping_mug_position(), mug.faces))
    out, report = correct_clip(clip, hm, cols)
    reused, reused_report = correct_clip(clip, hm, cols, world=world)
    assert report.chains_corrected and report.to_dict()["penetration_before_mm"]["max"] > 1.0
    np.testing.assert_array_equal(reused.rotations, out.rotations)
    assert reused_report.to_dict() == report.to_dict()


def _with_roll_joint(flat: bool = False):
    """The humanoid with a roll joint between the left index's first two joints (twisted 25 degrees
    at rest, animated), or with the second joint moved under the hand (``flat``); the index curls."""
    from scipy.spatial.transform import Rotation

    from usdhands.model.clip import Clip
    from usdhands.model.rotations import quat_conjugate, quat_multiply
    from usdhands.model.skeleton import Skeleton
    from usdhands.samples.humanoid import humanoid_skeleton

    def quat_from_axis_angle(axis, radians):
        return Rotation.from_rotvec(np.multiply.outer(np.atleast_1d(radians), axis)).as_quat().reshape(
            np.shape(radians) + (4,))

    sk = humanoid_skeleton()
    i1, i2 = sk.index("LeftHandIndex1"), sk.index("LeftHandIndex2")
    names, parents = list(sk.joint_names), list(sk.parents)
    tr, rot = np.array(sk.rest_translations), np.array(sk.rest_rotations)
    bone = tr[i2] / 2
    roll = quat_from_axis_angle(bone / np.linalg.norm(bone), np.radians(25.0))
    # insert the roll after Index1; Index2 (and below) shift by one
    names.insert(i1 + 1, names[i1] + "/Roll")
    parents = [p + (p > i1) for p in parents]
    parents.insert(i1 + 1, i1)
    tr = np.insert(tr, i1 + 1, bone, axis=0)
    rot = np.insert(rot, i1 + 1, roll, axis=0)
    j2 = i2 + 1
    parents[j2] = i1 + 1
    tr[j2] = bone
    rot[j2] = quat_multiply(quat_conjugate(roll), rot[j2])  # the same rest pose below the roll
    tr[j2] = Rotation.from_quat(quat_conjugate(roll)).apply(bone)
    if flat:
        parents[j2] = sk.index("LeftHand")
    skel = Skeleton(tuple(names), np.array(parents), tr, rot, meters_per_unit=sk.meters_per_unit, up_axis="Y")
    T = 8
    rotations = np.tile(skel.rest_rotations, (T, 1, 1))
    twist = quat_from_axis_angle(bone / np.linalg.norm(bone), np.radians(np.linspace(0.0, 40.0, T)))
    rotations[:, i1 + 1] = quat_multiply(twist, roll)
    curl = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(-np.linspace(10.0, 60.0, T)))
    for j in (i1, j2, j2 + 1):
        rotations[:, j] = quat_multiply(rotations[:, j], curl)
    clip = Clip(skel, 30.0, rotations, name="roll")
    return clip, humanoid_handmap(skel)


def test_a_roll_joint_between_finger_joints_is_carried_along():
    """The capsules the correction poses from the finger's angles end where the clip's forward
    kinematics puts the joints, with an animated roll joint between two of them."""
    from usdhands.algorithms.interaction.correction import finger_angles

    clip, hm = _with_roll_joint()
    world = clip.world_positions()
    index = next(p for p in chain_posers(clip, hm, InteractionConfig()) if p.chain.name == "left index")
    assert index.between is not None
    frames = np.arange(clip.num_frames)
    a, b = index.capsules(frames, finger_angles(clip, index.chain.joints))
    np.testing.assert_allclose(a, world[:, list(index.chain.joints)], atol=1e-9)
    np.testing.assert_allclose(b[:, :-1], world[:, list(index.chain.joints[1:])], atol=1e-9)


def test_finger_joints_that_are_not_a_chain_are_refused():
    from usdhands.errors import UnsupportedRigError

    clip, hm = _with_roll_joint(flat=True)
    with pytest.raises(UnsupportedRigError, match="left index finger's joints are not a chain: '.*LeftHandIndex2'"):
        correct_clip(clip, hm, colliders_for(clip, cylinder_under_palm()))


def test_fingers_posed_where_asked_and_the_reach_that_bounds_every_pose():
    """correct_clip poses a chain's joints only at the frames where some pose of it can reach a collider
    (posing.FingersPosed, chain_reach): rows equal full forward kinematics bit for bit at any frames, and
    every joint and tip of every pose lies within the reach of the chain's parent joint, scaled and
    animated translations included (a reach from the rest bones alone fails it)."""
    from interaction_data import grasping_clip

    from usdhands.algorithms.interaction.correction import _given_points, _poser
    from usdhands.algorithms.interaction.finger_geometry import finger_chains
    from usdhands.algorithms.interaction.posing import FingersPosed, chain_reach

    source = grasping_clip(2.0)
    hm = humanoid_handmap(source.skeleton)
    rng = np.random.default_rng(5)
    fingers = [source.skeleton.index(j) for h in hm.sides for j in h.finger_joints]
    rotations = np.array(source.rotations)
    rotations[:, fingers] = np.roll(rotations[:, fingers], 7, axis=0)
    translations = np.array(source.translations)
    translations[:, fingers] *= rng.uniform(0.8, 1.6, size=(source.num_frames, len(fingers), 1))
    scales = np.array(source.scales)
    scales[:, fingers] = rng.uniform(0.7, 1.5, size=(source.num_frames, len(fingers), 3))
    clip = source.replace(rotations=rotations, translations=translations, scales=scales)
    full = clip.world_xforms()
    posed = FingersPosed(clip, hm, source.world_xforms())
    frames = np.sort(rng.choice(clip.num_frames, size=17, replace=False))
    for j, w in zip(fingers, posed.at(fingers, frames)):
        assert w.tobytes() == np.ascontiguousarray(full[frames, j]).tobytes()
    for hand in hm.sides:
        for chain in finger_chains(clip.skeleton, hand):
            poser = _poser(clip, chain, posed, given=False)
            reach = chain_reach(clip, chain.joints, chain.tip_offset, poser.parent_world)
            for _ in range(3):  # the pose given and random ones
                pts = _given_points(chain, posed)
                far = np.linalg.norm(pts - poser.parent_world[:, None, :3, 3], axis=2).max(axis=1)
                assert np.all(far <= reach * (1 + 1e-12))
                angles = rng.uniform(-170, 170, size=(clip.num_frames, len(chain.joints), 3))
                a, b = poser.capsules(np.arange(clip.num_frames), angles)
                far = np.linalg.norm(np.concatenate([a, b[:, -1:]], axis=1) - poser.parent_world[:, None, :3, 3],
                                     axis=2).max(axis=1)
                assert np.all(far <= reach * (1 + 1e-12))
            rest = np.linalg.norm(clip.skeleton.rest_translations[list(chain.joints)], axis=1).sum() + \
                np.linalg.norm(chain.tip_offset)
            assert far.max() > rest  # the scaled bones reach farther than the rest ones

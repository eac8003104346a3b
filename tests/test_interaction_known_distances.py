"""Reusing measured distances (known_distances.ChainDistances): the same answers, bit for bit, as
measuring everything again, with fewer exact queries."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from interaction_data import (
    closing_hand_clip,
    colliders_for,
    cylinder_under_palm,
    grasping_clip,
    grasping_mug_position,
)

import usdhands.algorithms.interaction.correction as correction
from usdhands.algorithms.interaction.correction import chain_posers, correct_clip, finger_angles
from usdhands.algorithms.interaction.finger_geometry import InteractionConfig
from usdhands.algorithms.interaction.known_distances import ChainDistances
from usdhands.formats.props import read_props
from usdhands.model.prop import PropMesh
from usdhands.samples.humanoid import humanoid_handmap

ASSETS = Path(__file__).resolve().parent.parent.parent / "shared" / "assets"
MUG = ASSETS / "mujoco_mug" / "mug.obj"
TEAPOT = ASSETS / "usd_teapot" / "UtahTeapot.usd"


def _cylinder():
    clip = closing_hand_clip(frames=30, noise_deg=1.5)
    return clip, cylinder_under_palm()


def _mug():
    clip = grasping_clip(8.0)
    (mug,) = read_props(MUG, meters_per_unit=clip.skeleton.meters_per_unit, up_axis="Y", prop_meters_per_unit=0.01)
    return clip, PropMesh("mug", np.asarray(mug.vertices) + grasping_mug_position(), mug.faces)


def _teapot():
    """The teapot (metres, open edges) under the sweeping left hand, its top 1 cm below the mug's rim."""
    clip = grasping_clip(8.0)
    (pot,) = read_props(TEAPOT, meters_per_unit=clip.skeleton.meters_per_unit, up_axis="Y")
    v = np.asarray(pot.vertices)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    top = grasping_mug_position() + [0.0, 6.2, 0.0]
    return clip, PropMesh("teapot", v - [centre[0], v[:, 1].max(), centre[2]] + top, pot.faces)


CASES = {"cylinder": _cylinder, "mug": _mug, "teapot": _teapot}


def _queries(cols) -> int:
    return sum(c.exact_queries for c in cols.items)


@pytest.mark.parametrize("ik", ["opening", "ccd"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_correction_with_reused_distances_equals_measuring_everything(case, ik, monkeypatch):
    if case != "cylinder" and not MUG.exists():
        pytest.skip("shared assets not present")
    clip, prop = CASES[case]()
    hm = humanoid_handmap(clip.skeleton)
    cfg = InteractionConfig(ik=ik)
    cols = colliders_for(clip, prop)
    out, report = correct_clip(clip, hm, cols, config=cfg)
    reused = _queries(cols)
    # the twin: nothing is remembered, every test measures all it needs (the code before the memo)
    monkeypatch.setattr(correction, "ChainDistances", lambda rows, joints: None)
    cols = colliders_for(clip, prop)
    twin, twin_report = correct_clip(clip, hm, cols, config=cfg)
    exact = _queries(cols)
    assert report.chains_corrected and report.penetration_before_mm.max() > 1.0  # the case corrects something
    np.testing.assert_array_equal(out.rotations, twin.rotations)
    np.testing.assert_array_equal(report.penetration_before_mm, twin_report.penetration_before_mm)
    np.testing.assert_array_equal(report.penetration_after_mm, twin_report.penetration_after_mm)
    assert report.to_dict() == twin_report.to_dict()
    assert report.unresolved == twin_report.unresolved
    assert reused < exact


def test_candidates_sharing_a_frame_keep_their_own_rows():
    """Many poses at the same frame (candidates, as the collision term has them), one memo row each:
    the bisection with the memo equals the one without; a memo keyed by frame (rows shared) too."""
    clip, prop = _cylinder()
    hm = humanoid_handmap(clip.skeleton)
    cols = colliders_for(clip, prop)
    mm = 0.001 / clip.skeleton.meters_per_unit
    rng = np.random.default_rng(3)
    for poser in chain_posers(clip, hm, InteractionConfig()):
        angles = finger_angles(clip, poser.chain.joints)
        frames = np.repeat(np.arange(10, 30, 2), 6)  # 6 candidates per frame
        base = angles[frames] + rng.normal(scale=15.0, size=(len(frames),) + angles.shape[1:])
        exact, exact_ok = poser.least_opening(cols, frames, base, 0.0, 0.5 * mm)
        rows = np.arange(len(frames))
        known = ChainDistances(len(frames), len(poser.chain.joints) + 1)
        u, ok = poser.least_opening(cols, frames, base, 0.0, 0.5 * mm, known=known, rows=rows)
        np.testing.assert_array_equal(u, exact)
        np.testing.assert_array_equal(ok, exact_ok)
        shared = ChainDistances(clip.num_frames, len(poser.chain.joints) + 1)
        u, ok = poser.least_opening(cols, frames, base, 0.0, 0.5 * mm, known=shared)  # rows: the frames
        np.testing.assert_array_equal(u, exact)
        np.testing.assert_array_equal(ok, exact_ok)


@pytest.mark.parametrize("case", ["cylinder", "mug"])
def test_bisections_of_many_chains_in_step_equal_each_alone(case):
    """The collision term opens every chain's candidates together (ik.least_openings: one query per step
    for all chains): each chain's openings and resolved frames are those of its own bisection, with fewer
    queries (a joint the path has not moved, and a chain's base at a frame several candidates share, is
    measured once)."""
    from usdhands.algorithms.interaction.ik import least_openings

    if case != "cylinder" and not MUG.exists():
        pytest.skip("shared assets not present")
    clip, prop = CASES[case]()
    hm = humanoid_handmap(clip.skeleton)
    mm = 0.001 / clip.skeleton.meters_per_unit
    rng = np.random.default_rng(11)
    posers = chain_posers(clip, hm, InteractionConfig())
    frames, bases = [], []
    for k, poser in enumerate(posers):
        angles = finger_angles(clip, poser.chain.joints)
        f = np.sort(rng.choice(clip.num_frames, size=0 if k == 3 else 40))  # one chain with no frames
        frames.append(f)
        bases.append(angles[f] + rng.normal(scale=20.0, size=(len(f),) + angles.shape[1:]))
    cols = colliders_for(clip, prop)
    alone = [p.least_opening(cols, f, b, 0.3 * mm, 2.0 * mm, iterations=5) for p, f, b in zip(posers, frames, bases)]
    queries = _queries(cols)
    cols = colliders_for(clip, prop)
    together = least_openings(posers, cols, frames, bases, 0.3 * mm, 2.0 * mm, iterations=5)
    assert _queries(cols) < queries and any((u > 0).any() for u, _ in alone)
    for (u, ok), (u2, ok2) in zip(alone, together):
        assert u.tobytes() == u2.tobytes() and ok.tobytes() == ok2.tobytes()


def test_a_capsule_proved_clear_by_earlier_distances_costs_no_query():
    clip, prop = _cylinder()
    hm = humanoid_handmap(clip.skeleton)
    cols = colliders_for(clip, prop)
    mm = 0.001 / clip.skeleton.meters_per_unit
    poser = next(p for p in chain_posers(clip, hm, InteractionConfig()) if p.chain.finger == "index")
    angles = finger_angles(clip, poser.chain.joints)
    frames = np.array([0])  # the open hand, 3 mm and more above the cylinder
    known = ChainDistances(clip.num_frames, len(poser.chain.joints) + 1)
    assert poser.clear(cols, frames, angles[frames], 0.0, 0.5 * mm, known=known)
    first = _queries(cols)
    assert first > 0
    # nudged by 0.1 mm: every capsule still proved clear from what was measured, nothing measured again
    moved = angles[frames].copy()
    moved[:, -1, int(poser.chain.axes[-1, 0])] += 0.05
    assert poser.clear(cols, frames, moved, 0.0, 0.5 * mm, known=known)
    assert _queries(cols) == first
    # asked for a clearance it cannot prove (a 5 cm margin): measured, and the answer is the exact one's
    assert not poser.clear(cols, frames, moved, 50 * mm, 0.5 * mm, known=known)
    assert _queries(cols) > first
    assert not poser.clear(colliders_for(clip, prop), frames, moved, 50 * mm, 0.5 * mm)


@pytest.mark.parametrize("case", ["cylinder", "mug"])
def test_a_group_of_chains_bisects_and_tests_as_each_chain_alone(case):
    """The correction bisects and re-tests all its chains of a size in step (ik.ChainGroup: chain c's frame
    f is the virtual frame c * stride + f, one memo for all): the openings, resolved frames, clear_below's
    answers and query count are those of each chain alone with its own memo, every=2's anchors and
    neighbours included (an odd stride, which puts one chain's anchors on the next one's odd frames,
    fails it)."""
    from usdhands.algorithms.interaction.ik import ChainGroup, group_stride

    if case != "cylinder" and not MUG.exists():
        pytest.skip("shared assets not present")
    clip, prop = CASES[case]()
    hm = humanoid_handmap(clip.skeleton)
    mm = 0.001 / clip.skeleton.meters_per_unit
    rng = np.random.default_rng(3)
    posers = chain_posers(clip, hm, InteractionConfig())
    T = clip.num_frames
    frames, bases = [], []
    for k, poser in enumerate(posers):
        angles = finger_angles(clip, poser.chain.joints)
        f = np.arange(T) if k % 2 else np.sort(rng.choice(T, size=min(T, 30), replace=False))
        frames.append(f)
        bases.append(angles[f] + rng.normal(scale=15.0, size=(len(f),) + angles.shape[1:]))
    cols = colliders_for(clip, prop)
    alone = []
    for p, f, b in zip(posers, frames, bases):
        known = ChainDistances(T, len(p.chain.joints) + 1)
        u, ok = p.least_opening(cols, f, b, 0.0, 0.5 * mm, every=2, known=known)
        below = p.clear_below(cols, f, b, np.zeros(len(f)), np.ones(len(f)), 0.0, 0.5 * mm, known=known)
        alone.append((u, ok, below))
    queries = _queries(cols)
    cols = colliders_for(clip, prop)
    stride = group_stride(T, 2)
    assert stride % 2 == 0 and stride >= T + 1
    group = ChainGroup(posers, stride)
    memo = ChainDistances(len(posers) * stride, len(posers[0].chain.joints) + 1)
    vf = np.concatenate([group.frames_of(c, f) for c, f in enumerate(frames)])
    u, ok = group.least_opening(cols, vf, np.concatenate(bases), 0.0, 0.5 * mm, every=2, known=memo)
    below = group.clear_below(cols, vf, np.concatenate(bases), np.zeros(len(vf)), np.ones(len(vf)), 0.0, 0.5 * mm,
                              known=memo)
    assert _queries(cols) == queries and any((a[0] > 0).any() for a in alone)
    sizes = np.cumsum([len(f) for f in frames])[:-1]
    for (ua, oka, ba), ug, okg, bg in zip(alone, np.split(u, sizes), np.split(ok, sizes), np.split(below, sizes)):
        assert ua.tobytes() == ug.tobytes() and oka.tobytes() == okg.tobytes() and ba.tobytes() == bg.tobytes()
    view = memo.view(stride, stride + T)  # chain 1's rows: what the group measured, the chain's memo knows
    assert np.array_equal(view.value, memo.value[stride:stride + T]) and np.isfinite(view.cutoff).any()

"""The interaction samples: the clips touch their props as documented, and ``correct`` fixes them."""

from __future__ import annotations

import numpy as np
import pytest

from usdhands.algorithms.interaction.body import body_collider
from usdhands.algorithms.interaction.colliders import Colliders, attached_xforms, mesh_collider
from usdhands.algorithms.interaction.correction import chain_posers, correct_clip
from usdhands.algorithms.interaction.finger_geometry import InteractionConfig
from usdhands.model.finger_dofs import finger_curves
from usdhands.model.prop import PropMesh
from usdhands.samples.humanoid import humanoid_handmap
from usdhands.samples.interaction import (
    CUP_HELD, cup_grasp_clip, cup_on_table_mesh, scratch_head_clip, table_mesh, table_rest_clip,
)


def _prop(mesh, name):
    return PropMesh(name, np.asarray(mesh.vertices), np.asarray(mesh.faces))


@pytest.fixture(scope="module")
def cup_scene():
    clip = cup_grasp_clip()
    hm = humanoid_handmap(clip.skeleton)
    cup = _prop(cup_on_table_mesh(), "cup")
    hand = clip.world_xforms()[:, clip.skeleton.index("RightHand")]
    held = attached_xforms(cup.xforms_at(clip.times), hand, *CUP_HELD)
    cols = Colliders([mesh_collider(cup, clip.times, world=held), mesh_collider(_prop(table_mesh(), "table"),
                                                                                clip.times)])
    return clip, hm, cols, held


def test_interaction_clips_are_deterministic():
    a, b = table_rest_clip(), table_rest_clip()
    assert a.rotations.tobytes() == b.rotations.tobytes()
    assert table_rest_clip(seed=1).rotations.tobytes() != a.rotations.tobytes()


def test_the_held_cup_is_lifted_with_the_hand_and_put_back(cup_scene):
    clip, hm, cols, held = cup_scene
    lift = held[:, 1, 3]  # the cup's height over the clip
    start, stop = CUP_HELD
    assert np.allclose(lift[:start], 0.0) and lift[start:stop].max() > 12.0  # lifted some 15 cm
    assert abs(lift[stop + 1:]).max() < 1.0  # and put down where it was, within a centimetre


def test_cup_grasp_penetrates_and_correct_fixes_it(cup_scene):
    clip, hm, cols, _ = cup_scene
    out, report = correct_clip(clip, hm, cols)
    d = report.to_dict()
    assert 3.0 < d["penetration_before_mm"]["max"] < 30.0  # fingers a little too far into the cup
    assert d["penetration_after_mm"]["max"] <= 0.5 and not report.unresolved
    assert "left index" not in report.chains_corrected  # the idle hand is left alone


def test_table_and_head_samples_touch_what_they_should():
    table = _prop(table_mesh(), "table")
    rest = table_rest_clip()
    hm = humanoid_handmap(rest.skeleton)
    _, report = correct_clip(rest, hm, Colliders([mesh_collider(table, rest.times)]), measure=True)
    assert report.penetration_before_mm.max() > 5.0 and report.penetration_after_mm.max() <= 0.5
    assert all(c.startswith("left") for c in report.chains_corrected)
    head = scratch_head_clip()
    _, report = correct_clip(head, hm, Colliders([body_collider(head, hm)]))
    assert report.penetration_before_mm.max() > 10.0
    assert {"right index", "right middle"} <= set(report.chains_corrected)


def _body_gaps_mm(clip, body, posers) -> np.ndarray:
    """Least gap between each chain's capsules and the body capsules per frame, ``(chains, T)`` mm:
    finger axes sampled every 0.25 mm, each sample's exact distance to every body segment (the
    textbook point-to-segment projection, not the collider's code)."""
    mm = 0.001 / clip.skeleton.meters_per_unit
    out = np.empty((len(posers), clip.num_frames))
    for c, poser in enumerate(posers):
        n = len(poser.chain.joints)
        angles = finger_curves(clip, poser.chain.joints).values.reshape(clip.num_frames, n, 3)
        a, b = poser.capsules(np.arange(clip.num_frames), angles)
        m = int(np.ceil(np.linalg.norm(b - a, axis=-1).max() / (0.25 * mm))) + 1
        t = np.linspace(0.0, 1.0, m)
        pts = a[:, :, None] + t[None, None, :, None] * (b - a)[:, :, None]  # (T, n, m, 3)
        best = np.full(pts.shape[:3], np.inf)
        for k in range(body.a.shape[1]):
            p0, p1 = body.a[:, k][:, None, None], body.b[:, k][:, None, None]
            axis = p1 - p0
            s = np.clip(np.sum((pts - p0) * axis, -1) / np.maximum(np.sum(axis * axis, -1), 1e-30), 0.0, 1.0)
            d = np.linalg.norm(pts - (p0 + s[..., None] * axis), axis=-1) - body.radii[k]
            best = np.minimum(best, d)
        out[c] = (best - poser.chain.radii[None, :, None]).min(axis=(1, 2)) / mm
    return out


def test_self_collision_guarantee_holds_on_the_head_by_exact_measure():
    """``--self`` on scratch_head: the fingertips dig some 25 mm into the head; afterwards no finger
    capsule is deeper than 0.5 mm in any body capsule on any frame, and none is left unresolved."""
    head = scratch_head_clip()
    hm = humanoid_handmap(head.skeleton)
    body = body_collider(head, hm)
    out, report = correct_clip(head, hm, Colliders([body]))
    before = _body_gaps_mm(head, body, chain_posers(head, hm, InteractionConfig()))
    after = _body_gaps_mm(out, body, chain_posers(out, hm, InteractionConfig()))
    assert before.min() < -20.0 and not report.unresolved
    assert after.min() >= -0.5
    assert report.penetration_after_mm.max() <= 0.5

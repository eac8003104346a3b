"""The palm as a collider of the hand: a palm pressed into a prop while every finger is clear is
measured (the correction's report, ``check --props``), though nothing can move it."""

from __future__ import annotations

import numpy as np
import trimesh
from interaction_data import colliders_for, exact_capsule_gaps_mm

from usdhands.algorithms.interaction.correction import chain_posers, correct_clip
from usdhands.algorithms.interaction.finger_geometry import InteractionConfig, finger_chains
from usdhands.algorithms.interaction.palm import palm_axes, palm_depth_mm
from usdhands.model.clip import Clip
from usdhands.model.prop import PropMesh
from usdhands.samples.humanoid import humanoid_handmap, humanoid_skeleton

#: How far the block's top rises above the bottom of the palm's 12 mm capsule at the wrist's height, mm
#: (deeper under the little finger's axis, which descends 3 mm to its base).
RISE_MM = 6.0


def palm_on_a_block():
    """The humanoid at rest (left wrist at (70, 144, -1) cm, fingers straight along +X, palm down)
    and a block under the left palm only: from behind the wrist to 1.5 cm short of the finger
    bases, on the little-finger side of the thumb, its top :data:`RISE_MM` into the palm's capsule."""
    sk = humanoid_skeleton()
    clip = Clip(sk, 30.0, np.tile(sk.rest_rotations, (5, 1, 1)), name="rest")
    top = 144.0 - 1.2 + RISE_MM / 10.0
    block = trimesh.creation.box(bounds=[[66.0, top - 3.0, -5.0], [76.5, top, -1.0]])
    return clip, PropMesh("block", block.vertices, block.faces)


def test_the_palm_in_a_block_with_every_finger_clear_is_measured():
    clip, block = palm_on_a_block()
    hm = humanoid_handmap(clip.skeleton)
    # the fingers (exact trimesh measure along every capsule) are clear of the block
    gaps = exact_capsule_gaps_mm(clip, [block], chain_posers(clip, hm, InteractionConfig()))
    assert np.nanmin(gaps) > 1.0
    # the palm is not: an exact measure of its axes (dense samples, trimesh) finds the block 6 mm in
    world = clip.world_xforms()
    axes = palm_axes(world, clip.skeleton, hm["left"], finger_chains(clip.skeleton, hm["left"]))
    t = np.linspace(0.0, 1.0, 400)[:, None]
    pts = (axes[0, :, 0, None] + t * (axes[0, :, 1, None] - axes[0, :, 0, None])).reshape(-1, 3)
    mesh = trimesh.Trimesh(np.asarray(block.vertices), np.asarray(block.faces))
    exact_mm = 12.0 - 10.0 * float(np.min(-trimesh.proximity.signed_distance(mesh, pts)))  # radius - gap, cm -> mm
    assert RISE_MM < exact_mm < RISE_MM + 3.0
    depth = palm_depth_mm(world, clip.skeleton, hm["left"], finger_chains(clip.skeleton, hm["left"]),
                          colliders_for(clip, block))
    assert np.all(depth >= exact_mm - 1e-6) and np.all(depth <= exact_mm + 0.06)  # the search's upper bound
    assert not palm_depth_mm(world, clip.skeleton, hm["right"], finger_chains(clip.skeleton, hm["right"]),
                             colliders_for(clip, block)).any()
    # the correction cannot move the palm: no finger changes, the report says where the hand still is
    out, report = correct_clip(clip, hm, colliders_for(clip, block))
    assert report.chains_corrected == []
    np.testing.assert_array_equal(out.rotations, clip.rotations)
    np.testing.assert_allclose(report.penetration_before_mm, depth)
    np.testing.assert_allclose(report.penetration_after_mm, depth)
    assert report.unresolved == [("left palm", f) for f in range(clip.num_frames)]
    # a thinner palm (the configuration) clears the block
    thin = InteractionConfig(palm_radius_mm=3.0)
    _, report = correct_clip(clip, hm, colliders_for(clip, block), config=thin)
    assert report.penetration_before_mm.max() == 0.0 and report.unresolved == []


def test_check_finds_the_palm_in_a_prop(tmp_path):
    from usdhands.formats.io import write_asset
    from usdhands.jobs.validation import CheckOptions, check
    from usdhands.model.asset import Asset

    clip, block = palm_on_a_block()
    src = tmp_path / "rest.usda"
    write_asset(Asset("rest", (clip.skeleton,), (clip,)), src)
    prop = tmp_path / "block.obj"
    trimesh.Trimesh(np.asarray(block.vertices), np.asarray(block.faces)).export(prop)
    findings = [f for f in check([src], CheckOptions(props=(prop,))).findings if f.rule == "props"]
    assert len(findings) == 1
    hm = humanoid_handmap(clip.skeleton)
    depth = palm_depth_mm(clip.world_xforms(), clip.skeleton, hm["left"], finger_chains(clip.skeleton, hm["left"]),
                          colliders_for(clip, block))
    assert depth.max() > RISE_MM
    assert findings[0].message.startswith(f"the left palm penetrates block by up to {depth.max():.2f} mm in 5 frame(s)")


def test_with_self_a_palm_is_not_measured_against_its_own_upper_arm():
    """The scratch_head sample folds the right elbow: the palm's wrist end passes 27 mm into the right
    upper arm's capsule, which stands for the whole arm's flesh, and is not counted; every other
    body capsule is."""
    from usdhands.algorithms.interaction.body import body_collider
    from usdhands.algorithms.interaction.colliders import CapsuleCollider, Colliders
    from usdhands.samples.interaction import scratch_head_clip

    clip = scratch_head_clip()
    hm = humanoid_handmap(clip.skeleton)
    body = body_collider(clip, hm)
    assert body.parts == ("torso", "head", "left upper arm", "right upper arm", "left thigh", "right thigh")
    world = clip.world_xforms()
    hand = hm["right"]
    chains = finger_chains(clip.skeleton, hand)
    assert not palm_depth_mm(world, clip.skeleton, hand, chains, Colliders([body])).any()
    anonymous = CapsuleCollider("body", body.a, body.b, body.radii)  # no part names: every capsule counts
    folded = palm_depth_mm(world, clip.skeleton, hand, chains, Colliders([anonymous]))
    assert folded.max() > 20.0 and np.count_nonzero(folded) <= 5
    # the upper arm alone, under another name, is measured
    arm = body.parts.index("right upper arm")
    renamed = CapsuleCollider("arm", body.a[:, arm:arm + 1], body.b[:, arm:arm + 1], body.radii[arm:arm + 1],
                              ("left upper arm",))
    np.testing.assert_array_equal(palm_depth_mm(world, clip.skeleton, hand, chains, Colliders([renamed])), folded)

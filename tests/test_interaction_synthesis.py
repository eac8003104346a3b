"""Interactions inside synthesis: proximity cuts, the collision term, and ``synthesize --props``."""

from __future__ import annotations

import json

import numpy as np
import trimesh
from interaction_data import closing_hand_clip, colliders_for, cylinder_under_palm

from usdhands.algorithms.interaction.synthesis_terms import InteractionTerms, proximity_cuts
from usdhands.algorithms.synthesis.finger_transfer import (
    canonical_curves, canonical_to_local, hand_rig, local_to_canonical,
)
from usdhands.cli import main
from usdhands.formats.io import write_asset
from usdhands.model.asset import Asset
from usdhands.samples.humanoid import humanoid_handmap


def test_proximity_cuts_split_where_the_wrist_comes_near_unless_too_close_to_a_boundary():
    near = np.zeros(60, dtype=bool)
    near[12:45] = True
    assert proximity_cuts(np.array([0, 30, 60]), near, 10).tolist() == [0, 12, 30, 45, 60]
    near[:] = False
    near[33:52] = True  # 3 frames after a boundary and 8 before one: no cut
    assert proximity_cuts(np.array([0, 30, 60]), near, 10).tolist() == [0, 30, 60]


def test_collision_term_charges_a_curled_candidate_and_not_an_open_one():
    clip = closing_hand_clip(frames=30)
    hand = humanoid_handmap(clip.skeleton)["left"]
    rig = hand_rig(clip.skeleton, hand)
    curled = canonical_curves(clip, rig)[15]  # the fingers at full curl, through the cylinder
    segments = {0: np.zeros((20, 60)), 1: np.tile(curled, (20, 1))}
    to_local = lambda c: canonical_to_local(clip.skeleton, rig, c)  # noqa: E731
    to_curves = lambda q: local_to_canonical(clip.skeleton, rig, q)  # noqa: E731
    terms = InteractionTerms(clip, hand, rig, to_local, to_curves, lambda s: segments[s],
                             colliders_for(clip, cylinder_under_palm()), weight=1.0, reach=15.0, min_frames=5)
    assert terms.near.all()  # the wrist is within 15 cm of the cylinder throughout
    cost = terms.penalty(np.array([0, 30]), np.array([[0, 1]]))
    assert cost[0, 0] == 0.0 and cost[0, 1] > 10.0  # deg^2 per frame and DOF
    far = InteractionTerms(clip, hand, rig, to_local, to_curves, lambda s: segments[s],
                           colliders_for(clip, cylinder_under_palm()), weight=1.0, reach=0.1, min_frames=5)
    assert far.penalty(np.array([0, 30]), np.array([[0, 1]])).tolist() == [[0.0, 0.0]]


def test_synthesize_with_props_leaves_no_penetration(tmp_path, capsys):
    clip = closing_hand_clip(frames=30)
    write_asset(Asset("closing", (clip.skeleton,), (clip,)), tmp_path / "in.usda")
    prop = cylinder_under_palm()
    trimesh.Trimesh(np.asarray(prop.vertices), np.asarray(prop.faces)).export(tmp_path / "cyl.obj")
    code = main([str(a) for a in ("synthesize", tmp_path / "in.usda", "--props", tmp_path / "cyl.obj",
                                  "-o", tmp_path / "out.usda", "--json")])
    out = capsys.readouterr()
    assert code == 0, out.err
    report = json.loads(out.out)
    inter = report["interaction"]
    assert inter["penetration_after_mm"]["max"] <= 0.5
    assert {"penetration_before_mm", "frames_corrected", "jitter_before", "jitter_after",
            "max_change_deg"} <= set(inter)
    assert (tmp_path / "out.usda").exists()


def test_db_build_with_props_stores_the_corrected_fingers(tmp_path, capsys):
    from usdhands.algorithms.synthesis.database import load_database

    clip = closing_hand_clip(frames=30)
    write_asset(Asset("closing", (clip.skeleton,), (clip,)), tmp_path / "in.usda")
    prop = cylinder_under_palm()
    trimesh.Trimesh(np.asarray(prop.vertices), np.asarray(prop.faces)).export(tmp_path / "cyl.obj")
    assert main(["db", "build", str(tmp_path / "in.usda"), "-o", str(tmp_path / "plain")]) == 0
    assert main(["db", "build", str(tmp_path / "in.usda"), "--props", str(tmp_path / "cyl.obj"),
                 "-o", str(tmp_path / "props")]) == 0
    err = capsys.readouterr().err
    assert "corrected against the props" in err
    plain, fixed = load_database(tmp_path / "plain"), load_database(tmp_path / "props")
    assert plain.fingers.shape == fixed.fingers.shape
    # the curled frames were opened: less total flexion in the corrected database
    assert np.abs(np.asarray(fixed.fingers)).sum() < 0.8 * np.abs(np.asarray(plain.fingers)).sum()


def test_synthesize_with_props_at_another_rate_than_the_database_builds_each_tree_once(tmp_path, capsys,
                                                                                        monkeypatch):
    """A 60 fps clip is synthesized at the database's 30 fps and corrected at its own rate: two sets of
    colliders, one MeshProximity per prop (a static one and one attached to the wrist)."""
    from usdhands.algorithms.interaction import colliders as colliders_module

    built = []
    real = colliders_module.MeshProximity

    class Counted(real):
        def __init__(self, *args, **kwargs):
            built.append(1)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(colliders_module, "MeshProximity", Counted)
    clip = closing_hand_clip(frames=60, fps=60.0)
    write_asset(Asset("closing", (clip.skeleton,), (clip,)), tmp_path / "in.usda")
    prop = cylinder_under_palm()
    trimesh.Trimesh(np.asarray(prop.vertices), np.asarray(prop.faces)).export(tmp_path / "cyl.obj")
    ball = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    ball.apply_translation([60.0, 120.0, 0.0])
    ball.export(tmp_path / "ball.obj")
    wrist = humanoid_handmap(clip.skeleton)["left"].wrist
    code = main([str(a) for a in ("synthesize", tmp_path / "in.usda", "--props", tmp_path / "cyl.obj",
                                  tmp_path / "ball.obj", "--attach", f"ball={wrist}", "-o", tmp_path / "out.usda",
                                  "--json")])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert len(built) == 2
    assert json.loads(out.out)["interaction"]["penetration_after_mm"]["max"] <= 0.5

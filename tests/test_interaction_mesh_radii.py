"""Finger capsules from the skinned hand mesh: a hand made of tubes of known radii gives those radii,
and the correction measures penetration with them (the configuration's table where the mesh has
too few vertices, names in the configuration first)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from usdhands.algorithms.interaction.finger_geometry import InteractionConfig, finger_chains, mesh_radii
from usdhands.model.asset import Asset, SkinnedMesh
from usdhands.model.clip import Clip
from usdhands.samples.humanoid import humanoid_handmap, humanoid_skeleton

#: Tube radius per segment of the left hand's fingers, cm (the default table says 6.5 to 10 mm).
TUBE_CM = {"thumb": (0.71, 0.62, 0.53), "index": (0.5, 0.45, 0.4), "middle": (0.52, 0.47, 0.42),
           "ring": (0.5, 0.44, 0.38), "pinky": (0.45, 0.4, 0.35)}


def tube_hand(skeleton, hand, rings: int = 12, around: int = 16, skip: tuple = ()) -> SkinnedMesh:
    """A mesh of one tube per finger segment (joint to next joint or tip) of radius :data:`TUBE_CM`,
    every vertex skinned fully to the segment's joint; ``skip``: joint names given no tube."""
    rest = skeleton.rest_world_xforms()
    pts, faces, joints = [], [], []
    for chain in finger_chains(skeleton, hand):
        js = list(chain.joints)
        ends = [rest[j, :3, 3] for j in js] + [rest[js[-1], :3, :3] @ chain.tip_offset + rest[js[-1], :3, 3]]
        for k, j in enumerate(js):
            if skeleton.joint_names[j].rsplit("/", 1)[-1] in skip:
                continue
            a, b = ends[k], ends[k + 1]
            axis = (b - a) / np.linalg.norm(b - a)
            e1 = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(axis, e1)
            t = np.linspace(0.0, 1.0, rings)[:, None, None]
            u = np.linspace(0.0, 2 * np.pi, around, endpoint=False)[None, :, None]
            ring = a + t * (b - a) + TUBE_CM[chain.finger][k] * (np.cos(u) * e1 + np.sin(u) * e2)
            base = sum(len(p) for p in pts)
            pts.append(ring.reshape(-1, 3))
            for r in range(rings - 1):
                for s in range(around):
                    i0, i1 = base + r * around + s, base + r * around + (s + 1) % around
                    faces += [[i0, i1, i1 + around], [i0, i1 + around, i0 + around]]
            joints += [j] * (rings * around)
    points = np.concatenate(pts)
    faces = np.asarray(faces)
    return SkinnedMesh("hand", points, np.full(len(faces), 3), faces.reshape(-1),
                       joint_indices=np.asarray(joints)[:, None], joint_weights=np.ones((len(points), 1)))


def test_the_radii_of_a_hand_made_of_tubes():
    sk = humanoid_skeleton()
    hand = humanoid_handmap(sk)["left"]
    measured = mesh_radii(sk, hand, [tube_hand(sk, hand, skip=("LeftHandRing3",))])
    for chain in finger_chains(sk, hand):
        for k, j in enumerate(chain.joints):
            name = sk.joint_names[j].rsplit("/", 1)[-1]
            if name == "LeftHandRing3":
                assert sk.joint_names[j] not in measured  # no vertices: the configuration's radius applies
                continue
            assert measured[sk.joint_names[j]] == pytest.approx(TUBE_CM[chain.finger][k] * 10.0, rel=1e-9)  # mm
    config = InteractionConfig(joint_radii_mm={"LeftHandIndex1": 7.5}).with_mesh_radii(measured)
    radii = {c.finger: c.radii for c in finger_chains(sk, hand, config)}
    np.testing.assert_allclose(radii["index"], [0.75, 0.45, 0.4])  # the name given wins over the mesh
    np.testing.assert_allclose(radii["ring"], [0.5, 0.44, InteractionConfig().radii_mm["ring"][2] / 10.0])
    assert InteractionConfig(mesh_radii=False).with_mesh_radii(measured).joint_radii_mm == {}


def test_weights_below_half_do_not_count():
    sk = humanoid_skeleton()
    hand = humanoid_handmap(sk)["left"]
    mesh = tube_hand(sk, hand)
    weak = SkinnedMesh(mesh.name, mesh.points, mesh.face_vertex_counts, mesh.face_vertex_indices,
                       joint_indices=np.concatenate([mesh.joint_indices, np.zeros_like(mesh.joint_indices)], axis=1),
                       joint_weights=np.full((len(mesh.points), 2), 0.5) - [0.0, 1e-3] * np.array([[-1.0, 1.0]]))
    assert mesh_radii(sk, hand, [weak]) == mesh_radii(sk, hand, [mesh])  # 0.501 to the finger joint
    none = SkinnedMesh(mesh.name, mesh.points, mesh.face_vertex_counts, mesh.face_vertex_indices,
                       joint_indices=np.concatenate([mesh.joint_indices, mesh.joint_indices + 1], axis=1),
                       joint_weights=np.full((len(mesh.points), 2), 0.49))
    assert mesh_radii(sk, hand, [none]) == {}


@pytest.fixture(scope="module")
def hand_on_a_ledge(tmp_path_factory):
    """The humanoid at rest with its left hand of tubes written as .glb, and a block 7 mm below the
    middle of the index's proximal segment (the tube there is 5 mm thick, the default capsule 9 mm)."""
    from usdhands.formats.io import write_asset

    sk = humanoid_skeleton()
    hand = humanoid_handmap(sk)["left"]
    clip = Clip(sk, 30.0, np.tile(sk.rest_rotations, (4, 1, 1)), name="rest")
    folder = tmp_path_factory.mktemp("ledge")
    src = folder / "hand.glb"
    write_asset(Asset("hand", (sk,), (clip,), (tube_hand(sk, hand),)), src)
    rest = sk.rest_world_positions()
    a, b = rest[sk.index("LeftHandIndex1")], rest[sk.index("LeftHandIndex2")]
    mid = (a + b) / 2
    block = trimesh.creation.box([0.6, 1.0, 0.8])
    block.apply_translation(mid + [0.0, -0.7 - 0.5, 0.0])  # its top 7 mm below the axis
    prop = folder / "ledge.obj"
    (block.apply_scale(0.01)).export(prop)  # the .glb reads back in metres; an OBJ is taken in the clip's units
    return src, prop, folder


@pytest.mark.parametrize("config, deepest_mm", [({}, 0.0), ({"mesh_radii": False}, 2.0),
                                                ({"joint_radii_mm": {"LeftHandIndex1": 8.0}}, 1.0)])
def test_correct_measures_the_fingers_the_file_draws(hand_on_a_ledge, config, deepest_mm):
    from usdhands.jobs.correction import CorrectOptions, correct

    src, prop, folder = hand_on_a_ledge
    cfg = folder / f"config{len(json.dumps(config))}.json"
    cfg.write_text(json.dumps(config))
    result = correct(src, folder / "out.glb", CorrectOptions(props=(prop,), interaction_config=cfg))
    assert result.penetration_before_mm["max"] == pytest.approx(deepest_mm, abs=0.06)
    assert result.chains_corrected == (("left index",) if deepest_mm else ())


@pytest.mark.parametrize("config, finds", [({}, False), ({"mesh_radii": False}, True)])
def test_check_measures_with_the_same_capsules_as_correct(hand_on_a_ledge, config, finds):
    from usdhands.jobs.validation import CheckOptions, check

    src, prop, folder = hand_on_a_ledge
    cfg = folder / f"check{len(json.dumps(config))}.json"
    cfg.write_text(json.dumps(config))
    result = check([src], CheckOptions(props=(prop,), interaction_config=cfg))
    props = [f for f in result.findings if f.rule == "props"]
    assert bool(props) == finds
    assert all("left index finger penetrates" in f.message for f in props)


def test_correct_stage_measures_the_fingers_the_stage_draws(hand_on_a_ledge):
    """The stage hook takes the skinned mesh's radii as the correct job does."""
    pxr = pytest.importorskip("pxr")
    import usdhands.usd
    from usdhands.formats.io import read_asset, write_asset
    from usdhands.jobs.correction import CorrectOptions

    src, prop, folder = hand_on_a_ledge
    usda = folder / "hand.usda"
    write_asset(read_asset(src), usda)
    cfg = folder / "no_mesh.json"
    cfg.write_text(json.dumps({"mesh_radii": False}))
    with_mesh = usdhands.usd.correct_stage(pxr.Usd.Stage.Open(str(usda)), props=[prop])
    without = usdhands.usd.correct_stage(pxr.Usd.Stage.Open(str(usda)), props=[prop],
                                         options=CorrectOptions(interaction_config=cfg))
    assert with_mesh.report["penetration_before_mm"]["max"] == 0.0
    assert without.report["penetration_before_mm"]["max"] == pytest.approx(2.0, abs=0.06)


def test_check_stage_measures_the_fingers_the_stage_draws(hand_on_a_ledge):
    pxr = pytest.importorskip("pxr")
    import usdhands.usd
    from usdhands.formats.io import read_asset, write_asset
    from usdhands.jobs.validation import CheckOptions

    src, prop, folder = hand_on_a_ledge
    usda = folder / "hand_check.usda"
    write_asset(read_asset(src), usda)
    findings = usdhands.usd.check_stage(pxr.Usd.Stage.Open(str(usda)), CheckOptions(props=(prop,)))
    assert not [f for f in findings if f.rule == "props"]


@pytest.mark.parametrize("config, deepest_mm", [({}, 0.0), ({"mesh_radii": False}, 2.0)])
def test_db_build_corrects_the_fingers_the_file_draws(hand_on_a_ledge, config, deepest_mm, tmp_path):
    """``db build --props`` measures with the skinned mesh's radii as ``correct`` does: the 5 mm tubes
    clear the ledge and go into the database as they are; the table's 9 mm capsule is 2 mm into it
    (the finger already straight: nothing to open, so it stays there)."""
    from usdhands.algorithms.synthesis.database import load_database
    from usdhands.formats.io import read_asset, write_asset
    from usdhands.jobs.database import BuildDbOptions, build_db

    src, prop, folder = hand_on_a_ledge
    asset = read_asset(src)
    (clip,) = asset.clips
    long = Clip(clip.skeleton, 30.0, np.tile(clip.rotations[:1], (90, 1, 1)), name="rest")  # 3 s to segment
    held = tmp_path / "held.glb"
    write_asset(Asset("hand", asset.skeletons, (long,), asset.meshes), held)
    cfg = tmp_path / "config.json"
    cfg.write_text(json.dumps(config))
    result = build_db([held], tmp_path / "db", BuildDbOptions(props=(prop,), interaction_config=cfg))
    (note,) = [text for kind, text in result.messages if "corrected against the props" in text]
    before = float(note.split("(penetration ")[1].split(" ->")[0])
    assert before == pytest.approx(deepest_mm, abs=0.06)
    build_db([held], tmp_path / "plain", BuildDbOptions())
    same = np.array_equal(load_database(tmp_path / "db").fingers, load_database(tmp_path / "plain").fingers)
    assert same == (deepest_mm == 0.0)


def palm_slab(skeleton, hand, half_cm: float, rows: int = 10, cols: int = 8) -> SkinnedMesh:
    """Two sheets ``half_cm`` either side of the plane of the wrist and the long fingers' first joints,
    over the palm (from the wrist to the finger bases, between the outermost bases), every vertex
    skinned fully to the wrist: a palm ``2 * half_cm`` thick."""
    rest = skeleton.rest_world_xforms()[:, :3, 3]
    w = rest[skeleton.index(hand.wrist)]
    b = rest[[c.joints[0] for c in finger_chains(skeleton, hand) if c.finger != "thumb"]]
    corners = np.vstack([w[None], b])
    centre = corners.mean(axis=0)
    normal = np.linalg.svd(corners - centre)[2][2]
    forward = b.mean(axis=0) - w
    forward -= normal * (forward @ normal)
    across = np.cross(normal, forward) / np.linalg.norm(forward)
    span = (b - w) @ across
    t = np.linspace(0.05, 0.95, rows)[:, None, None]
    u = np.linspace(span.min(), span.max(), cols)[None, :, None]
    sheet = w + t * forward + u * across + ((centre - w) @ normal) * normal
    pts = np.concatenate([(sheet + side * half_cm * normal).reshape(-1, 3) for side in (1.0, -1.0)])
    faces = []
    for base in (0, rows * cols):
        for r in range(rows - 1):
            for c in range(cols - 1):
                i = base + r * cols + c
                faces += [[i, i + 1, i + cols + 1], [i, i + cols + 1, i + cols]]
    faces = np.asarray(faces)
    return SkinnedMesh("palm", pts, np.full(len(faces), 3), faces.reshape(-1),
                       joint_indices=np.full((len(pts), 1), skeleton.index(hand.wrist)),
                       joint_weights=np.ones((len(pts), 1)))


def test_the_palm_radius_is_half_the_thickness_of_the_palm_the_mesh_draws():
    sk = humanoid_skeleton()
    hand = humanoid_handmap(sk)["left"]
    wrist = sk.joint_names[sk.index(hand.wrist)]
    measured = mesh_radii(sk, hand, [tube_hand(sk, hand), palm_slab(sk, hand, 0.45)])
    assert measured[wrist] == pytest.approx(4.5, rel=1e-9)  # mm
    # vertices the wrist drives beside the palm (the forearm behind it, a thumb pad outside the bases)
    # do not count
    slab = palm_slab(sk, hand, 0.45)
    rest = sk.rest_world_positions()
    stray = np.concatenate([rest[sk.index(hand.wrist)] - [3.0, 0.0, 0.0] + np.arange(30)[:, None] * [0.0, 0.1, 0.0],
                            rest[sk.index(hand.wrist)] + [3.0, 0.0, 6.0] + np.arange(30)[:, None] * [0.0, 0.1, 0.0]])
    both = SkinnedMesh("palm", np.concatenate([slab.points, stray]), slab.face_vertex_counts, slab.face_vertex_indices,
                       joint_indices=np.full((len(slab.points) + len(stray), 1), sk.index(hand.wrist)),
                       joint_weights=np.ones((len(slab.points) + len(stray), 1)))
    assert mesh_radii(sk, hand, [both])[wrist] == pytest.approx(4.5, rel=1e-9)
    assert wrist not in mesh_radii(sk, hand, [tube_hand(sk, hand)])  # no palm drawn: palm_radius_mm applies


@pytest.mark.parametrize("half_mm, config, deeper_mm", [
    (3.0, {}, None),  # a thin palm clears the block the default 12 mm capsule is in
    (16.0, {}, 4.0),  # a thick one is 4 mm deeper in than the default
    (16.0, {"mesh_radii": False}, 0.0),  # the configuration's palm_radius_mm
    (16.0, {"joint_radii_mm": {"LeftHand": 12.0}}, 0.0),  # the wrist named in the configuration wins
])
def test_correct_measures_the_palm_the_file_draws(tmp_path, half_mm, config, deeper_mm):
    from test_interaction_palm import palm_on_a_block

    from usdhands.formats.io import write_asset
    from usdhands.jobs.correction import CorrectOptions, correct

    clip, block = palm_on_a_block()
    sk = clip.skeleton
    hand = humanoid_handmap(sk)["left"]
    src = tmp_path / "hand.glb"
    write_asset(Asset("hand", (sk,), (clip,), (tube_hand(sk, hand), palm_slab(sk, hand, half_mm / 10.0))), src)
    prop = tmp_path / "block.obj"
    trimesh.Trimesh(np.asarray(block.vertices) * 0.01, np.asarray(block.faces)).export(prop)  # the .glb reads in metres
    default = tmp_path / "default.json"
    default.write_text(json.dumps({"mesh_radii": False}))
    reference = correct(src, tmp_path / "ref.glb", CorrectOptions(props=(prop,), interaction_config=default))
    assert reference.penetration_before_mm["max"] > 6.0  # the default 12 mm palm is in the block
    cfg = tmp_path / "config.json"
    cfg.write_text(json.dumps(config))
    result = correct(src, tmp_path / "out.glb", CorrectOptions(props=(prop,), interaction_config=cfg))
    assert result.chains_corrected == ()  # the fingers are clear: only the palm touches
    if deeper_mm is None:
        assert result.penetration_before_mm["max"] == 0.0 and result.unresolved == ()
    else:
        assert result.penetration_before_mm["max"] == pytest.approx(reference.penetration_before_mm["max"] + deeper_mm,
                                                                     abs=0.06)
        assert result.unresolved

"""Generated sample assets: the rig, the gesture motions, the files and their determinism."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from usdhands.cli import main as cli_main
from usdhands.model import finger_curves
from usdhands.model.rotations import quat_angle_deg, quat_conjugate, quat_multiply
from usdhands.samples.gestures import (
    GESTURE_TYPES, TAKES_PER_TYPE, body_only, conversation_annotations, conversation_clip, gesture_database,
    gesture_hands, gesture_take, wave_clip,
)
from usdhands.samples.hand_poses import fingertip_positions, gesture_pose, mirror_pose, relaxed_pose
from usdhands.samples.humanoid import (
    FINGER_NAMES, finger_joint_indices, humanoid_handmap, humanoid_mesh, humanoid_skeleton,
)
from usdhands.samples.props import CUP_HEIGHT_CM, cup_mesh

ROOT = Path(__file__).resolve().parent.parent
FPS = 30.0


@pytest.fixture(scope="module")
def database():
    return gesture_database()


@pytest.fixture(scope="module")
def skeleton():
    return humanoid_skeleton()


def _names(side: str) -> list[str]:
    s = side
    arm = [f"{s}Shoulder", f"{s}Arm", f"{s}ForeArm", f"{s}Hand"]
    fingers = [f"{s}Hand{f}{k}" for f in FINGER_NAMES for k in range(1, 5)]
    legs = [f"{s}UpLeg", f"{s}Leg", f"{s}Foot", f"{s}ToeBase", f"{s}Toe_End"]
    return arm + fingers + legs


def _hold_frame(clip, side="Right") -> int:
    """The frame of least wrist speed in the middle half of a take (inside the hold)."""
    w = clip.world_positions_cm()[:, clip.skeleton.index(f"{side}Hand")]
    sp = np.linalg.norm(np.diff(w, axis=0), axis=1)
    T = len(sp)
    return int(np.argmin(sp[T // 4:3 * T // 4]) + T // 4)


def _rel(clip):
    sk = clip.skeleton
    return quat_multiply(quat_conjugate(sk.rest_rotations)[None], clip.rotations)


# ------------------------------------------------------------------- the rig

def test_skeleton_names_units_and_proportions(skeleton):
    sk = skeleton
    expected = {"Hips", "Spine", "Spine1", "Spine2", "Neck", "Head", "HeadTop_End"}
    expected |= set(_names("Left")) | set(_names("Right"))
    assert set(sk.short_names) == expected and sk.num_joints == 65
    assert all(":" not in n for n in sk.joint_names)
    assert sk.joint_names[sk.index("LeftHandIndex1")] == "Hips/Spine/Spine1/Spine2/LeftShoulder/LeftArm/LeftForeArm/LeftHand/LeftHandIndex1"
    assert sk.meters_per_unit == 0.01 and sk.up_axis == "Y"
    p = sk.rest_world_positions()
    ix = sk.index
    assert 170 <= p[ix("HeadTop_End"), 1] - p[ix("LeftToe_End"), 1] + 1.5 <= 180
    # T-pose: arms along +X (left) and -X (right) at shoulder height
    for side, sgn in (("Left", 1), ("Right", -1)):
        d = p[ix(f"{side}Hand")] - p[ix(f"{side}Arm")]
        assert sgn * d[0] > 50 and abs(d[1]) < 1 and abs(d[2]) < 1
    # arm span about the height
    span = p[ix("LeftHandMiddle4"), 0] - p[ix("RightHandMiddle4"), 0]
    assert 165 < span < 190
    # mirror symmetric
    for n in _names("Left"):
        assert np.allclose(p[ix(n)] * [-1, 1, 1], p[ix(n.replace("Left", "Right"))])
    # bind transforms are the rest pose's world transforms
    assert np.allclose(sk.bind_xforms, sk.rest_world_xforms(), atol=1e-9)


def test_finger_flexion_is_one_local_axis(skeleton):
    """Rotating a finger joint about its local +X curls the finger toward the palm, on both hands."""
    sk = skeleton
    for side in ("Left", "Right"):
        hand = sk.rest_world_xforms()[sk.index(f"{side}Hand")]
        palm_out = hand[:3, 2]  # local Z of the hand: out of the palm
        assert np.allclose(palm_out, [0, -1, 0], atol=1e-6)  # palms down in the T-pose
        for f in FINGER_NAMES[1:]:
            j = sk.index(f"{side}Hand{f}2")
            tip = sk.index(f"{side}Hand{f}4")
            rot = np.array(sk.rest_rotations)
            rot[j] = quat_multiply(rot[j], [np.sin(np.radians(30)), 0, 0, np.cos(np.radians(30))])  # 60° about X
            from usdhands.model import Clip
            c = Clip(sk, 30.0, rot[None])
            moved = c.world_positions()[0, tip] - sk.rest_world_positions()[tip]
            assert np.dot(moved, palm_out) > 1.5, (side, f)  # toward the palm side
            assert abs(moved[2]) < 0.3  # not sideways


def test_handmap_detection_matches(skeleton):
    from usdhands.model.hand_detection import detect_hands

    assert detect_hands(skeleton).to_dict() == humanoid_handmap(skeleton).to_dict()


def test_mesh_skinning_normals_uvs(skeleton):
    m = humanoid_mesh(skeleton)
    V = len(m.points)
    assert 300 <= V <= 600 and len(m.face_vertex_counts) == 624
    assert set(np.unique(m.face_vertex_counts)) == {3}
    assert m.face_vertex_indices.max() == V - 1
    assert np.allclose(m.joint_weights.sum(axis=1), 1.0)
    nz = (m.joint_weights > 0).sum(axis=1)
    assert nz.min() == 1 and nz.max() == 5 and (nz > 4).sum() >= 8
    assert np.allclose(np.linalg.norm(m.normals, axis=1), 1.0)
    assert m.uvs.min() >= 0 and m.uvs.max() <= 1
    # faces wind outward: the signed volume of the closed boxes is positive
    tri = m.points[m.face_vertex_indices.reshape(-1, 3)]
    vol = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    assert vol > 0
    # each vertex's main influence is the bone whose box it belongs to: near its joint
    p = skeleton.rest_world_positions()
    main = m.joint_indices[np.arange(V), np.argmax(m.joint_weights, axis=1)]
    assert np.median(np.linalg.norm(m.points - p[main], axis=1)) < 20


# ------------------------------------------------------------------- gestures

def test_database_labels_lengths_and_names(database):
    assert len(database) == 64
    labels = [lab for lab, _ in database]
    assert sorted(set(labels)) == sorted(GESTURE_TYPES) and all(labels.count(g) == 8 for g in GESTURE_TYPES)
    for lab, clip in database:
        assert re.fullmatch(r"([a-z_]+)_\d+", clip.name).group(1) == lab
        assert clip.fps == FPS and 2.0 <= clip.duration <= 4.0
        clip.validate()
    # every take differs from every other of its type
    for g in GESTURE_TYPES:
        takes = [c for lab, c in database if lab == g]
        for i in range(1, len(takes)):
            n = min(takes[0].num_frames, takes[i].num_frames)
            assert np.abs(takes[0].rotations[:n] - takes[i].rotations[:n]).max() > 0.05


def test_deterministic_in_memory():
    a, b = gesture_take("turn", 3), gesture_take("turn", 3)
    assert np.array_equal(a.rotations, b.rotations) and np.array_equal(a.translations, b.translations)
    assert not np.array_equal(gesture_take("turn", 3, seed=1).rotations[:10], a.rotations[:10])


def test_takes_vary_height_distance_and_pacing(database):
    for g in GESTURE_TYPES:
        clips = [c for lab, c in database if lab == g]
        heights, dists = [], []
        for c in clips:
            f = _hold_frame(c)
            w = c.world_positions_cm()[f]
            heights.append(w[c.skeleton.index("RightHand"), 1])
            dists.append(w[c.skeleton.index("RightHand"), 2])
        durations = [c.duration for c in clips]
        assert np.ptp(heights) > 9, g
        assert np.ptp(dists) > 6, g
        assert np.ptp(durations) > 0.4, g


def test_phases_rest_stroke_hold_retraction(database):
    """Each take starts and ends at rest and holds between two fast phases."""
    rest = gesture_take("ok", 0).world_positions_cm()[0, humanoid_skeleton().index("RightHand")]
    for lab, c in database:
        w = c.world_positions_cm()[:, c.skeleton.index("RightHand")]
        assert np.linalg.norm(w[0] - rest) < 4 and np.linalg.norm(w[-1] - rest) < 4, c.name
        speed = np.linalg.norm(np.diff(w, axis=0), axis=1) * FPS  # cm/s
        fast = speed > 25
        still = speed < 5
        first_fast = np.argmax(fast)
        last_fast = len(fast) - 1 - np.argmax(fast[::-1])
        hold = still[first_fast:last_fast]
        # a hold of at least 0.25 s between the stroke and the retraction
        runs = np.diff(np.flatnonzero(np.diff(np.concatenate([[0], hold.astype(int), [0]]))))[::2]
        assert len(runs) and runs.max() >= 0.25 * FPS, c.name
        assert speed.max() > 30, c.name


def test_joint_limits_and_smoothness(database):
    clips = [c for _, c in database[::3]] + [conversation_clip(), wave_clip()]
    sk = clips[0].skeleton
    fj = finger_joint_indices(sk, "left") + finger_joint_indices(sk, "right")
    for c in clips:
        rel = _rel(c)
        world = c.world_xforms()
        step = quat_angle_deg(c.rotations[1:], c.rotations[:-1])
        assert step.max() < 25, c.name  # no joint turns more than 25° in one frame (750°/s)
        acc = np.abs(np.diff(step, axis=0))
        assert acc.max() < 18, c.name
        # fingers: flexion -10..110°, abduction within ±35°, never about the bone (y)
        e = finger_curves(c, fj).values.reshape(c.num_frames, -1, 3)
        assert e[..., 0].min() > -10 and e[..., 0].max() < 110, c.name
        assert np.abs(e[..., 2]).max() < 35 and np.abs(e[5:, 3:, 1]).max() < 1e-6
        for side in ("Left", "Right"):
            # the elbow hinges one way, under 160°: the angle between the upper arm and forearm
            # bones, and the turn from one to the other about the upper arm's +x axis only
            arm, fore = world[:, sk.index(f"{side}Arm"), :3, :3], world[:, sk.index(f"{side}ForeArm"), :3, :3]
            ya, yf = arm[:, :, 1], fore[:, :, 1]
            flex = np.degrees(np.arccos(np.clip(np.sum(ya * yf, axis=1), -1, 1)))
            assert flex.max() < 160, (c.name, side, flex.max())
            hinge = np.einsum("tji,tj->ti", arm, np.cross(ya, yf))  # sin(flex) times the axis, in the arm's frame
            assert hinge[:, 0].min() > 0 and np.abs(hinge[:, 1:]).max() < 1e-6, (c.name, side)
            # the wrist bends less than 80° from its forearm (angle between the bones)
            yh = world[:, sk.index(f"{side}Hand"), :3, 1]
            yf = world[:, sk.index(f"{side}ForeArm"), :3, 1]
            bend = np.degrees(np.arccos(np.clip(np.sum(yh * yf, axis=1), -1, 1)))
            assert bend.max() < 80, (c.name, side, bend.max())
            lift = quat_angle_deg(rel[:, sk.index(f"{side}Shoulder")], [0, 0, 0, 1])
            assert lift.max() < 16


def test_characteristic_finger_poses(database):
    """At the hold, each type shows its hand shape; at the first frame the hand is relaxed."""
    sk = humanoid_skeleton()
    fj = finger_joint_indices(sk, "right")
    for lab, c in database:
        f = _hold_frame(c)
        pose = mirror_pose(finger_curves(c.slice(f, f + 1), fj).values.reshape(15, 3))
        start = mirror_pose(finger_curves(c.slice(0, 1), fj).values.reshape(15, 3))
        assert np.abs(start - relaxed_pose()).max() < 12, c.name
        tips = fingertip_positions(pose, sk)
        flex = {g: pose[3 * i:3 * i + 3, 0].sum() for i, g in enumerate(FINGER_NAMES)}
        if lab == "ok":
            assert np.linalg.norm(tips["Thumb4"] - tips["Index4"]) < 1.5, c.name
            assert max(flex["Middle"], flex["Ring"]) < 60
        elif lab == "attention":
            assert flex["Index"] < 20 and min(flex["Middle"], flex["Ring"], flex["Pinky"]) > 180, c.name
        elif lab in ("palm_presentation", "wipe", "big", "doubt_shrug"):
            assert max(flex[g] for g in FINGER_NAMES[1:]) < 65, c.name
        elif lab in ("small", "turn"):
            assert 40 < np.mean([flex[g] for g in FINGER_NAMES[1:]]) < 160, c.name
    # wipe keeps the fingers together, shrug spreads them
    wipe, shrug = gesture_pose("wipe"), gesture_pose("doubt_shrug")
    assert np.abs(wipe[3:, 2]).sum() < np.abs(shrug[3:, 2]).sum() / 3


def test_one_or_two_hands(database):
    sk = humanoid_skeleton()
    for lab, c in database:
        take = int(c.name.rsplit("_", 1)[1])
        w = c.world_positions_cm()[:, sk.index("LeftHand")]
        moving = np.linalg.norm(w - w.mean(axis=0), axis=1).max() > 5
        assert moving == ("left" in gesture_hands(lab, take)), c.name


def test_wrist_motion_predicts_the_type(database):
    """Issue 3's leave-one-out (seed 000 §4) on the database: P + 0.5·R ≥ 80% and best of the single joints."""
    from usdhands.algorithms.synthesis.evaluation import (
        PAPER_PREDICTOR, SINGLE_JOINT_PREDICTORS, evaluate_predictors, prepare_eval_set,
    )

    hm = humanoid_handmap(database[0][1].skeleton)
    es = prepare_eval_set([(lab, c, hm) for lab, c in database])
    res = evaluate_predictors(es, (PAPER_PREDICTOR,) + tuple(SINGLE_JOINT_PREDICTORS), k=5)
    shares = res["predictors"]
    assert shares[PAPER_PREDICTOR] >= 0.80
    assert all(shares[PAPER_PREDICTOR] > shares[p] for p in SINGLE_JOINT_PREDICTORS)
    assert shares[PAPER_PREDICTOR] < 0.98  # realistic: types are not trivially identical
    assert shares["wrist_rot"] < shares[PAPER_PREDICTOR] and res["chance"] < 0.2
    # the paper segments most takes into 3 phases
    counts = np.bincount(es.seg_clip[es.seg_side == 1])
    assert np.mean((counts >= 2) & (counts <= 4)) > 0.85


def test_body_only(database):
    c = database[0][1]
    b = body_only(c)
    sk = c.skeleton
    fj = finger_joint_indices(sk, "left", True) + finger_joint_indices(sk, "right", True)
    other = [j for j in range(sk.num_joints) if j not in fj]
    assert b.name == c.name + "_bodyonly"
    assert np.array_equal(b.rotations[:, other], c.rotations[:, other])
    assert np.allclose(b.rotations[:, fj], sk.rest_rotations[fj][None])
    assert np.abs(c.rotations[:, fj] - sk.rest_rotations[fj][None]).max() > 0.1
    no_fingers = sk.subset([j for j in other])
    from usdhands.model import Clip
    with pytest.raises(ValueError, match="No finger joints found in skeleton 'Humanoid'"):
        body_only(Clip(no_fingers, 30.0, no_fingers.rest_rotations[None]))


def test_conversation():
    c = conversation_clip()
    spans = conversation_annotations()
    assert 20 <= c.duration <= 30 and c.fps == FPS
    assert {s.gesture for s in spans} == set(GESTURE_TYPES)
    assert all(a.end <= b.start for a, b in zip(spans[:-1], spans[1:]))
    assert spans[-1].end <= c.duration + 1e-6
    sk = c.skeleton
    # ground-truth fingers move: the ok gesture closes the ring in its span
    ok = next(s for s in spans if s.gesture == "ok")
    fj = finger_joint_indices(sk, "right")
    a, b = int(ok.start * FPS), int(ok.end * FPS)
    d = []
    for f in range(a, b):
        pose = mirror_pose(finger_curves(c.slice(f, f + 1), fj).values.reshape(15, 3))
        t = fingertip_positions(pose, sk)
        d.append(np.linalg.norm(t["Thumb4"] - t["Index4"]))
    assert min(d) < 1.5 and max(d) > 6


# ------------------------------------------------------------------- prop

def test_cup_mesh_and_usd(tmp_path):
    from pxr import Usd, UsdGeom

    from usdhands.formats.usd_validate import usd_compliance_errors
    from usdhands.samples.props import cup_obj_text, cup_usda_text

    m = cup_mesh()
    assert 300 <= len(m.faces) <= 800 and m.is_watertight and m.volume > 0
    assert np.isclose(m.bounds[1, 1], CUP_HEIGHT_CM) and m.bounds[0, 1] == 0
    p = tmp_path / "cup.usda"
    p.write_text(cup_usda_text(m))
    stage = Usd.Stage.Open(str(p))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 0.01 and UsdGeom.GetStageUpAxis(stage) == "Y"
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Cup/Geom"))
    pts = np.asarray(mesh.GetPointsAttr().Get())
    assert np.allclose(pts, m.vertices, atol=1e-3)
    assert np.array_equal(np.asarray(mesh.GetFaceVertexIndicesAttr().Get()), m.faces.reshape(-1))
    assert usd_compliance_errors(p) == []
    import trimesh
    o = tmp_path / "cup.obj"
    o.write_text(cup_obj_text(m))
    back = trimesh.load(o, process=False)
    assert len(back.faces) == len(m.faces) and np.allclose(back.vertices, m.vertices, atol=1e-4)


# ------------------------------------------------------------------- files

def test_generated_files_round_trip(tmp_path, gltf_validator):
    from usdhands.formats.io import read_asset
    from usdhands.formats.usd_validate import usd_compliance_errors
    from usdhands.samples.generate import generate_samples

    files = generate_samples(tmp_path, only=("humanoid.*", "gestures/ok_00.glb", "gestures_bodyonly/*"))
    names = sorted(f.relative_to(tmp_path).as_posix() for f in files)
    assert names == ["gestures/ok_00.glb", "gestures_bodyonly/attention_03_bodyonly.glb",
                     "gestures_bodyonly/ok_00_bodyonly.usdc", "gestures_bodyonly/turn_05_bodyonly.bvh",
                     "humanoid.bvh", "humanoid.glb", "humanoid.usda"]
    reports = gltf_validator(tmp_path / "humanoid.glb", tmp_path / "gestures/ok_00.glb")
    assert [r["numErrors"] for r in reports] == [0, 0]
    assert usd_compliance_errors(tmp_path / "humanoid.usda") == []
    ref = wave_clip()
    for name in ("humanoid.usda", "humanoid.glb", "humanoid.bvh"):
        a = read_asset(tmp_path / name)
        c = a.clips[0]
        idx = [c.skeleton.index(n) for n in ref.skeleton.short_names]
        assert c.num_frames == ref.num_frames and c.fps == FPS
        assert quat_angle_deg(c.rotations[:, idx], ref.rotations).max() < 1e-3, name
        assert np.abs(c.world_positions_cm()[:, idx] - ref.world_positions_cm()).max() < 1e-3, name
        if not name.endswith(".bvh"):
            mesh = a.meshes[0]
            assert len(mesh.points) == len(humanoid_mesh().points)
            assert (mesh.joint_weights > 0).sum(axis=1).max() == 5
    ok = read_asset(tmp_path / "gestures/ok_00.glb").clips[0]
    truth = gesture_take("ok", 0)
    idx = [ok.skeleton.index(n) for n in truth.skeleton.short_names]
    assert quat_angle_deg(ok.rotations[:, idx], truth.rotations).max() < 1e-3
    bo = read_asset(tmp_path / "gestures_bodyonly/turn_05_bodyonly.bvh").clips[0]
    fj = [bo.skeleton.index(n) for n in ("RightHandIndex1", "RightHandThumb2", "LeftHandPinky3")]
    truth = body_only(gesture_take("turn", 5))
    tj = [truth.skeleton.index(n) for n in ("RightHandIndex1", "RightHandThumb2", "LeftHandPinky3")]
    assert quat_angle_deg(bo.rotations[:, fj], truth.rotations[:, tj]).max() < 1e-3
    assert quat_angle_deg(bo.rotations[:, fj], bo.rotations[:1, fj]).max() < 1e-3  # frozen


_REGENERATED = ["props/*", "humanoid.*", "gestures/labels.csv", "gestures/wipe_07.glb", "conversation.labels.csv",
                "gestures_bodyonly/turn_05_bodyonly.bvh", "interaction/table_rest.glb"]


def _regenerate(folder: Path) -> list[Path]:
    """The committed files of ``_REGENERATED`` written again by a fresh process into ``folder``."""
    code = ("import sys; from usdhands.samples.generate import generate_samples; "
            "generate_samples(sys.argv[1], only=tuple(sys.argv[2:]))")
    subprocess.run([sys.executable, "-c", code, str(folder), *_REGENERATED], check=True)
    return sorted(p.relative_to(folder) for p in folder.rglob("*") if p.is_file())


def test_regenerated_twice_byte_identical(tmp_path):
    """Two fresh processes on one machine write the same bytes."""
    first, second = _regenerate(tmp_path / "a"), _regenerate(tmp_path / "b")
    assert first == second and len(first) == 12
    for rel in first:
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes(), rel


def test_regenerated_match_committed(tmp_path):
    """A fresh process regenerates the committed files: byte for byte where this machine's arithmetic is
    the committing machine's, otherwise the same text, structure and integers with every number equal to
    within its last bits (OpenBLAS's kernel and NumPy's SIMD functions are chosen by CPU: on an AMD EPYC
    with AVX-512, OpenBLAS's default kernel and its SkylakeX kernel, which reproduces the committed files,
    differ in the 16th digit of some rest-pose products)."""
    committed = ROOT / "sample_assets"
    if not (committed / "humanoid.usda").is_file():
        pytest.skip("sample_assets/ not generated")
    files = _regenerate(tmp_path)
    assert len(files) == 12
    for rel in files:
        assert_same_sample(tmp_path / rel, committed / rel)


_NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?\b(?:nan|inf)\b")


def _close(a, b, rtol: float, atol: float) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and bool(np.all(np.isclose(a, b, rtol=rtol, atol=atol, equal_nan=True)))


def _same_content(a, b, path: str) -> None:
    """Dataclasses, sequences, dicts and arrays of two readings equal: integers, text and shapes exactly,
    floats to 1e-6 relative / 1e-9 absolute, quaternions (fields named ``*rotations``) up to sign."""
    import dataclasses

    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), path
        for f in dataclasses.fields(a):
            if f.name not in ("path", "_index"):
                _same_content(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _same_content(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _same_content(x, y, f"{path}[{i}]")
    elif isinstance(a, np.ndarray) and a.dtype.kind == "f":
        assert isinstance(b, np.ndarray) and a.shape == b.shape, path
        if path.endswith("rotations") and a.shape[-1:] == (4,):
            flip = np.sum(a * b, axis=-1, keepdims=True) < 0
            b = np.where(flip, -b, b)
        assert _close(a, b, 1e-6, 1e-9), (path, float(np.max(np.abs(a - b))))
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and np.array_equal(a, b), path
    elif isinstance(a, float):
        assert _close(a, b, 1e-9, 1e-12), (path, a, b)
    else:
        assert a == b, (path, a, b)


def assert_same_sample(new: Path, old: Path) -> None:
    """``new`` holds what ``old`` holds: identical bytes; or else the same text with its numbers replaced
    (JSON keys and structure for GLB) and, read by usdhands, the same skeletons, clips and meshes to
    1e-6 relative / 1e-9 absolute (quaternions up to sign: a BVH angle of 0 can come out as 360); other
    text files (OBJ, CSV) the same text with numbers equal to that tolerance."""
    a, b = new.read_bytes(), old.read_bytes()
    if a == b:
        return
    if new.suffix == ".glb":
        import json
        import struct

        def doc(data: bytes) -> dict:
            return json.loads(data[20:20 + struct.unpack_from("<I", data, 12)[0]])

        def shape(x):
            if isinstance(x, dict):
                return {k: shape(v) for k, v in x.items()}
            if isinstance(x, list):
                return [shape(v) for v in x]
            return x if isinstance(x, (str, bool, int)) and not isinstance(x, float) else "number"

        da, db_ = doc(a), doc(b)
        for view in (*da.get("accessors", []), *db_.get("accessors", [])):
            view.pop("min", None), view.pop("max", None)
        assert shape(da) == shape(db_), f"{old.name}: structure differs"
    else:
        assert _NUMBER.split(a) == _NUMBER.split(b), f"{old.name}: text differs"
    if new.suffix in (".glb", ".usda", ".usdc", ".bvh"):
        from usdhands.formats.io import read_asset

        _same_content(read_asset(new), read_asset(old), old.name)
        return
    num_a, num_b = _NUMBER.findall(a), _NUMBER.findall(b)
    assert _close([float(x) for x in num_a], [float(x) for x in num_b], 1e-6, 1e-9), f"{old.name}: numbers differ"


def test_same_sample_comparison_catches_changes(tmp_path):
    """The comparison above fails on a changed number, a changed word, a changed index and a changed
    float32 value, and passes a last-bit change."""
    committed = ROOT / "sample_assets"
    if not (committed / "humanoid.usda").is_file():
        pytest.skip("sample_assets/ not generated")
    import json
    import struct

    def variant(src: Path, name: str, edit) -> Path:
        out = tmp_path / name
        out.write_bytes(edit(src.read_bytes()))
        return out

    usda, glb = committed / "humanoid.usda", committed / "gestures" / "wipe_07.glb"
    text = usda.read_bytes()
    m = re.search(rb"\b\d\.\d{3,}", text)
    value = float(m.group())
    for new, ok in (((value * (1 + 1e-12)), True), (value * 1.001, False)):
        edited = variant(usda, f"n{ok}.usda", lambda d: d[:m.start()] + repr(new).encode() + d[m.end():])
        if ok:
            assert_same_sample(edited, usda)
        else:
            with pytest.raises(AssertionError):
                assert_same_sample(edited, usda)
    with pytest.raises(AssertionError):
        assert_same_sample(variant(usda, "w.usda", lambda d: d.replace(b"Skeleton", b"Skeletom", 1)), usda)

    data = glb.read_bytes()
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + n])
    f32_at = 20 + n + 8 + doc["bufferViews"][doc["accessors"][2]["bufferView"]].get("byteOffset", 0) + 16
    x = np.frombuffer(data, "<f4", 1, f32_at)[0]
    for new, ok in ((np.nextafter(x, np.float32(2)), True), (x + np.float32(0.01), False)):
        edited = variant(glb, f"b{ok}.glb", lambda d: d[:f32_at] + np.float32(new).tobytes() + d[f32_at + 4:])
        if ok:
            assert_same_sample(edited, glb)
        else:
            with pytest.raises(AssertionError):
                assert_same_sample(edited, glb)
    with pytest.raises(AssertionError):  # a node's child index: an integer of the JSON
        assert b'"children":[1,' in data
        assert_same_sample(variant(glb, "c.glb", lambda d: d.replace(b'"children":[1,', b'"children":[2,', 1)), glb)


def test_committed_set_is_small_and_labelled():
    committed = ROOT / "sample_assets"
    if not (committed / "humanoid.usda").is_file():
        pytest.skip("sample_assets/ not generated")
    total = sum(p.stat().st_size for p in committed.rglob("*") if p.is_file())
    assert total < 15e6
    takes = sorted(p.name for p in (committed / "gestures").glob("*.glb"))
    assert len(takes) == 64
    labels = {re.match(r"^([a-z_]+)_\d+", t).group(1) for t in takes}
    assert labels == set(GESTURE_TYPES)
    rows = (committed / "gestures/labels.csv").read_text().splitlines()
    assert rows[0] == "file,label,take,hands" and len(rows) == 1 + 8 * TAKES_PER_TYPE


def test_cli_samples(tmp_path, capsys):
    out = tmp_path / "out"
    assert cli_main(["samples", str(out), "--formats", "bvh"]) == 0
    table = capsys.readouterr().out
    assert "conversation_bodyonly.bvh" in table and "total" in table
    assert len(list((out / "gestures").glob("*.bvh"))) == 64  # the database goes in the one format asked
    assert (out / "props/cup.obj").is_file() and not (out / "props/cup.usda").exists()
    assert cli_main(["samples", str(out), "--formats", "usd,fbx"]) == 2
    assert "unknown value(s) ['fbx']" in capsys.readouterr().err
    assert cli_main(["samples", str(tmp_path / "missing" / "x")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_usd_skinning_matches_linear_blend(tmp_path):
    """UsdSkel's own skinning of humanoid.usda equals linear blend skinning of the in-memory rig."""
    from pxr import Usd, UsdGeom, UsdSkel

    from usdhands.samples.generate import generate_samples

    path = generate_samples(tmp_path, formats=("usd",), only=("humanoid.usda",))[0]
    stage = Usd.Stage.Open(str(path))
    assert UsdSkel.BakeSkinning(stage.Traverse())
    prim = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    clip = wave_clip()
    mesh = humanoid_mesh(clip.skeleton)
    skin = clip.world_xforms() @ np.linalg.inv(clip.skeleton.bind_xforms)[None]
    P = np.concatenate([mesh.points, np.ones((len(mesh.points), 1))], axis=1)
    for f in (0, 45, 80):
        baked = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(Usd.TimeCode(f)))
        lbs = sum(mesh.joint_weights[:, k, None] * np.einsum("vij,vj->vi", skin[f, mesh.joint_indices[:, k]], P)[:, :3]
                  for k in range(mesh.joint_indices.shape[1]))
        assert np.abs(baked - lbs).max() < 1e-3
    assert np.abs(lbs - mesh.points).max() > 30  # the wave moves the arm

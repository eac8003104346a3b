"""Hand detection on every naming convention, on real rigs, and the JSON override."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from usdhands.errors import ConfigError, NoHandsError
from usdhands.model import Skeleton
from usdhands.model.hand_detection import detect_hands, joint_tokens, load_handmap, resolve_handmap

ROOT = Path(__file__).resolve().parent.parent


def make_skeleton(pairs, name="Skeleton"):
    """A skeleton from ``[(joint, parent or None), ...]`` (parents listed first)."""
    names = [n for n, _ in pairs]
    parents = [-1 if p is None else names.index(p) for _, p in pairs]
    J = len(names)
    return Skeleton(names, parents, np.zeros((J, 3)), np.tile([0, 0, 0, 1.0], (J, 1)), name=name)


def arm(side_names, fingers, end=None):
    """Pairs for wrist + finger chains: fingers maps finger → list of names (chain order)."""
    pairs = []
    for prev, n in zip([None] + side_names[:-1], side_names):
        pairs.append((n, prev))
    wrist = side_names[-1]
    for chain in fingers:
        parent = wrist
        for n in chain:
            pairs.append((n, parent))
            parent = n
        if end:
            pairs.append((end(chain[-1]), parent))
    return pairs


def chains(hand):
    return {f: list(v) for f, v in hand.fingers.items()}


# -- conventions ---------------------------------------------------------------------

def mixamo(ns="mixamorig:"):
    pairs = [(f"{ns}Hips", None), (f"{ns}Spine", f"{ns}Hips"),
             (f"{ns}LeftUpLeg", f"{ns}Hips"), (f"{ns}LeftLeg", f"{ns}LeftUpLeg"),
             (f"{ns}LeftFoot", f"{ns}LeftLeg"), (f"{ns}LeftToeBase", f"{ns}LeftFoot")]
    for S in ("Left", "Right"):
        pairs += [(f"{ns}{S}Shoulder", f"{ns}Spine"), (f"{ns}{S}Arm", f"{ns}{S}Shoulder"),
                  (f"{ns}{S}ForeArm", f"{ns}{S}Arm"), (f"{ns}{S}Hand", f"{ns}{S}ForeArm")]
        for F in ("Thumb", "Index", "Middle", "Ring", "Pinky"):
            parent = f"{ns}{S}Hand"
            for k in range(1, 5):
                pairs.append((f"{ns}{S}Hand{F}{k}", parent))
                parent = f"{ns}{S}Hand{F}{k}"
    return make_skeleton(pairs)


def test_mixamo_with_namespace():
    hm = detect_hands(mixamo())
    for S, hand in (("Left", hm.left), ("Right", hm.right)):
        assert hand.wrist == f"mixamorig:{S}Hand"
        assert hand.forearm == f"mixamorig:{S}ForeArm"
        assert hand.shoulder == f"mixamorig:{S}Arm"
        assert hand.root == "mixamorig:Hips"
        assert chains(hand) == {F.lower(): [f"mixamorig:{S}Hand{F}{k}" for k in (1, 2, 3)]
                                for F in ("Thumb", "Index", "Middle", "Ring", "Pinky")}


def test_usd_paths_use_full_names():
    sk = mixamo(ns="")
    paths = []
    for j, n in enumerate(sk.joint_names):
        p = sk.parents[j]
        paths.append(n if p < 0 else paths[p] + "/" + n)
    sk2 = Skeleton(paths, sk.parents, sk.rest_translations, sk.rest_rotations)
    hm = detect_hands(sk2)
    assert hm.left.wrist == "Hips/Spine/LeftShoulder/LeftArm/LeftForeArm/LeftHand"
    assert hm.left.fingers["index"][0] == "Hips/Spine/LeftShoulder/LeftArm/LeftForeArm/LeftHand/LeftHandIndex1"


def test_ue5_metacarpals():
    pairs = [("root", None), ("pelvis", "root"), ("spine_01", "pelvis")]
    for s in ("l", "r"):
        pairs += [(f"clavicle_{s}", "spine_01"), (f"upperarm_{s}", f"clavicle_{s}"),
                  (f"lowerarm_{s}", f"upperarm_{s}"), (f"lowerarm_twist_01_{s}", f"lowerarm_{s}"),
                  (f"hand_{s}", f"lowerarm_{s}"), (f"ik_hand_{s}", "root")]
        parent = f"hand_{s}"
        for k in (1, 2, 3):
            pairs.append((f"thumb_0{k}_{s}", parent))
            parent = f"thumb_0{k}_{s}"
        for F in ("index", "middle", "ring", "pinky"):
            pairs.append((f"{F}_metacarpal_{s}", f"hand_{s}"))
            parent = f"{F}_metacarpal_{s}"
            for k in (1, 2, 3):
                pairs.append((f"{F}_0{k}_{s}", parent))
                parent = f"{F}_0{k}_{s}"
    hm = detect_hands(make_skeleton(pairs))
    assert (hm.right.wrist, hm.right.forearm, hm.right.shoulder, hm.right.root) == \
        ("hand_r", "lowerarm_r", "upperarm_r", "pelvis")
    assert chains(hm.left) == {
        "thumb": ["thumb_01_l", "thumb_02_l", "thumb_03_l"],
        **{F: [f"{F}_metacarpal_l", f"{F}_01_l", f"{F}_02_l", f"{F}_03_l"]
           for F in ("index", "middle", "ring", "pinky")}}


@pytest.mark.parametrize("vrm1", [False, True])
def test_unity_vrm(vrm1):
    pairs = [("hips", None), ("spine", "hips")]
    for s in ("left", "right"):
        pairs += [(f"{s}Shoulder", "spine"), (f"{s}UpperArm", f"{s}Shoulder"),
                  (f"{s}LowerArm", f"{s}UpperArm"), (f"{s}Hand", f"{s}LowerArm")]
        segs = {"Thumb": ["Metacarpal", "Proximal", "Distal"] if vrm1 else ["Proximal", "Intermediate", "Distal"]}
        for F in ("Thumb", "Index", "Middle", "Ring", "Little"):
            parent = f"{s}Hand"
            for seg in segs.get(F, ["Proximal", "Intermediate", "Distal"]):
                pairs.append((f"{s}{F}{seg}", parent))
                parent = f"{s}{F}{seg}"
    hm = detect_hands(make_skeleton(pairs))
    assert hm.left.shoulder == "leftUpperArm" and hm.left.forearm == "leftLowerArm"
    thumb = ["Metacarpal", "Proximal", "Distal"] if vrm1 else ["Proximal", "Intermediate", "Distal"]
    assert chains(hm.right)["thumb"] == [f"rightThumb{s}" for s in thumb]
    assert chains(hm.right)["pinky"] == [f"rightLittle{s}" for s in ("Proximal", "Intermediate", "Distal")]
    assert chains(hm.right)["middle"] == [f"rightMiddle{s}" for s in ("Proximal", "Intermediate", "Distal")]


def test_smplx_order_in_file():
    pairs = [("pelvis", None), ("spine1", "pelvis"), ("left_hip", "pelvis"), ("left_knee", "left_hip")]
    for s in ("left", "right"):
        pairs += [(f"{s}_collar", "spine1"), (f"{s}_shoulder", f"{s}_collar"),
                  (f"{s}_elbow", f"{s}_shoulder"), (f"{s}_wrist", f"{s}_elbow")]
    for s in ("left", "right"):
        for F in ("index", "middle", "pinky", "ring", "thumb"):
            parent = f"{s}_wrist"
            for k in (1, 2, 3):
                pairs.append((f"{s}_{F}{k}", parent))
                parent = f"{s}_{F}{k}"
    hm = detect_hands(make_skeleton(pairs))
    h = hm.left
    assert (h.wrist, h.forearm, h.shoulder, h.root) == ("left_wrist", "left_elbow", "left_shoulder", "pelvis")
    assert chains(h) == {F: [f"left_{F}{k}" for k in (1, 2, 3)] for F in ("thumb", "index", "middle", "ring", "pinky")}


def test_humanik_in_hand_metacarpals_and_foot_fingers():
    pairs = [("Hips", None), ("Spine", "Hips"), ("LeftUpLeg", "Hips"), ("LeftLeg", "LeftUpLeg"),
             ("LeftFoot", "LeftLeg"), ("LeftToeBase", "LeftFoot"),
             ("LeftFootIndex1", "LeftFoot"), ("LeftFootIndex2", "LeftFootIndex1"),
             ("LeftShoulder", "Spine"), ("LeftArm", "LeftShoulder"), ("LeftForeArm", "LeftArm"),
             ("LeftHand", "LeftForeArm")]
    for F in ("Thumb", "Index", "Middle", "Ring", "Pinky"):
        pairs.append((f"LeftInHand{F}", "LeftHand"))
        parent = f"LeftInHand{F}"
        for k in range(1, 5):
            pairs.append((f"LeftHand{F}{k}", parent))
            parent = f"LeftHand{F}{k}"
    hm = detect_hands(make_skeleton(pairs))
    assert hm.right is None
    assert chains(hm.left) == {F.lower(): [f"LeftInHand{F}"] + [f"LeftHand{F}{k}" for k in (1, 2, 3)]
                               for F in ("Thumb", "Index", "Middle", "Ring", "Pinky")}


def test_rokoko_finger_numbers():
    pairs = [("Hips", None), ("Spine", "Hips")]
    for S in ("Left", "Right"):
        pairs += [(f"{S}Shoulder", "Spine"), (f"{S}Arm", f"{S}Shoulder"), (f"{S}ForeArm", f"{S}Arm"),
                  (f"{S}Hand", f"{S}ForeArm")]
        for n in range(1, 6):
            segs = ["Metacarpal", "Proximal", "Distal", "Tip"] if n == 1 else \
                ["Metacarpal", "Proximal", "Medial", "Distal", "Tip"]
            parent = f"{S}Hand"
            for seg in segs:
                pairs.append((f"{S}Finger{n}{seg}", parent))
                parent = f"{S}Finger{n}{seg}"
    hm = detect_hands(make_skeleton(pairs))
    c = chains(hm.right)
    assert c["thumb"] == ["RightFinger1Metacarpal", "RightFinger1Proximal", "RightFinger1Distal"]
    assert c["index"] == [f"RightFinger2{s}" for s in ("Metacarpal", "Proximal", "Medial", "Distal")]
    assert c["pinky"] == [f"RightFinger5{s}" for s in ("Metacarpal", "Proximal", "Medial", "Distal")]
    assert hm.right.shoulder == "RightArm"



def test_3dsmax_biped_counts_fingers_from_zero():
    pairs = [("Bip01", None), ("Bip01 Pelvis", "Bip01"), ("Bip01 Spine", "Bip01 Pelvis")]
    for S in ("L", "R"):
        pairs += [(f"Bip01 {S} Clavicle", "Bip01 Spine"), (f"Bip01 {S} UpperArm", f"Bip01 {S} Clavicle"),
                  (f"Bip01 {S} Forearm", f"Bip01 {S} UpperArm"), (f"Bip01 {S} Hand", f"Bip01 {S} Forearm")]
        for n in range(5):
            names = [f"Bip01 {S} Finger{n}", f"Bip01 {S} Finger{n}1", f"Bip01 {S} Finger{n}2"]
            pairs += [(names[0], f"Bip01 {S} Hand"), (names[1], names[0]), (names[2], names[1]),
                      (f"Bip01 {S} Finger{n}Nub", names[2])]
    hm = detect_hands(make_skeleton(pairs))
    h = hm.right
    assert (h.wrist, h.forearm, h.shoulder, h.root) == ("Bip01 R Hand", "Bip01 R Forearm", "Bip01 R UpperArm",
                                                        "Bip01 Pelvis")
    assert chains(h) == {f: [f"Bip01 R Finger{n}", f"Bip01 R Finger{n}1", f"Bip01 R Finger{n}2"]
                         for n, f in enumerate(("thumb", "index", "middle", "ring", "pinky"))}


def test_makehuman_numbers_and_shared_carpal():
    # MakeHuman: finger1-1.L (thumb) ...; metacarpal1.L under the hand carries index AND middle here,
    # so it is shared and stays out of both chains; metacarpal3.L carries the ring only
    pairs = [("root", None), ("upperarm01.L", "root"), ("lowerarm01.L", "upperarm01.L"), ("wrist.L", "lowerarm01.L"),
             ("metacarpal1.L", "wrist.L"), ("metacarpal3.L", "wrist.L"), ("metacarpal4.L", "wrist.L")]
    parent_of = {1: "wrist.L", 2: "metacarpal1.L", 3: "metacarpal1.L", 4: "metacarpal3.L", 5: "metacarpal4.L"}
    for n in range(1, 6):
        parent = parent_of[n]
        for k in (1, 2, 3):
            pairs.append((f"finger{n}-{k}.L", parent))
            parent = f"finger{n}-{k}.L"
    hm = detect_hands(make_skeleton(pairs))
    c = chains(hm.left)
    assert hm.right is None and hm.left.wrist == "wrist.L" and hm.left.forearm == "lowerarm01.L"
    assert hm.left.shoulder == "upperarm01.L" and hm.left.root == "root"
    assert c["thumb"] == ["finger1-1.L", "finger1-2.L", "finger1-3.L"]
    assert c["index"] == ["finger2-1.L", "finger2-2.L", "finger2-3.L"]
    assert c["ring"] == ["metacarpal3.L", "finger4-1.L", "finger4-2.L", "finger4-3.L"]
    assert c["pinky"] == ["metacarpal4.L", "finger5-1.L", "finger5-2.L", "finger5-3.L"]


def test_daz_genesis_shared_carpals_and_twist_joints():
    pairs = [("hip", None), ("pelvis", "hip"), ("lThighBend", "pelvis"), ("abdomenLower", "hip"),
             ("chestUpper", "abdomenLower"), ("lCollar", "chestUpper"), ("lShldrBend", "lCollar"),
             ("lShldrTwist", "lShldrBend"), ("lForearmBend", "lShldrTwist"), ("lForearmTwist", "lForearmBend"),
             ("lHand", "lForearmTwist"), ("lThumb1", "lHand"), ("lThumb2", "lThumb1"), ("lThumb3", "lThumb2"),
             ("lCarpal1", "lHand"), ("lCarpal2", "lHand")]
    for F, carpal in (("Index", "lCarpal1"), ("Mid", "lCarpal1"), ("Ring", "lCarpal2"), ("Pinky", "lCarpal2")):
        pairs += [(f"l{F}1", carpal), (f"l{F}2", f"l{F}1"), (f"l{F}3", f"l{F}2")]
    hm = detect_hands(make_skeleton(pairs))
    h = hm.left
    assert (h.wrist, h.forearm, h.shoulder, h.root) == ("lHand", "lForearmBend", "lShldrBend", "hip")
    assert chains(h) == {f: [f"l{F}{k}" for k in (1, 2, 3)] for f, F in
                         zip(("thumb", "index", "middle", "ring", "pinky"), ("Thumb", "Index", "Mid", "Ring", "Pinky"))}


def test_helper_joint_inside_a_finger_and_a_stray_hand_named_joint():
    pairs = robot_pairs() + [("HandProp.L", "Torso")]  # wristless rig + a "hand" joint the fingers are not under
    pairs = [(n, p) if n != "Index2.L" else ("Index2.L", "Index.L_twist") for n, p in pairs]
    pairs.insert([n for n, _ in pairs].index("Index2.L"), ("Index.L_twist", "Index.L"))
    hm = detect_hands(make_skeleton(pairs))
    assert hm.left.wrist == "LowerArm.L"
    assert chains(hm.left)["index"] == ["Palm1.L", "Index.L", "Index2.L"]

WEBXR = ["wrist", "thumb-metacarpal", "thumb-phalanx-proximal", "thumb-phalanx-distal", "thumb-tip"] + [
    f"{F}-finger-{s}" for F in ("index", "middle", "ring", "pinky")
    for s in ("metacarpal", "phalanx-proximal", "phalanx-intermediate", "phalanx-distal", "tip")]


def webxr_expected():
    return {"thumb": ["thumb-metacarpal", "thumb-phalanx-proximal", "thumb-phalanx-distal"],
            **{F: [f"{F}-finger-{s}" for s in ("metacarpal", "phalanx-proximal", "phalanx-intermediate",
                                              "phalanx-distal")] for F in ("index", "middle", "ring", "pinky")}}


def test_webxr_hierarchical_with_side_hint():
    pairs = [("wrist", None)]
    for n in WEBXR[1:]:
        first = n.endswith("metacarpal")
        pairs.append((n, "wrist" if first else pairs[-1][0]))
    sk = make_skeleton(pairs)
    hm = detect_hands(sk, side_hint="left")
    assert hm.right is None and hm.left.wrist == "wrist" and hm.left.forearm is None and hm.left.root is None
    assert chains(hm.left) == webxr_expected()


def test_webxr_flat_reversed_order_side_from_skeleton_name():
    sk = make_skeleton([(n, None) for n in reversed(WEBXR)], name="/right_hand/Armature")
    hm = detect_hands(sk)
    assert hm.left is None and hm.right.wrist == "wrist"
    assert chains(hm.right) == webxr_expected()


def test_sideless_hand_without_hint_says_so():
    sk = make_skeleton([(n, None) for n in WEBXR], name="hand")
    with pytest.raises(NoHandsError, match=r"finger joints were found but their names give no side: "
                                            r"pass side_hint 'left' or 'right'"):
        detect_hands(sk)


@pytest.mark.parametrize("fmt", ["L_{F}{k}", "{f}{k}.L", "{F}{k}_L", "l{F}{k}"])
def test_generic_names(fmt):
    side = {"L_{F}{k}": ("L_Hand", "L_ForeArm"), "{f}{k}.L": ("hand.L", "forearm.L"),
            "{F}{k}_L": ("Hand_L", "ForeArm_L"), "l{F}{k}": ("lHand", "lForeArm")}[fmt]
    fingers = [[fmt.format(F=F, f=F.lower(), k=k) for k in (1, 2, 3)]
               for F in ("Thumb", "Index", "Middle", "Ring", "Pinky")]
    pairs = arm(["Pelvis", side[1], side[0]], fingers, end=lambda n: n + "_end")
    pairs.append(("LeftToeBase", "Pelvis"))
    hm = detect_hands(make_skeleton(pairs))
    assert hm.right is None
    assert hm.left.wrist == side[0] and hm.left.forearm == side[1] and hm.left.root == "Pelvis"
    assert chains(hm.left) == dict(zip(("thumb", "index", "middle", "ring", "pinky"), fingers))


def test_leap_names():
    fingers = [[f"r{F}{k}" for k in (1, 2, 3)] for F in ("Thumb", "Index", "Mid", "Ring", "Pinky")]
    hm = detect_hands(make_skeleton(arm(["rForeArm", "rHand"], fingers, end=lambda n: n + "_end")))
    assert hm.left is None
    assert (hm.right.wrist, hm.right.forearm, hm.right.shoulder, hm.right.root) == \
        ("rHand", "rForeArm", None, "rForeArm")
    assert chains(hm.right) == dict(zip(("thumb", "index", "middle", "ring", "pinky"), fingers))


def robot_pairs():
    pairs = [("Bone", None), ("Body", "Bone"), ("Hips", "Body"), ("Abdomen", "Hips"), ("Torso", "Abdomen")]
    for s in ("L", "R"):
        pairs += [(f"Shoulder.{s}", "Torso"), (f"UpperArm.{s}", f"Shoulder.{s}"),
                  (f"LowerArm.{s}", f"UpperArm.{s}"),
                  (f"Palm2.{s}", f"LowerArm.{s}"), (f"Middle1.{s}", f"Palm2.{s}"), (f"Middle2.{s}", f"Middle1.{s}"),
                  (f"Thumb.{s}", f"LowerArm.{s}"), (f"Thumb2.{s}", f"Thumb.{s}"),
                  (f"Palm1.{s}", f"LowerArm.{s}"), (f"Index.{s}", f"Palm1.{s}"), (f"Index2.{s}", f"Index.{s}"),
                  (f"Palm3.{s}", f"LowerArm.{s}"), (f"Ring1.{s}", f"Palm3.{s}"), (f"Ring2.{s}", f"Ring1.{s}")]
    pairs += [("UpperLeg.L", "Body"), ("Foot.L", "Bone"), ("PoleTarget.L", "Bone")]
    return pairs


def robot_expected(s):
    return {"thumb": [f"Thumb.{s}", f"Thumb2.{s}"], "index": [f"Palm1.{s}", f"Index.{s}", f"Index2.{s}"],
            "middle": [f"Palm2.{s}", f"Middle1.{s}", f"Middle2.{s}"],
            "ring": [f"Palm3.{s}", f"Ring1.{s}", f"Ring2.{s}"], "pinky": []}


def check_robot(hm):
    for s, hand in (("L", hm.left), ("R", hm.right)):
        assert (hand.wrist, hand.forearm, hand.shoulder, hand.root) == \
            (f"LowerArm.{s}", f"UpperArm.{s}", f"Shoulder.{s}", "Hips")
        assert chains(hand) == robot_expected(s)


def test_robot_without_hand_joint_synthetic():
    check_robot(detect_hands(make_skeleton(robot_pairs())))


def test_wristless_rig_ignores_finger_words_in_the_head():
    pairs = robot_pairs() + [("Neck", "Torso"), ("Head", "Neck"), ("EarRing.L", "Head"), ("Pinky.L", "EarRing.L")]
    check_robot(detect_hands(make_skeleton(pairs)))


def test_no_hands_lists_joints_and_what_was_looked_for():
    names = [("Hips", None)] + [(f"Bone{k:02d}", "Hips" if k == 0 else f"Bone{k - 1:02d}") for k in range(44)]
    with pytest.raises(NoHandsError) as e:
        detect_hands(make_skeleton(names, name="Body"))
    msg = str(e.value)
    assert msg.startswith("no hand found in skeleton 'Body'; looked for finger joints named thumb, index")
    assert "saw 45 joints: Hips, Bone00, Bone01" in msg
    assert msg.endswith("Bone37, Bone38 (and 5 more)")


def test_side_from_name():
    from usdhands.model.hand_detection import side_from_name

    assert side_from_name("left.glb") == "left" and side_from_name("webxr/right.glb") == "right"
    assert side_from_name("hand_L.usd") == "left" and side_from_name("LR.bvh") is None
    assert side_from_name("/CesiumMan/Skeleton") is None and side_from_name("left_right.bvh") is None


def test_tokens():
    assert joint_tokens("mixamorig:LeftHandIndex1") == ["left", "hand", "index", "1"]
    assert joint_tokens("Root/Hips/index_metacarpal_l") == ["index", "metacarpal", "l"]
    assert joint_tokens("rMid1") == ["r", "mid", "1"]
    assert joint_tokens("LIndex1") == ["l", "index", "1"]


# -- JSON override -------------------------------------------------------------------

def test_schema_copies_identical():
    a = (ROOT / "schemas" / "handmap.schema.json").read_bytes()
    b = (ROOT / "usdhands" / "schemas" / "handmap.schema.json").read_bytes()
    assert a == b


def test_handmap_json_round_trip(tmp_path):
    sk = mixamo()
    hm = detect_hands(sk)
    p = tmp_path / "map.json"
    p.write_text(json.dumps(hm.to_dict()))
    assert load_handmap(p, sk) == hm
    assert resolve_handmap(sk, p) == hm
    assert resolve_handmap(sk) == hm


def test_handmap_short_names_become_full(tmp_path):
    sk = make_skeleton([("ns:Hips", None), ("ns:Hand", "ns:Hips"), ("ns:Thumb1", "ns:Hand")])
    paths = Skeleton(["Hips", "Hips/Hand", "Hips/Hand/Thumb1"], sk.parents, sk.rest_translations,
                     sk.rest_rotations)
    p = tmp_path / "map.json"
    p.write_text(json.dumps({"right": {"wrist": "Hand", "fingers": {"thumb": ["Thumb1"]}}}))
    hm = load_handmap(p, paths)
    assert hm.left is None and hm.right.wrist == "Hips/Hand" and hm.right.fingers["thumb"] == ("Hips/Hand/Thumb1",)


def test_handmap_bad_joint_exact_error(tmp_path):
    sk = mixamo()
    d = detect_hands(sk).to_dict()
    d["left"]["fingers"]["ring"][1] = "mixamorig:LeftHandRing9"
    p = tmp_path / "map.json"
    p.write_text(json.dumps(d))
    with pytest.raises(ConfigError) as e:
        load_handmap(p, sk)
    assert str(e.value) == f"{p}: left ring finger: joint 'mixamorig:LeftHandRing9' is not in skeleton 'Skeleton'"


def test_handmap_schema_violation_exact_error(tmp_path):
    p = tmp_path / "map.json"
    p.write_text(json.dumps({"left": {"wrist": "LeftHand", "fingers": {"thumbs": []}}}))
    with pytest.raises(ConfigError) as e:
        load_handmap(p, mixamo())
    assert str(e.value) == (f"{p}: invalid hand map at left/fingers: Additional properties are not allowed "
                            "('thumbs' was unexpected)")


def test_handmap_bad_json(tmp_path):
    p = tmp_path / "map.json"
    p.write_text("{\"left\": ")
    with pytest.raises(ConfigError, match=r"map.json: hand map file is not valid JSON: Expecting value at line 1 column 10"):
        load_handmap(p, mixamo())


# -- real assets -----------------------------------------------------------------------

def test_robot_expressive_glb(shared_assets):
    from usdhands.formats.io import read_asset

    asset = read_asset(shared_assets / "robot_expressive" / "RobotExpressive.glb")
    hm = detect_hands(asset.skeletons[0])
    sk = asset.skeletons[0]
    short = lambda n: sk.short_names[sk.index(n)]  # noqa: E731
    for s, hand in (("L", hm.left), ("R", hm.right)):
        assert tuple(map(short, (hand.wrist, hand.forearm, hand.shoulder, hand.root))) == \
            (f"LowerArm.{s}", f"UpperArm.{s}", f"Shoulder.{s}", "Hips")
        assert {f: [short(j) for j in c] for f, c in hand.fingers.items()} == robot_expected(s)


def test_leap_bvh(shared_assets):
    from usdhands.formats.io import read_asset

    sk = read_asset(shared_assets / "leap_hands" / "gesture-typing.bvh").skeletons[0]
    hm = detect_hands(sk)
    assert hm.left is None
    assert (hm.right.wrist, hm.right.forearm, hm.right.shoulder, hm.right.root) == \
        ("rHand", "rForeArm", None, "rForeArm")
    assert chains(hm.right) == {f: [f"r{F}{k}" for k in (1, 2, 3)] for f, F in
                                zip(("thumb", "index", "middle", "ring", "pinky"),
                                    ("Thumb", "Index", "Mid", "Ring", "Pinky"))}


@pytest.mark.parametrize("side", ["left", "right"])
def test_webxr_glb(shared_assets, side):
    from usdhands.formats.io import read_asset

    sk = read_asset(shared_assets / "webxr_hand" / f"{side}.glb").skeletons[0]
    hm = detect_hands(sk, side_hint=side)
    hand = hm[side]
    other = hm["right" if side == "left" else "left"]
    assert other is None
    assert sk.short_names[sk.index(hand.wrist)] == "wrist"
    assert {f: [sk.short_names[sk.index(j)] for j in c] for f, c in hand.fingers.items()} == webxr_expected()


# -- the command -------------------------------------------------------------------------

def test_handmap_command_writes_json(shared_assets, tmp_path, capsys):
    from usdhands.cli import main

    out = tmp_path / "map.json"
    src = shared_assets / "webxr_hand" / "left.glb"
    assert main(["handmap", str(src), "-o", str(out)]) == 0  # side from the file name
    printed = capsys.readouterr().out
    assert "left   wrist     wrist" in printed and "right  -         (no hand found)" in printed
    data = json.loads(out.read_text())
    assert data["right"] is None
    assert [n.rsplit("/", 1)[-1] for n in data["left"]["fingers"]["thumb"]] == webxr_expected()["thumb"]
    from usdhands.formats.io import read_asset

    sk = read_asset(src).skeletons[0]
    assert load_handmap(out, sk) == detect_hands(sk, side_hint="left")


def test_handmap_command_errors(shared_assets, tmp_path, capsys):
    from usdhands.cli import main

    src = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    assert main(["handmap", str(src), "-o", str(tmp_path / "m.json")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"usdhands: error: {src}: no hand found in skeleton ")
    assert "saw 19 joints: Skeleton_torso_joint_1" in err
    assert not (tmp_path / "m.json").exists()
    bvh = shared_assets / "leap_hands" / "fingers-ok.bvh"
    assert main(["handmap", str(bvh), "-o", str(bvh)]) == 2
    assert "output path equals the input" in capsys.readouterr().err


def test_sideless_finger_names_inherit_the_side_of_their_hand():
    # USD paths make the short names repeat: "Index1" under both hands
    pairs = [("Hips", None), ("Hips/Spine", "Hips")]
    for S in ("Left", "Right"):
        arm_ = f"Hips/Spine/{S}Arm"
        pairs += [(arm_, "Hips/Spine"), (f"{arm_}/{S}ForeArm", arm_), (f"{arm_}/{S}ForeArm/{S}Hand", f"{arm_}/{S}ForeArm"),
                  (f"{arm_}/{S}ForeArm/{S}HandProp", f"{arm_}/{S}ForeArm")]
        for F in ("Thumb", "Index"):
            parent = f"{arm_}/{S}ForeArm/{S}Hand"
            for k in (1, 2):
                pairs.append((f"{parent}/{F}{k}", parent))
                parent = f"{parent}/{F}{k}"
    hm = detect_hands(make_skeleton(pairs))
    base = "Hips/Spine/RightArm/RightForeArm/RightHand"
    assert hm.right.wrist == base  # not the RightHandProp sibling
    assert chains(hm.right)["index"] == [f"{base}/Index1", f"{base}/Index1/Index2"]
    assert chains(hm.left)["thumb"] == ["Hips/Spine/LeftArm/LeftForeArm/LeftHand/Thumb1",
                                        "Hips/Spine/LeftArm/LeftForeArm/LeftHand/Thumb1/Thumb2"]
    assert chains(hm.left)["middle"] == []


def test_sample_humanoid_matches_its_authored_handmap():
    from usdhands.samples.humanoid import humanoid_handmap, humanoid_skeleton

    sk = humanoid_skeleton()
    assert detect_hands(sk) == humanoid_handmap(sk)


def test_hands_for_prefers_override_then_recorded_usd_map_then_detection(tmp_path):
    from usdhands.formats.hands import hands_for
    from usdhands.formats.io import read_asset, write_asset, write_clip
    from usdhands.model import Clip
    from usdhands.model.asset import Asset
    from usdhands.model.handmap import HandMap, HandSide
    from usdhands.samples.humanoid import humanoid_skeleton

    sk = humanoid_skeleton()
    write_asset(Asset("mem", (sk,), (Clip(sk, 30, np.tile(sk.rest_rotations, (3, 1, 1))),)), tmp_path / "h.usda")
    plain = read_asset(tmp_path / "h.usda")
    detected, src = hands_for(tmp_path / "h.usda", plain.skeletons[0])
    assert src == "detected" and detected.right is not None
    custom = HandMap(left=HandSide("left", detected.left.wrist, fingers={"index": detected.left.fingers["index"][:2]}))
    write_clip(tmp_path / "h.usda", plain.clip(), tmp_path / "marked.usda", hand_map=custom)
    marked = read_asset(tmp_path / "marked.usda").skeletons[0]
    assert hands_for(tmp_path / "marked.usda", marked) == (custom, "file")
    js = tmp_path / "map.json"
    js.write_text(json.dumps(detected.to_dict()))
    assert hands_for(tmp_path / "marked.usda", marked, js) == (detected, "override")


def test_hands_for_side_from_file_name_and_error_path(shared_assets):
    from usdhands.formats.hands import hands_for
    from usdhands.formats.io import read_asset

    src = shared_assets / "webxr_hand" / "right.glb"
    hm, how = hands_for(src, read_asset(src).skeletons[0])
    assert how == "detected" and hm.left is None and hm.right is not None
    cesium = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    with pytest.raises(NoHandsError) as e:
        hands_for(cesium, read_asset(cesium).skeletons[0])
    assert str(e.value).startswith(f"{cesium}: no hand found in skeleton ")

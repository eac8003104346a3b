"""``usdhands inspect``: the report's JSON layout on real files."""

from __future__ import annotations

import json

from usdhands.cli import main


def inspect_json(capsys, path) -> dict:
    assert main(["inspect", "--json", str(path)]) == 0
    return json.loads(capsys.readouterr().out)


def test_robot_expressive(shared_assets, capsys):
    d = inspect_json(capsys, shared_assets / "robot_expressive" / "RobotExpressive.glb")
    assert len(d["skeletons"]) == 1 and "Palm1.L" in d["skeletons"][0]["joints"]
    wave = next(a for a in d["animations"] if a["name"] == "Wave")
    assert wave["frames"] > 1 and wave["fps"] > 0
    left = d["hands"]["left"]
    assert left["wrist"] == "LowerArm.L"
    assert left["fingers"]["thumb"] == ["Thumb.L", "Thumb2.L"]
    assert left["fingers"]["ring"] == ["Palm3.L", "Ring1.L", "Ring2.L"]
    assert left["fingers"]["pinky"] == []
    assert d["hands"]["right"]["fingers"]["index"] == ["Palm1.R", "Index.R", "Index2.R"]


def test_leap_bvh_has_only_a_right_hand(shared_assets, capsys):
    d = inspect_json(capsys, shared_assets / "leap_hands" / "fingers-ok.bvh")
    assert d["animations"] == [{"name": "fingers-ok", "skeleton": 0, "frames": 245, "fps": 40.0,
                                "duration": 6.1}]
    assert d["hands"]["left"] is None
    assert d["hands"]["right"]["wrist"] == "rHand"
    assert d["hands"]["right"]["fingers"]["middle"] == ["rMid1", "rMid2", "rMid3"]


def test_webxr_side_from_file_name_and_no_animation(shared_assets, capsys):
    d = inspect_json(capsys, shared_assets / "webxr_hand" / "right.glb")
    assert d["animations"] == [] and d["hands"]["left"] is None
    assert d["hands"]["right"]["fingers"]["thumb"][0] == "thumb-metacarpal"


def test_no_hands_is_null_on_both_sides(shared_assets, capsys):
    d = inspect_json(capsys, shared_assets / "usd_cesiumman" / "CesiumMan.usdz")
    assert d["hands"] == {"left": None, "right": None}
    assert d["skeletons"][0]["num_joints"] == 19
    assert d["animations"][0]["frames"] == 48 and d["animations"][0]["fps"] == 24.0


def test_table_output(shared_assets, capsys):
    assert main(["inspect", str(shared_assets / "leap_hands" / "fingers-ok.bvh")]) == 0
    out = capsys.readouterr().out
    assert "fingers-ok  245     40" in out
    assert "right  rHand  index   rIndex1 rIndex2 rIndex3" in out


def test_commands_use_the_hand_map_a_usd_file_records_and_the_override(tmp_path, capsys):
    """inspect and handmap take --handmap first, then the USD-recorded map, then detection."""
    import numpy as np

    from usdhands.formats.hands import hands_for
    from usdhands.formats.io import read_asset, write_asset, write_clip
    from usdhands.model import Clip
    from usdhands.model.asset import Asset
    from usdhands.model.handmap import HandMap, HandSide
    from usdhands.samples.humanoid import humanoid_skeleton

    sk = humanoid_skeleton()
    plain_path = write_asset(Asset("mem", (sk,), (Clip(sk, 30, np.tile(sk.rest_rotations, (3, 1, 1))),)),
                             tmp_path / "h.usda")
    plain = read_asset(plain_path)
    detected, _ = hands_for(plain_path, plain.skeletons[0])
    two = detected.left.fingers["index"][:2]
    custom = HandMap(left=HandSide("left", detected.left.wrist, fingers={"index": two}))
    marked = write_clip(plain_path, plain.clip(), tmp_path / "marked.usda", hand_map=custom)

    d = inspect_json(capsys, marked)
    assert d["hands"]["right"] is None
    assert d["hands"]["left"]["fingers"]["index"] == list(two)
    assert d["hands"]["left"]["fingers"]["thumb"] == []

    assert main(["handmap", str(marked)]) == 0
    out = capsys.readouterr().out
    assert "hands recorded in the file (UsdHandsHandMapAPI)" in out.splitlines()[0]
    assert "right  -         (no hand found)" in out

    override = tmp_path / "full.json"
    override.write_text(json.dumps(detected.to_dict()))
    assert main(["handmap", str(marked), "--handmap", str(override)]) == 0
    out = capsys.readouterr().out
    assert f"hands from {override}" in out.splitlines()[0]
    assert "right  wrist" in out
    d = json.loads(json.dumps(detected.to_dict()))
    assert main(["inspect", "--json", str(marked), "--handmap", str(override)]) == 0
    assert json.loads(capsys.readouterr().out)["hands"] == d


def test_file_with_two_skeletons_hands_per_skeleton(tmp_path, capsys):
    """handmap --skeleton picks one; inspect reports hands per skeleton and the first found at the top."""
    import numpy as np

    from usdhands.formats.io import write_asset
    from usdhands.model import Clip, Skeleton
    from usdhands.model.asset import Asset
    from usdhands.samples.humanoid import humanoid_skeleton

    prop = Skeleton(["Lid", "Lid/Knob"], [-1, 0], [[0, 0, 0], [0, 1, 0]], np.tile([0, 0, 0, 1.0], (2, 1)), name="Prop")
    body = humanoid_skeleton()
    path = write_asset(Asset("mem", (prop, body), (Clip(prop, 30, np.tile(prop.rest_rotations, (2, 1, 1))),
                                                   Clip(body, 30, np.tile(body.rest_rotations, (2, 1, 1))))),
                       tmp_path / "two.usda")
    assert main(["handmap", str(path)]) == 2  # the first skeleton has no hands
    assert "no hand found in skeleton '/Root/PropRoot/Prop'" in capsys.readouterr().err
    assert main(["handmap", str(path), "--skeleton", "1"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.startswith(f"{path}: skeleton '/Root/") and "65 joints; hands detected" in first
    d = inspect_json(capsys, path)
    assert d["skeletons"][0]["hands"] == {"left": None, "right": None}
    assert d["skeletons"][1]["hands"]["left"]["wrist"].endswith("/LeftHand")
    assert d["hands"] == d["skeletons"][1]["hands"]
    assert [a["skeleton"] for a in d["animations"]] == [0, 1]


def test_file_without_skeleton(shared_assets, capsys):
    teapot = shared_assets / "usd_teapot" / "UtahTeapot.usd"
    assert main(["inspect", str(teapot)]) == 0
    assert capsys.readouterr().out == f"{teapot}\nno skeleton\n"
    d = inspect_json(capsys, teapot)
    assert d["skeletons"] == [] and d["animations"] == [] and d["hands"] == {"left": None, "right": None}

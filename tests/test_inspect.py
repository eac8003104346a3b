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

"""Provenance: how finger motion was made, recorded by every writer that can and carried through conversion.

USD: ``UsdHandsFingerMotionAPI`` on the SkelAnimation (also in an ``--as-layer``
override); glTF: the animation's ``extras.usdhands.provenance``; BVH: a warning that
it is not kept.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from pxr import Usd

from usdhands.jobs.conversion import convert
from usdhands.formats.io import read_asset, write_asset, write_clip
from usdhands.formats.usd_schema_data import read_finger_motion
from usdhands.model import Clip, Skeleton
from usdhands.model.asset import Asset
from usdhands.model.provenance import provenance_record

RECORD = {"method": "synthesis", "database": "db/gestures.npz", "parameters": {"k": 3, "alpha": 0.5}}


def _asset() -> Asset:
    sk = Skeleton(["Hips", "Hips/Hand", "Hips/Hand/Index1"], [-1, 0, 1], [[0, 1, 0], [0, 0.5, 0], [0, 0.1, 0]],
                  np.tile([0, 0, 0, 1.0], (3, 1)))
    rot = np.tile([0, 0, 0, 1.0], (6, 3, 1))
    rot[:, 2] = [0, 0, np.sin(0.2), np.cos(0.2)]
    return Asset("mem", (sk,), (Clip(sk, 30, rot, name="Take"),))


def test_record_is_checked_and_completed():
    rec = provenance_record(RECORD)
    assert rec["version"] and rec["method"] == "synthesis" and rec["parameters"] == {"alpha": 0.5, "k": 3}
    with pytest.raises(ValueError, match="method"):
        provenance_record("magic")
    with pytest.raises(ValueError, match="keys"):
        provenance_record({"method": "synthesis", "db": "x"})


@pytest.mark.parametrize("ext", [".usda", ".glb", ".gltf"])
def test_write_clip_records_provenance(tmp_path, ext):
    src = write_asset(_asset(), tmp_path / f"src{ext}")
    clip = read_asset(src).clips[0]
    out = write_clip(src, clip, tmp_path / f"out{ext}", provenance=RECORD)
    assert read_asset(src).provenance == {}
    back = read_asset(out)
    assert back.provenance[back.clips[0].name] == provenance_record(RECORD)


def test_as_layer_records_provenance_in_the_layer(tmp_path):
    src = write_asset(_asset(), tmp_path / "src.usda")
    clip = read_asset(src).clips[0]
    out = write_clip(src, clip, tmp_path / "layer.usda", as_layer=True, provenance=RECORD)
    layer_only = Usd.Stage.Open(str(out))
    rec = read_finger_motion(layer_only.GetPrimAtPath(clip.name))
    assert rec == provenance_record(RECORD)
    assert "UsdHandsFingerMotionAPI" in out.read_text()  # authored in the layer, not the body
    assert "UsdHandsFingerMotionAPI" not in src.read_text()


def test_conversion_carries_provenance_both_ways(tmp_path):
    a = _asset()
    a = Asset(a.path, a.skeletons, a.clips, provenance={"Take": provenance_record(RECORD)})
    glb = write_asset(a, tmp_path / "a.glb")
    usd = tmp_path / "b.usda"
    back = tmp_path / "c.gltf"
    convert(glb, usd)
    convert(usd, back)
    for path in (glb, usd, back):
        asset = read_asset(path)
        assert list(asset.provenance.values()) == [provenance_record(RECORD)], path
    assert json.loads(back.read_text())["animations"][0]["extras"]["usdhands"]["provenance"]["method"] == "synthesis"


def test_bvh_names_the_provenance_it_cannot_keep(tmp_path, caplog):
    a = _asset()
    a = Asset(a.path, a.skeletons, a.clips, provenance={"Take": provenance_record(RECORD)})
    usd = write_asset(a, tmp_path / "a.usda")
    with caplog.at_level("WARNING", logger="usdhands"):
        convert(usd, tmp_path / "a.bvh")
    assert "BVH cannot record how the finger motion was made (method 'synthesis'): provenance not kept" in caplog.text


def test_malformed_gltf_record_is_named_and_left_out(tmp_path, caplog):
    path = write_asset(_asset(), tmp_path / "a.gltf")
    doc = json.loads(path.read_text())
    doc["animations"][0]["extras"]["usdhands"]["provenance"] = {"method": "magic"}
    path.write_text(json.dumps(doc))
    with caplog.at_level("WARNING", logger="usdhands"):
        assert read_asset(path).provenance == {}
    assert "ignoring extras.usdhands.provenance" in caplog.text


@pytest.mark.parametrize("as_layer", [False, True])
def test_handmap_write_schema(shared_assets, tmp_path, capsys, as_layer):
    from usdhands.cli import main
    from usdhands.formats.usd_schema_data import read_hand_maps
    from usdhands.formats.usd_validate import usd_compliance_errors
    from usdhands.model.hand_detection import detect_hands

    src = tmp_path / "robot.usda"
    convert(shared_assets / "robot_expressive" / "RobotExpressive.glb", src)
    before = src.read_bytes()
    out = tmp_path / "with_map.usda"
    argv = ["handmap", str(src), "--write-schema", str(out)] + (["--as-layer"] if as_layer else [])
    assert main(argv) == 0
    assert src.read_bytes() == before
    asset = read_asset(out)
    maps = read_hand_maps(out)
    assert list(maps) == [asset.skeletons[0].name]
    assert maps[asset.skeletons[0].name] == detect_hands(asset.skeletons[0])
    assert usd_compliance_errors(out) == []
    text = out.read_text()
    assert ("subLayers" in text and "over " in text and "def Mesh" not in text) == as_layer


def test_handmap_write_schema_refuses_non_usd(shared_assets, tmp_path, capsys):
    from usdhands.cli import main

    glb = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    assert main(["handmap", str(glb), "--write-schema", str(tmp_path / "x.usda")]) == 2
    assert capsys.readouterr().err.strip().endswith("--write-schema needs a USD input (the schema is authored on its "
                                                    "Skeleton prim)")
    assert not (tmp_path / "x.usda").exists()


def _records(path):
    return list(read_asset(path).provenance.values())


def test_every_command_writing_finger_motion_records_it(sample_assets, shared_assets, ok_glb, tmp_path, capsys):
    """synthesize (copy, --as-layer, another format), splice, reduce and expand: the output says how."""
    from usdhands.cli import main

    body_usd = tmp_path / "body.usdc"
    import shutil

    shutil.copy(sample_assets / "gestures_bodyonly" / "ok_00_bodyonly.usdc", body_usd)
    runs = {
        "synthesis": [["synthesize", body_usd, "-o", tmp_path / "s.usda"],
                      ["synthesize", body_usd, "-o", tmp_path / "s_layer.usda", "--as-layer"],
                      ["synthesize", ok_glb, "-o", tmp_path / "s.glb"]],
        "splicing": [["splice", ok_glb, ok_glb, "-o", tmp_path / "sp.glb"]],
        "reduction": [["reduce", ok_glb, "-o", tmp_path / "r.glb", "--model", tmp_path / "m.json"],
                      ["expand", tmp_path / "r.glb", "--model", tmp_path / "m.json", "-o", tmp_path / "e.glb"]],
    }
    for method, argvs in runs.items():
        for argv in argvs:
            assert main([str(a) for a in argv]) == 0, argv
            capsys.readouterr()
            out = argv[argv.index("-o") + 1]
            recs = _records(out)
            assert len(recs) == 1 and recs[0]["method"] == method, (argv, recs)
            assert recs[0]["version"] and isinstance(recs[0]["parameters"], dict)
    assert _records(tmp_path / "s.usda")[0]["database"].endswith("gesture_db")
    assert _records(tmp_path / "sp.glb")[0]["database"] == ok_glb.as_posix()
    assert _records(tmp_path / "e.glb")[0]["database"] == (tmp_path / "m.json").as_posix()
    assert "UsdHandsFingerMotionAPI" in (tmp_path / "s_layer.usda").read_text()

"""``usdhands correct`` from the command line: a built case end to end, the JSON keys, layers,
plots, attached props, and bad input in one line with exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_helpers import run
from interaction_data import write_closing_scene

from usdhands.formats.io import read_clip

KEYS = {"penetration_before_mm", "penetration_after_mm", "frames_corrected", "jitter_before", "jitter_after",
        "max_change_deg"}


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    d = tmp_path_factory.mktemp("correct")
    write_closing_scene(d)
    return d


def _json(capsys, *argv):
    from usdhands.cli import main

    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_json_summary(scene, capsys):
    code, out, err = _json(capsys, "correct", scene / "closing.usda", "--props", scene / "cyl.obj",
                           "-o", scene / "j.usda", "--json")
    assert code == 0, err
    s = json.loads(out)
    assert KEYS <= set(s)
    assert s["penetration_before_mm"]["max"] > 15 and s["penetration_after_mm"]["max"] <= 0.5
    assert set(s["penetration_after_mm"]) == {"max", "mean", "frames"}
    assert s["jitter_after"] < s["jitter_before"]
    before = read_clip(scene / "closing.usda")
    after = read_clip(scene / "j.usda")
    assert after.num_frames == before.num_frames
    assert not np.allclose(after.rotations, before.rotations)
    from usdhands.formats.io import read_asset

    (record,) = read_asset(scene / "j.usda").provenance.values()  # UsdHandsFingerMotionAPI
    assert record["method"] == "interaction" and record["parameters"]["props"] == [str(scene / "cyl.obj")]


def test_table_layer_and_plots(scene, capsys):
    code, out, err = _json(capsys, "correct", scene / "closing.usda", "--props", scene / "cyl.obj",
                           "-o", scene / "layer.usda", "--as-layer", "--plot", scene / "plots")
    assert code == 0, err
    for key in KEYS:
        assert key in out
    text = (scene / "layer.usda").read_text()
    assert "subLayers" in text and "closing.usda" in text
    assert (scene / "plots" / "penetration_depth.png").stat().st_size > 1000
    assert (scene / "plots" / "worst_frame.png").stat().st_size > 1000


def test_attached_prop_moves_with_the_hand(scene, capsys):
    # the cylinder held by the left hand for the whole clip: the fingers curl onto it all along;
    # held only from frame 20 on, it stays where it is until then: the same correction up to frame 19
    code, out, err = _json(capsys, "correct", scene / "closing.usda", "--props", scene / "cyl.obj",
                           "-o", scene / "held.usda", "--attach", "cyl=LeftHand:20-23", "--json")
    assert code == 0, err
    code, out2, err = _json(capsys, "correct", scene / "closing.usda", "--props", scene / "cyl.obj",
                            "-o", scene / "free.usda", "--json")
    held, free = read_clip(scene / "held.usda"), read_clip(scene / "free.usda")
    np.testing.assert_array_equal(held.rotations[:20], free.rotations[:20])


@pytest.mark.parametrize("make,args,message", [
    (lambda d: (d / "bad.obj").write_text("not a mesh\n"), ["--props", "{d}/bad.obj"], "no triangles"),
    (lambda d: (d / "empty.stl").write_text("solid e\nendsolid e\n"), ["--props", "{d}/empty.stl"], "no triangles"),
    (lambda d: None, ["--props", "{d}/cyl.obj", "--prop-units", "1", "--prop-up", "Y"], None),
    (lambda d: None, ["--props", "{d}/cyl.obj", "--attach", "cyl=NoSuchJoint"], "no joint named 'NoSuchJoint'"),
    (lambda d: None, ["--props", "{d}/cyl.obj", "--attach", "mug=LeftHand"], "no prop named 'mug'"),
    (lambda d: None, ["--props", "{d}/cyl.obj", "--attach", "cyl=LeftHand:9-3"], "runs backwards"),
    (lambda d: None, ["--props", "{d}/cyl.obj", "--margin", "-1"], "--margin"),
])
def test_bad_input_one_line_exit_2(scene, capsys, make, args, message):
    make(scene)
    out = scene / "never.usda"
    argv = ["correct", scene / "closing.usda", "-o", out] + [a.format(d=scene) for a in args]
    code, lines = run(capsys, *argv)
    if message is None:  # the cylinder (cm) claimed to be in metres: a unit slip
        message = "looks like it is in centimetres"
    assert code == 2 and len(lines) == 1 and lines[0].startswith("usdhands: error: ") and message in lines[0]
    assert not out.exists()


def test_output_over_a_prop_is_refused(scene, capsys):
    before = (scene / "cyl.obj").read_bytes()
    code, lines = run(capsys, "correct", scene / "closing.usda", "--props", scene / "cyl.obj", "-o", scene / "cyl.obj")
    assert code == 2 and len(lines) == 1 and "--props" in lines[0]
    assert (scene / "cyl.obj").read_bytes() == before

"""Synthesis on odd inputs: real rigs with degenerate arms, clips shorter than a segment,
damaged databases, other frame rates and up axes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from usdhands.algorithms.finger_database import load_database
from usdhands.cli import main
from usdhands.formats.io import read_clip


def _run(capsys, *argv):
    status = main([str(a) for a in argv])
    out = capsys.readouterr()
    return status, out.out, out.err


def test_db_build_on_leap_bvhs_whose_wrist_sits_on_the_root(shared_assets, capsys, tmp_path):
    # rHand is at offset 0 from the root rForeArm: no forearm direction to build the hand frame from
    leap = shared_assets / "leap_hands"
    db_path = tmp_path / "leapdb"
    status, out, err = _run(capsys, "db", "build", leap, "-o", db_path, "--labels", r"^(\w+)-", "--json")
    assert status == 0, err
    info = json.loads(out)
    assert info["clips"] == 3 and info["tracks"] == 3 and info["labels"] == ["fingers", "gesture"]
    db = load_database(db_path)
    assert set(db.hands) == {"right"} and set(db.tracks[:, 3]) == {1}
    joints = db.hands["right"]["joints"]
    # the hand frame's forward axis (x) points from the wrist towards the fingers
    firsts = [j for j in joints if j["parent"] == -1]
    assert [j["slot"] for j in firsts] == ["thumb.d2", "index.d2", "middle.d2", "ring.d2", "pinky.d2"]
    assert all(j["offset_cm"][0] > 20 for j in firsts[1:]), [j["offset_cm"] for j in firsts]
    for j in joints:
        assert np.linalg.norm(j["rotation"]) == pytest.approx(1.0)
    # the right-hand-only database synthesizes a right hand and refuses a left one clearly
    src = leap / "gesture-pointing.bvh"
    status, _, err = _run(capsys, "synthesize", src, "-o", tmp_path / "o.bvh", "--db", db_path)
    assert status == 0, err
    back, clip = read_clip(tmp_path / "o.bvh"), read_clip(src)
    assert back.num_frames == clip.num_frames

"""The worked example of docs/interaction.md and the README's interaction commands run on the
committed samples and print what the page shows."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from usdhands.cli import main

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "interaction.md"
SAMPLES = ROOT / "sample_assets"
PROPS = [str(SAMPLES / "props" / "cup_on_table.obj"), str(SAMPLES / "props" / "table.obj")]

pytestmark = pytest.mark.skipif(not (SAMPLES / "interaction" / "cup_grasp.glb").is_file(),
                                reason="sample_assets/ not generated")


def _doc_table() -> dict[str, str]:
    rows = {}
    for line in DOC.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^(penetration_before_mm|penetration_after_mm|frames_corrected|jitter_before|jitter_after|"
                     r"max_change_deg|chains_corrected)\s+(.*)$", line)
        if m and m.group(1) not in rows:
            rows[m.group(1)] = m.group(2).strip()
    return rows


def test_the_cup_example_prints_the_pages_table(tmp_path, capsys):
    argv = ["correct", str(SAMPLES / "interaction" / "cup_grasp.glb"), "--props", *PROPS,
            "--attach", "cup_on_table=RightHand:48-102", "-o", str(tmp_path / "cup_fixed.glb"),
            "--plot", str(tmp_path / "plots")]
    assert main(argv) == 0
    printed = {}
    for line in capsys.readouterr().out.splitlines():
        parts = line.split(None, 1)
        if len(parts) == 2:
            printed[parts[0]] = parts[1].strip()
    table = _doc_table()
    assert len(table) == 7 and all(printed[k] == v for k, v in table.items())
    assert {p.name for p in (tmp_path / "plots").iterdir()} == {"penetration_depth.png", "worst_frame.png"}


def test_synthesize_with_the_cup_leaves_no_penetration(tmp_path, capsys):
    argv = ["synthesize", str(SAMPLES / "interaction" / "cup_grasp_bodyonly.glb"), "--props", *PROPS,
            "--attach", "cup_on_table=RightHand:48-102", "-o", str(tmp_path / "cup_synth.glb"), "--json"]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["interaction"]["penetration_before_mm"]["max"] > 1.0
    assert report["interaction"]["penetration_after_mm"]["max"] <= 0.5

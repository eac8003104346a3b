"""The worked example of docs/synthesis.md: every command prints what the page shows."""

from __future__ import annotations

import contextlib
import io
import os
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from usdhands.cli import main

DOC = Path(__file__).resolve().parents[1] / "docs" / "synthesis.md"


def examples() -> list[tuple[list[str], list[str]]]:
    """(argv, printed lines) of every ``$ usdhands ...`` line of the page's plain ``` blocks.

    A block line ``...`` ends what the page shows of a command's output (the rest is cut).
    """
    blocks, current = [], None
    for line in DOC.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            if current is None:
                current = [] if line == "```" else "other"
            else:
                if current != "other":
                    blocks.append("\n".join(current) + "\n")
                current = None
        elif current is not None and current != "other":
            current.append(line)
    out = []
    for block in blocks:
        for cmd in re.split(r"^\$ ", block, flags=re.M)[1:]:
            first, *printed = cmd.rstrip("\n").splitlines()
            if "..." in printed:
                printed = printed[:printed.index("...")]
            out.append((first, printed))
    return out


def run(line: str, folder: Path) -> list[str]:
    argv = shlex.split(line)
    buf = io.StringIO()
    old = os.getcwd()
    os.chdir(folder)
    try:
        if argv[0] == "echo":  # echo '...' > file
            Path(argv[-1]).write_text(argv[1] + "\n")
            return []
        assert argv[0] == "usdhands", line
        with contextlib.redirect_stdout(buf):
            status = main(argv[1:])
    finally:
        os.chdir(old)
    assert status == 0, line
    return buf.getvalue().rstrip("\n").splitlines()


@pytest.fixture(scope="module")
def folder(tmp_path_factory, sample_assets, shared_assets):
    """A working folder like the repository root, with the files the page's commands name."""
    from usdhands.formats.io import read_clip, write_asset
    from usdhands.model.asset import Asset
    from usdhands.model.hand_detection import detect_hands

    tmp = tmp_path_factory.mktemp("docs")
    (tmp / "sample_assets").symlink_to(sample_assets)
    (tmp / "RobotExpressive.glb").symlink_to(shared_assets / "robot_expressive" / "RobotExpressive.glb")
    # body_without_fingers.usda: conversation_bodyonly.usdc with its 40 finger joints removed
    full = read_clip(sample_assets / "conversation_bodyonly.usdc")
    sk = full.skeleton
    hm = detect_hands(sk)
    fingers = {sk.index(j) for h in hm.sides for j in h.finger_joints}
    keep = [j for j in range(sk.num_joints) if not fingers.intersection(sk.chain_to_root(j))]
    assert sk.num_joints - len(keep) == 40
    sub = sk.subset(keep)
    body = full.replace(skeleton=sub, rotations=full.rotations[:, keep], translations=full.translations[:, keep],
                        scales=full.scales[:, keep])
    write_asset(Asset("memory", [sub], [body], []), tmp / "body_without_fingers.usda")
    return tmp


def test_page_has_the_commands():
    firsts = [line.split()[1] for line, _ in examples()]
    assert firsts == ["evaluate", "synthesize", "db", "'{\"segment_cost\":", "synthesize", "evaluate", "evaluate",
                      "synthesize", "synthesize"]


def test_every_command_prints_what_the_page_shows(folder):
    for line, shown in examples():
        assert shown or line.startswith("echo"), line
        printed = run(line, folder)
        assert printed[:len(shown)] == shown, line
    # what the page says about the outputs
    assert (folder / "gesture_db" / "manifest.json").exists()
    for png in ("predictors", "confusion", "right_segments", "right_graph", "right_fingers"):
        assert (folder / "plots" / f"{png}.png").stat().st_size < 150_000
        image = DOC.parent / "images" / f"synthesis_{png}.png"
        assert image.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    from usdhands.formats.io import read_clip

    grafted, original = read_clip(folder / "grafted.usda"), read_clip(folder / "sample_assets" / "conversation_bodyonly.usdc")
    names = grafted.skeleton.short_names
    order = [names.index(n) for n in original.skeleton.short_names]
    assert np.abs(grafted.skeleton.rest_world_positions()[order]
                  - original.skeleton.rest_world_positions()).max() < 1e-12 / original.skeleton.meters_per_unit

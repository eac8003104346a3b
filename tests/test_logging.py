"""The library logs what it decided through ``logging.getLogger("usdhands.<module>")``; ``-v`` shows it.

The library itself never configures logging (only the CLI does).
"""

from __future__ import annotations

import re
from pathlib import Path

from usdhands.cli import main
from usdhands.formats.io import read_asset
from usdhands.model.hand_detection import detect_hands

PACKAGE = Path(__file__).resolve().parents[1] / "usdhands"


def _robot_with_camera_and_loose_mesh(shared_assets, tmp_path) -> Path:
    """RobotExpressive with a camera (which convert cannot carry) and a mesh node on no skeleton
    (which it carries as a static mesh)."""
    import pygltflib

    g = pygltflib.GLTF2().load(str(shared_assets / "robot_expressive" / "RobotExpressive.glb"))
    g.cameras.append(pygltflib.Camera(type="perspective", perspective=pygltflib.Perspective(yfov=0.8, znear=0.1)))
    g.nodes.append(pygltflib.Node(name="Cam", camera=0))
    g.nodes.append(pygltflib.Node(name="Loose", mesh=0, translation=[2.0, 0.0, 0.0]))
    g.scenes[g.scene or 0].nodes += [len(g.nodes) - 2, len(g.nodes) - 1]
    out = tmp_path / "robot_extra.glb"
    g.save_binary(str(out))
    return out


def test_reader_names_what_it_left_out(shared_assets, tmp_path, caplog):
    with caplog.at_level("INFO", logger="usdhands"):
        asset = read_asset(_robot_with_camera_and_loose_mesh(shared_assets, tmp_path))
    assert asset.left_out == ("1 camera(s)",)
    assert sum(len(m.points) for m in asset.meshes) == 7214 + 64
    logged = [r for r in caplog.records if r.name == "usdhands.formats.gltf_read"]
    assert {r.getMessage().split("not read: ")[1] for r in logged} == set(asset.left_out)


def test_hands_found_are_logged(shared_assets, caplog):
    sk = read_asset(shared_assets / "robot_expressive" / "RobotExpressive.glb").skeletons[0]
    with caplog.at_level("INFO", logger="usdhands.model.hand_detection"):
        hm = detect_hands(sk)
    text = caplog.text
    for side in ("left", "right"):
        h = getattr(hm, side)
        assert f"{side} hand at {h.wrist!r}" in text


def test_verbose_flag_shows_decisions_and_convert_warns_once(shared_assets, tmp_path, capsys):
    src = _robot_with_camera_and_loose_mesh(shared_assets, tmp_path)
    assert main(["convert", str(src), str(tmp_path / "a.usda")]) == 0
    err = capsys.readouterr().err.splitlines()
    warned = [line for line in err if "not converted" in line]
    assert len(warned) == 1 and warned[0].endswith("1 camera(s)")
    assert not any("not read:" in line for line in err)  # INFO stays hidden without -v
    assert main(["-v", "convert", str(src), str(tmp_path / "b.usda")]) == 0
    err = capsys.readouterr().err
    assert "not read: 1 camera(s)" in err
    # the plain robot: everything is carried, no warning
    assert main(["convert", str(shared_assets / "robot_expressive" / "RobotExpressive.glb"),
                 str(tmp_path / "c.usda")]) == 0
    assert "not converted" not in capsys.readouterr().err


def test_library_never_configures_logging():
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        if path.name == "cli.py":
            continue
        text = path.read_text(encoding="utf-8")
        if re.search(r"logging\.basicConfig|\.addHandler\(|\.setLevel\(", text):
            offenders.append(str(path.relative_to(PACKAGE)))
    assert offenders == []


def test_plot_without_matplotlib_is_one_line(shared_assets, tmp_path, capsys, monkeypatch):
    """matplotlib is the ``plot`` extra: without it, --plot is refused in one line before any work."""
    import sys

    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib raises ImportError
    src = shared_assets / "leap_hands" / "fingers-ok.bvh"
    out = tmp_path / "out.bvh"
    code = main(["reduce", str(src), "-o", str(out), "--plot", str(tmp_path / "plots")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == [f'usdhands: error: {tmp_path / "plots"}: --plot needs matplotlib, which is not installed: '
                   'pip install "usdhands[plot]"']
    assert not out.exists() and not (tmp_path / "plots").exists()

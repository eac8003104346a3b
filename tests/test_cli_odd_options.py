"""Odd options and odd output paths: one line ``usdhands: error: ...``, exit 2, nothing written."""

from __future__ import annotations

import shutil

import pytest

from usdhands.cli import main


def run(capsys, *argv) -> tuple[int, list[str]]:
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err.strip().splitlines()


@pytest.fixture()
def ok_glb(sample_assets, tmp_path):
    dst = tmp_path / "ok.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", dst)
    return dst


@pytest.mark.parametrize("fps, shown", [("0", "0"), ("-5", "-5"), ("nan", "nan"), ("inf", "inf"),
                                         ("1e9", "1e+09"), ("1001", "1001")])
def test_bad_fps_refused_before_reading(fps, shown, ok_glb, tmp_path, capsys):
    """--fps 0 was ignored (convert, evaluate), -5 and nan were blamed on the file ('malformed glTF'),
    inf was an OverflowError traceback and 1e9 ran out of memory."""
    message = f"usdhands: error: --fps must be a frame rate above 0 and at most 1000, got {shown}"
    for argv in (["convert", ok_glb, tmp_path / "out.usda", f"--fps={fps}"],
                 ["db", "build", "-o", tmp_path / "db", ok_glb, f"--fps={fps}"],
                 ["evaluate", "--samples", f"--fps={fps}"]):
        code, err = run(capsys, *argv)
        assert (code, err) == (2, [message]), argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.glb"]


def test_library_refuses_bad_fps_as_a_programming_error(ok_glb):
    from usdhands.formats.io import read_asset

    for fps in (0.0, -5.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="Expected fps > 0 and finite"):
            read_asset(ok_glb, fps=fps)


def test_low_fps_still_converts(ok_glb, tmp_path, capsys):
    code, _ = run(capsys, "convert", ok_glb, tmp_path / "slow.usda", "--fps", "2")
    assert code == 0
    from usdhands.formats.io import read_clip

    src, out = read_clip(ok_glb), read_clip(tmp_path / "slow.usda")
    assert out.fps == 2.0
    assert out.num_frames == int(src.duration * 2 + 1e-6) + 1

"""The Python examples of docs/getting-started.md run and print what the page shows."""

from __future__ import annotations

import contextlib
import io
import os
import re
from pathlib import Path

DOC = Path(__file__).resolve().parents[1] / "docs" / "getting-started.md"


def python_examples() -> list[tuple[str, list[str]]]:
    """(code, printed lines) of each ```python block followed by a plain ``` output block."""
    text = DOC.read_text(encoding="utf-8")
    pairs = re.findall(r"```python\n(.*?)```\s*\n```\n(.*?)```", text, flags=re.S)
    return [(code, out.rstrip("\n").splitlines()) for code, out in pairs]


def run(code: str, folder: Path) -> list[str]:
    buf = io.StringIO()
    old = os.getcwd()
    os.chdir(folder)
    try:
        with contextlib.redirect_stdout(buf):
            exec(compile(code, str(DOC), "exec"), {"__name__": "__doc_example__"})
    finally:
        os.chdir(old)
    return buf.getvalue().rstrip("\n").splitlines()


def test_page_has_the_examples():
    assert len(python_examples()) == 2


def test_clip_from_arrays_example_prints_what_the_page_says(tmp_path):
    code, shown = python_examples()[1]
    assert run(code, tmp_path) == shown


def test_humanoid_example_runs_on_the_samples(sample_assets, tmp_path):
    (tmp_path / "sample_assets").symlink_to(sample_assets)
    (tmp_path / "out").mkdir()
    code, shown = python_examples()[0]
    printed = run(code, tmp_path)
    assert len(printed) == len(shown)
    # the same lines, numbers aside (the samples' motion may be regenerated)
    digits = re.compile(r"-?\d+(\.\d+)?")
    assert [digits.sub("#", line) for line in printed] == [digits.sub("#", line) for line in shown]
    assert printed[-1] == "round trip of the curves: True"
    assert (tmp_path / "out" / "humanoid_curled.glb").stat().st_size > 0
    assert float(printed[4].split()[2]) > 1.0  # the fingertip moved by centimetres

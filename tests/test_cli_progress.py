"""Progress on stderr: tqdm bars on a terminal, nothing with -q or when piped; -v/-q after the subcommand."""

from __future__ import annotations

import io
import logging
import re

import pytest

from usdhands.cli import build_parser, main
from usdhands.commands import _common
from usdhands.commands._common import Progress, compile_progress, set_quiet


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture(autouse=True)
def not_quiet():
    set_quiet(False)
    yield
    set_quiet(False)


def _drawn(stream: io.StringIO) -> list[str]:
    """The distinct texts a bar drew (carriage returns and ANSI codes removed)."""
    out = []
    for part in re.split(r"[\r\n]", stream.getvalue()):
        part = re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", part).strip()
        if part and part not in out:
            out.append(part)
    return out


def test_bar_on_a_terminal_shows_count_and_label_then_goes():
    term = Terminal()
    progress = Progress("reading", stream=term)
    for i in range(1, 4):
        progress(i, 3, f"clip_{i}.bvh")
    drawn = _drawn(term)
    assert any(d.startswith("reading: 1/3") and "clip_1.bvh" in d for d in drawn), drawn
    assert progress._bar is None  # closed at total (later steps within 0.1 s are not drawn)


def test_no_bar_when_piped_or_quiet(caplog):
    piped = io.StringIO()
    Progress("reading", stream=piped)(1, 2, "a")
    assert piped.getvalue() == ""
    set_quiet(True)
    term = Terminal()
    Progress("reading", stream=term)(1, 2, "a")
    assert term.getvalue() == ""


def test_verbose_without_a_terminal_logs_the_steps(caplog):
    with caplog.at_level(logging.INFO, logger="usdhands"):
        progress = Progress("holdout", stream=io.StringIO())
        progress(1, 3, "wave_01")
        progress(2, 3, "wave_02")  # within a second of the first: not logged
        progress(3, 3, "wave_03")
    assert [r.getMessage() for r in caplog.records] == ["holdout: 1/3 wave_01", "holdout: 3/3 wave_03"]


def test_compile_bar_names_the_kernel(monkeypatch):
    from usdhands import jit

    term = Terminal()
    with compile_progress(term):
        for listener in list(jit._listeners):
            listener("search")
            listener("align_path")
    assert any(d.startswith("compiling kernels, once: 1 kernels") and "search" in d for d in _drawn(term))
    assert jit._listeners == []


@pytest.mark.parametrize("argv", [
    ["-v", "synthesize", "in.bvh", "-o", "out.bvh"],
    ["synthesize", "in.bvh", "-o", "out.bvh", "-v"],
    ["synthesize", "-v", "in.bvh", "-o", "out.bvh"],
    ["db", "build", "x.bvh", "-o", "db", "--verbose"],
])
def test_verbose_before_or_after_the_subcommand(argv):
    args = build_parser().parse_args(argv)
    assert args.verbose is True and args.quiet is False


def test_quiet_after_the_subcommand_and_defaults():
    args = build_parser().parse_args(["inspect", "a.usda", "-q"])
    assert args.quiet is True and args.verbose is False
    args = build_parser().parse_args(["inspect", "a.usda"])
    assert args.quiet is False and args.verbose is False


def test_quiet_run_sets_and_clears_quiet(capsys, sample_assets):
    assert main(["inspect", str(sample_assets / "humanoid.bvh"), "-q"]) == 0
    assert _common._quiet is True
    assert main(["inspect", str(sample_assets / "humanoid.bvh")]) == 0
    assert _common._quiet is False

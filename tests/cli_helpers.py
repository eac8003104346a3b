"""Helpers for tests that drive the ``usdhands`` command line in-process."""

from __future__ import annotations

from usdhands.cli import main


def run(capsys, *argv) -> tuple[int, list[str]]:
    """Run ``usdhands ARGV...``; the exit status and the stderr lines."""
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err.strip().splitlines()

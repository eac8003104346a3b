"""docs/hostile-input.md states the input limits, the commands of the corpus and the fuzzed readers:
each against the code, so the page cannot drift from what is refused."""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PAGE = (ROOT / "docs" / "hostile-input.md").read_text()


def _limit_rows() -> list[tuple[str, str, str]]:
    """(what, limit, constant) of each row of the Limits table."""
    table = PAGE.split("## Limits", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 3 and cells[2].startswith("`usdhands."):
            rows.append((cells[0], cells[1], cells[2].strip("`")))
    return rows


def _number(text: str) -> float:
    """'10,000 fps' -> 10000, '2^53' -> 2**53, '1e30' -> 1e30."""
    token = text.split()[0].replace(",", "")
    if "^" in token:
        base, power = token.split("^")
        return float(int(base) ** int(power))
    return float(token)


def test_the_limits_table_has_the_limits_of_the_code():
    rows = _limit_rows()
    assert len(rows) >= 13
    wrong = {}
    for what, limit, constant in rows:
        module, name = constant.rsplit(".", 1)
        value = getattr(importlib.import_module(module), name)
        if float(value) != _number(limit):
            wrong[what] = (limit, value)
    assert wrong == {}


@pytest.mark.parametrize("example,expected", [("10,000 fps", 1e4), ("2^53", 2.0 ** 53), ("1e30", 1e30),
                                              ("1,000 s", 1000.0)])
def test_numbers_of_the_table_read_as_written(example, expected):
    assert _number(example) == expected


def test_the_page_names_every_command_of_the_corpus_and_every_fuzzed_reader():
    sys.path.insert(0, str(ROOT / "tests"))
    sys.path.insert(0, str(ROOT / "tests" / "fuzz"))
    from fuzz_target import READERS
    from test_hostile_corpus import COMMANDS

    tested = PAGE.split("## How it is tested", 1)[1]
    named = set(re.findall(r"`([a-z ]+)`", tested))
    assert set(COMMANDS) <= named, set(COMMANDS) - named
    assert set(READERS) <= named, set(READERS) - named

"""The shipped JSON schemas and the first-violation helper every JSON reader uses."""

from pathlib import Path

import pytest

from usdhands.json_schemas import first_schema_error, load_schema

SOURCES = Path(__file__).resolve().parent.parent / "schemas"
NAMES = ["handmap", "database", "synthesis_config", "reduction_model", "interaction_config"]


@pytest.mark.parametrize("name", NAMES)
def test_shipped_schema_is_the_source(name):
    import json

    assert load_schema(name) == json.loads((SOURCES / f"{name}.schema.json").read_text())


def test_valid_data_has_no_error():
    assert first_schema_error({"left": None, "right": None}, "handmap") is None


def test_error_names_the_deepest_place():
    data = {"left": {"wrist": "LeftHand", "fingers": {"index": ["LeftHandIndex1", 3]}}, "right": None}
    assert first_schema_error(data, "handmap") == ("left/fingers/index/1", "3 is not of type 'string'")


def test_top_level_error():
    where, message = first_schema_error([], "handmap")
    assert where == "(top level)" and "is not of type 'object'" in message

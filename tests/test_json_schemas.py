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


def test_bundled_database_manifest_is_valid(tmp_path):
    """synthesize loads the bundled database without the schema check (check_schema=False): checked here."""
    import json
    import shutil

    from usdhands.algorithms.synthesis.database import load_database
    from usdhands.jobs.inputs import bundled_database_path
    from usdhands.errors import ConfigError

    manifest = json.loads((bundled_database_path() / "manifest.json").read_text())
    assert first_schema_error(manifest, "database") is None
    # and the check the bundled database skips still runs for any other database
    broken = tmp_path / "db"
    shutil.copytree(bundled_database_path(), broken)
    manifest["fps"] = "thirty"
    (broken / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ConfigError, match="invalid database manifest at fps"):
        load_database(broken)

"""The command line's small frictions of issue 9: help texts, --json everywhere, short joint names."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from usdhands.cli import build_parser, main
from usdhands.formats.io import read_asset
from usdhands.model.skeleton import display_joint_names


def _subparsers(parser, prefix=()):
    """(command words, parser) for every parser below ``parser``."""
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield prefix + (name,), sub
                yield from _subparsers(sub, prefix + (name,))


def test_help_texts_name_papers_not_seed_files():
    parser = build_parser()
    texts = [parser.format_help()] + [sub.format_help() for _, sub in _subparsers(parser)]
    assert not [t for t in texts if "seed 00" in t]
    assert "Jörg et al. 2012" in parser.format_help()


def test_every_command_has_a_description():
    missing = [" ".join(words) for words, sub in _subparsers(build_parser()) if not sub.description]
    assert missing == []


def test_handmap_json_is_the_written_map_plus_where_it_came_from(sample_assets, tmp_path, capsys):
    src = sample_assets / "humanoid.bvh"
    assert main(["handmap", str(src), "--json", "-o", str(tmp_path / "map.json")]) == 0
    out = json.loads(capsys.readouterr().out)
    written = json.loads((tmp_path / "map.json").read_text())
    assert {k: v for k, v in out.items() if k not in ("file", "source", "num_joints")} == written
    assert out["file"] == str(src) and out["source"] == "detected"
    assert out["num_joints"] == read_asset(src).skeletons[0].num_joints
    assert written["left"]["wrist"].endswith("LeftHand") and len(written["right"]["fingers"]["index"]) == 3


def test_samples_json_lists_what_was_written(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["samples", str(out), "--formats", "bvh", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    on_disk = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert sorted(f["path"] for f in report["files"]) == on_disk
    assert all(f["bytes"] == (out / f["path"]).stat().st_size for f in report["files"])
    assert report["total_bytes"] == sum(f["bytes"] for f in report["files"]) and report["outdir"] == str(out)


def test_inspect_prints_short_joint_names(sample_assets, capsys):
    """A 401-character line of full USD paths on humanoid.usda; handmap printed short names."""
    assert main(["inspect", str(sample_assets / "humanoid.usda")]) == 0
    lines = capsys.readouterr().out.splitlines()
    row = next(line for line in lines if line.split()[:3] == ["left", "LeftHand", "index"])
    assert row.split()[3:] == ["LeftHandIndex1", "LeftHandIndex2", "LeftHandIndex3"]
    assert max(len(line) for line in lines) < 100


def test_display_names_keep_full_paths_where_short_ones_are_ambiguous():
    names = ["Hips", "Hips/L/Index1", "Hips/R", "Hips/R/Index1", "Hips/Spine", "Other/Spine/x", "x"]
    assert display_joint_names(names) == {
        "Hips": "Hips", "Hips/L/Index1": "Hips/L/Index1", "Hips/R": "R", "Hips/R/Index1": "Hips/R/Index1",
        "Hips/Spine": "Spine", "Other/Spine/x": "Other/Spine/x", "x": "x"}


@pytest.mark.parametrize("argv", [["--help"], ["synthesize", "--help"]])
def test_help_runs_in_a_fresh_process(argv):
    out = subprocess.run([sys.executable, "-m", "usdhands", *argv], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.startswith("usage: usdhands"), out.stderr


def test_evaluate_help_lists_the_default_predictors():
    from usdhands.algorithms.synthesis.evaluation import DEFAULT_PREDICTORS
    from usdhands.commands.evaluate import DEFAULT_PREDICTORS_HELP

    assert DEFAULT_PREDICTORS_HELP == ",".join(DEFAULT_PREDICTORS)


def test_building_the_parser_imports_no_heavy_library():
    """Every command (and --help) builds the whole parser: no synthesis algorithms, format handlers, numba, scipy."""
    code = ("import sys; from usdhands.cli import build_parser; build_parser(); "
            "print(sorted(m for m in sys.modules if m.startswith(('usdhands.algorithms.synthesis', 'usdhands.formats.bvh', "
            "'usdhands.formats.usd', 'usdhands.formats.gltf', 'numba', 'pxr', 'pygltflib', 'scipy', 'jsonschema', "
            "'matplotlib', 'tqdm'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_building_the_parser_imports_no_job_for_a_default():
    """``reduce --steps``' default is written out in the command (no job or reduction module imported
    for it), and is the steps' own default."""
    code = ("import sys; from usdhands.cli import build_parser; p = build_parser(); "
            "print(sorted(m for m in sys.modules if m.startswith(('usdhands.jobs', 'usdhands.algorithms.reduction')))); "
            "r = p._subparsers._group_actions[0].choices['reduce']; "
            "print(next(a.default for a in r._actions if a.dest == 'steps'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    imported, default = out.stdout.strip().splitlines()
    assert imported == "[]"
    from usdhands.algorithms.reduction.reduce import DEFAULT_STEPS, parse_steps
    from usdhands.jobs.reduction import ReduceOptions

    assert default == DEFAULT_STEPS == ReduceOptions().steps
    assert len(parse_steps(default)) == 4  # the paper's four steps


def test_a_command_line_builds_the_parser_of_the_command_it_names_only():
    """``usdhands batch ...`` registers the batch parser only (the other commands' modules, some of which
    load NumPy, are not imported); no command, a misspelled one or --version: the full parser."""
    from usdhands.cli import named_command

    assert named_command(["batch", "in", "--job", "synthesize"]) == "batch"
    assert named_command(["-v", "usd-plugin"]) == "usd-plugin"
    assert named_command(["-q", "--verbose", "db", "build"]) == "db"
    assert named_command(["usd_plugin"]) is None and named_command(["synthesise", "x"]) is None
    assert named_command([]) is None and named_command(["--version"]) is None and named_command(["-h"]) is None
    full = build_parser()._subparsers._group_actions[0].choices
    assert {"batch", "synthesize", "usd-plugin", "db", "inspect"} <= set(full)
    for name in full:
        assert list(build_parser(name)._subparsers._group_actions[0].choices) == [name]
    code = ("import json, sys; from usdhands.cli import main; code = main(['usd-plugin']); "
            "print(json.dumps([code, sorted(m for m in sys.modules if m.startswith('usdhands.commands.'))]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert json.loads(out.stdout.splitlines()[-1]) == [0, ["usdhands.commands._common", "usdhands.commands.usd_plugin"]]
    # a misspelled command is refused by the full parser, which lists every command
    code = "from usdhands.cli import main; raise SystemExit(main(['synthesise', 'x']))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 2 and "invalid choice: 'synthesise'" in out.stderr and "usd-plugin" in out.stderr

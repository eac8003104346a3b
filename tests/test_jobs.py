"""The jobs layer: each job writes the same bytes as its command and returns what its --json prints."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import usdhands
from usdhands.errors import UsdHandsError


def _cli(capsys, *argv) -> dict | None:
    from usdhands.cli import main

    capsys.readouterr()
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out) if "--json" in argv else None


def _same_json(cli: dict, job: dict, cli_dir: Path, job_dir: Path) -> None:
    assert json.loads(json.dumps(job).replace(str(job_dir), str(cli_dir))) == cli


@pytest.fixture()
def dirs(tmp_path):
    a, b = tmp_path / "cli", tmp_path / "job"
    a.mkdir()
    b.mkdir()
    return a, b


def test_synthesize_job_writes_the_commands_bytes(ok_glb, dirs, capsys):
    a, b = dirs
    cli = _cli(capsys, "synthesize", ok_glb, "-o", a / "out.glb", "--k", "3", "--hands", "right", "--json")
    result = usdhands.synthesize(ok_glb, b / "out.glb", usdhands.SynthesizeOptions(k=3, hands=("right",)))
    assert (a / "out.glb").read_bytes() == (b / "out.glb").read_bytes()
    _same_json(cli, result.to_json(), a, b)
    assert list(result.animations[0]["hands"]) == ["right"] and result.k == 3


def test_splice_job_writes_the_commands_bytes(ok_glb, shared_assets, dirs, capsys):
    a, b = dirs
    leap = shared_assets / "leap_hands" / "gesture-typing.bvh"
    cli = _cli(capsys, "splice", ok_glb, leap, "-o", a / "out.glb", "--band", "0.4,0.15", "--json")
    result = usdhands.splice(ok_glb, leap, b / "out.glb", usdhands.SpliceOptions(band=(0.4, 0.15)))
    assert (a / "out.glb").read_bytes() == (b / "out.glb").read_bytes()
    _same_json(cli, result.to_json(), a, b)
    assert any("resampled" in n for n in result.notes)  # the notes the command prints on stderr


def test_reduce_and_expand_jobs_write_the_commands_bytes(ok_glb, dirs, capsys):
    a, b = dirs
    # the provenance record names the model file, so both write the same model path
    cli = _cli(capsys, "reduce", ok_glb, "-o", a / "red.glb", "--model", a / "m.json", "--json")
    model = (a / "m.json").read_bytes()
    result = usdhands.reduce(ok_glb, b / "red.glb", model_output=a / "m.json")
    assert (a / "m.json").read_bytes() == model
    assert (a / "red.glb").read_bytes() == (b / "red.glb").read_bytes()
    _same_json(cli, result.to_json(), a, b)
    assert result.chosen.dofs_left < len(result.curve_names)

    cli = _cli(capsys, "expand", a / "red.glb", "--model", a / "m.json", "-o", a / "full.glb", "--json")
    expanded = usdhands.expand(b / "red.glb", a / "m.json", b / "full.glb")
    assert (a / "full.glb").read_bytes() == (b / "full.glb").read_bytes()
    _same_json(cli, expanded.to_json(), a, b)


def test_convert_job_writes_the_commands_bytes(ok_glb, dirs, capsys):
    a, b = dirs
    _cli(capsys, "convert", ok_glb, a / "out.bvh", "--bvh-units", "m")
    result = usdhands.convert(ok_glb, b / "out.bvh", usdhands.ConvertOptions(bvh_units="m"))
    assert (a / "out.bvh").read_bytes() == (b / "out.bvh").read_bytes()
    assert (len(result.skeletons), len(result.animations), result.meshes) == (1, 1, 0)


def test_jobs_raise_project_errors_and_write_nothing(ok_glb, tmp_path, capsys):
    with pytest.raises(UsdHandsError, match="--k must be at least 1"):
        usdhands.synthesize(ok_glb, tmp_path / "o.glb", usdhands.SynthesizeOptions(k=0))
    with pytest.raises(UsdHandsError, match="bad --band"):
        usdhands.splice(ok_glb, ok_glb, tmp_path / "o.glb", usdhands.SpliceOptions(band=(0.3, -1.0)))
    with pytest.raises(UsdHandsError, match="unknown BVH unit"):
        usdhands.convert(ok_glb, tmp_path / "o.bvh", usdhands.ConvertOptions(bvh_units="furlong"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.glb"]
    assert capsys.readouterr().out == ""  # jobs never print


def test_options_are_frozen_and_default_like_the_cli():
    import dataclasses

    from usdhands.cli import build_parser

    parser = build_parser()
    synth = parser.parse_args(["synthesize", "in.glb", "-o", "o.glb"])
    opts = usdhands.SynthesizeOptions()
    assert (opts.k, opts.finger_reference, opts.as_layer) == (synth.k, synth.finger_reference, synth.layer)
    red = parser.parse_args(["reduce", "in.glb"])
    assert (usdhands.ReduceOptions().steps, usdhands.ReduceOptions().order) == (red.steps, red.order)
    sp = parser.parse_args(["splice", "a.glb", "b.glb", "-o", "o.glb"])
    sopts = usdhands.SpliceOptions()
    assert (sopts.side, sopts.yaw, sopts.transfer, sopts.blend) == (sp.side, sp.yaw, sp.transfer, sp.blend)
    cor = parser.parse_args(["correct", "in.usda", "--props", "p.obj", "-o", "o.usda"])
    copts = usdhands.CorrectOptions()
    assert (copts.margin, copts.self_collision, copts.attach, copts.prop_units, copts.prop_up, copts.as_layer,
            copts.animation, copts.plot) == (cor.margin, cor.self_collision, tuple(cor.attach), cor.prop_units,
                                             cor.prop_up, cor.layer, cor.animation, cor.plot)
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.k = 3


def test_import_usdhands_loads_no_job_until_used():
    code = ("import sys, usdhands; before = sorted(m for m in sys.modules if m.startswith('usdhands.jobs')); "
            "usdhands.ReduceOptions; print(before, 'usdhands.jobs.reduction' in sys.modules, "
            "'usdhands.jobs.synthesis' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[] True False"


@pytest.fixture(scope="module")
def correct_scene(tmp_path_factory):
    """A hand closing into a cylinder under its palm (fingers 15+ mm deep), and the cylinder as OBJ."""
    from interaction_data import write_closing_scene

    d = tmp_path_factory.mktemp("correct_job")
    write_closing_scene(d)
    return d


@pytest.mark.parametrize("extra,options", [
    ((), {}),
    (("--margin", "1", "--as-layer"), {"margin": 1.0, "as_layer": True}),
])
def test_correct_job_writes_the_commands_bytes(correct_scene, dirs, capsys, extra, options):
    a, b = dirs
    src, cyl = correct_scene / "closing.usda", correct_scene / "cyl.obj"
    cli = _cli(capsys, "correct", src, "--props", cyl, "-o", a / "out.usda", *extra, "--json")
    result = usdhands.correct(src, b / "out.usda", usdhands.CorrectOptions(props=(cyl,), **options))
    assert (a / "out.usda").read_bytes() == (b / "out.usda").read_bytes()
    job = result.to_json()
    assert cli.pop("seconds") >= 0 and job.pop("seconds") >= 0
    _same_json(cli, job, a, b)
    assert list(job)[3:10] == ["props", "penetration_before_mm", "penetration_after_mm", "frames_corrected",
                               "jitter_before", "jitter_after", "max_change_deg"]
    assert set(job["penetration_after_mm"]) == {"max", "mean", "frames"}
    assert result.penetration_before_mm["max"] > 15 and result.penetration_after_mm["max"] <= 0.5


def test_correct_job_without_props_is_refused(correct_scene, tmp_path):
    with pytest.raises(UsdHandsError, match="--props: name at least one prop"):
        usdhands.correct(correct_scene / "closing.usda", tmp_path / "o.usda")
    assert list(tmp_path.iterdir()) == []


def test_inspect_and_handmap_jobs_report_what_the_commands_print(ok_glb, dirs, capsys):
    from usdhands.jobs.hand_mapping import HandMapOptions, map_hands
    from usdhands.jobs.inspection import inspect_file

    a, b = dirs
    assert _cli(capsys, "inspect", ok_glb, "--json") == inspect_file(ok_glb).to_json()
    cli = _cli(capsys, "handmap", ok_glb, "-o", a / "hands.json", "--json")
    result = map_hands(ok_glb, b / "hands.json", HandMapOptions())
    assert (a / "hands.json").read_bytes() == (b / "hands.json").read_bytes()
    assert cli == result.to_json() and result.source == "detected" and result.written == (b / "hands.json",)
    with pytest.raises(UsdHandsError, match="--write-schema needs a USD input"):
        map_hands(ok_glb, options=HandMapOptions(), schema_output=b / "x.usda")

"""Odd options and odd output paths: one line ``usdhands: error: ...``, exit 2, nothing written."""

from __future__ import annotations

import shutil

import pytest

from cli_helpers import run  # noqa: E402  (tests/ is on sys.path, like splice_synth)


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


def test_output_is_a_folder(ok_glb, tmp_path, capsys, sample_assets):
    """handmap -o FOLDER was an IsADirectoryError traceback from the atomic rename."""
    folder = tmp_path / "outdir"
    folder.mkdir()
    body = tmp_path / "body.bvh"
    shutil.copy(sample_assets / "gestures_bodyonly" / "turn_05_bodyonly.bvh", body)
    for argv in (["handmap", ok_glb, "-o", folder], ["convert", ok_glb, folder],
                 ["synthesize", body, "-o", folder]):
        code, err = run(capsys, *argv)
        assert code == 2, argv
        assert err == [f"usdhands: error: {folder}: is a folder; give the output a file name"], argv
    assert list(folder.iterdir()) == []


def test_output_folder_not_writable(ok_glb, capsys, monkeypatch, tmp_path):
    """A folder the user may not write into was a PermissionError traceback (mkstemp)."""
    import tempfile

    def refuse(*a, **k):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", refuse)
    out = tmp_path / "x.glb"
    for argv in (["convert", ok_glb, out], ["handmap", ok_glb, "-o", tmp_path / "m.json"]):
        code, err = run(capsys, *argv)
        assert code == 2
        assert len(err) == 1 and err[0].startswith("usdhands: error: ")
        assert err[0].endswith(f"cannot write into folder {str(tmp_path)!r}: Permission denied"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.glb"]


def test_plot_and_model_paths_refused_before_any_work(ok_glb, shared_assets, tmp_path, capsys):
    """splice/reduce --plot FILE were FileExistsError tracebacks after the output was written;
    reduce --model FOLDER an IsADirectoryError, --model in a missing folder a FileNotFoundError."""
    leap = shared_assets / "leap_hands" / "fingers-ok.bvh"
    folder = tmp_path / "outdir"
    folder.mkdir()
    cases = [
        (["splice", ok_glb, leap, "-o", tmp_path / "sp.glb", "--plot", ok_glb],
         f"{ok_glb}: --plot needs a folder; this is a file"),
        (["reduce", ok_glb, "-o", tmp_path / "r.glb", "--plot", ok_glb], f"{ok_glb}: --plot needs a folder; this is a file"),
        (["reduce", ok_glb, "--model", folder], f"{folder}: is a folder; give the output a file name"),
        (["reduce", ok_glb, "--model", tmp_path / "nope" / "m.json"],
         f"{tmp_path / 'nope' / 'm.json'}: output folder '{tmp_path / 'nope'}' does not exist"),
    ]
    for argv, message in cases:
        code, err = run(capsys, *argv)
        assert (code, err) == (2, [f"usdhands: error: {message}"]), argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.glb", "outdir"]
    assert list(folder.iterdir()) == []


def test_samples_folder_that_cannot_be_made(tmp_path, capsys, monkeypatch):
    """samples into a folder the user may not create was a PermissionError traceback."""
    from pathlib import Path

    def refuse(self, *a, **k):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(Path, "mkdir", refuse)
    code, err = run(capsys, "samples", tmp_path / "s")
    assert (code, err) == (2, [f"usdhands: error: {tmp_path / 's'}: cannot create the folder: Operation not permitted"])


def test_k_above_segment_count_is_capped(sample_assets, tmp_path, capsys):
    """--k 100000 asked numpy for a (100000, 100000, 45) transition array (3.27 TiB MemoryError);
    more candidates than the database has segments give the same result as all of them."""
    from usdhands.algorithms.synthesis.database import load_database
    from usdhands.jobs.inputs import bundled_database_path

    db = load_database(bundled_database_path())
    most = int(max((db.segment_side() == s).sum() for s in (0, 1)))
    body = tmp_path / "body.bvh"
    shutil.copy(sample_assets / "gestures_bodyonly" / "turn_05_bodyonly.bvh", body)
    for k in (most, 100000):
        code, err = run(capsys, "synthesize", body, "-o", tmp_path / f"k{k}.bvh", "--k", k)
        assert code == 0, err
    assert (tmp_path / f"k{most}.bvh").read_bytes() == (tmp_path / "k100000.bvh").read_bytes()


def _hand_map(tmp_path, name, right, left=None):
    import json

    path = tmp_path / name
    path.write_text(json.dumps({"left": left, "right": right}))
    return path


def test_hand_maps_whose_joints_exist_but_do_not_form_hands(ok_glb, tmp_path, capsys):
    """Inverted or shared joints passed load_handmap: synthesize and db build died in wrist_features
    ('Finger joint ... does not hang from the wrist' ValueError), reduce in reduce_curves
    ('Duplicate curve names' ValueError)."""
    thumb = ["RightHandThumb1", "RightHandThumb2", "RightHandThumb3"]
    cases = [
        (_hand_map(tmp_path, "inverted.json", {"wrist": "RightHandThumb1", "fingers": {"thumb": ["RightHand"]}}),
         "right thumb finger: joint 'RightHand' does not hang below the wrist 'RightHandThumb1' "
         "(joints go proximal to distal)"),
        (_hand_map(tmp_path, "reversed.json", {"wrist": "RightHand", "fingers": {"thumb": thumb[::-1]}}),
         "right thumb finger: joint 'RightHandThumb2' does not hang below the previous joint 'RightHandThumb3' "
         "(joints go proximal to distal)"),
        (_hand_map(tmp_path, "other_hand.json", {"wrist": "RightHand", "fingers": {"thumb": ["LeftHandThumb1"]}}),
         "right thumb finger: joint 'LeftHandThumb1' does not hang below the wrist 'RightHand' "
         "(joints go proximal to distal)"),
        (_hand_map(tmp_path, "shared.json", {"wrist": "RightHand", "fingers": {"thumb": thumb}},
                   left={"wrist": "RightHand", "fingers": {"thumb": thumb}}),
         "right wrist: joint 'RightHand' is already the left wrist"),
        (_hand_map(tmp_path, "two_fingers.json", {"wrist": "RightHand", "fingers": {"thumb": thumb,
                                                                                    "index": thumb[1:]}}),
         "right index finger: joint 'RightHandThumb2' is already the right thumb finger"),
    ]
    for path, message in cases:
        for argv in (["inspect", ok_glb, "--handmap", path],
                     ["synthesize", ok_glb, "-o", tmp_path / "out.glb", "--handmap", path],
                     ["reduce", ok_glb, "--handmap", path],
                     ["db", "build", "-o", tmp_path / "db", ok_glb, "--handmap", path]):
            code, err = run(capsys, *argv)
            assert (code, err) == (2, [f"usdhands: error: {path}: {message}"]), argv
    assert not (tmp_path / "out.glb").exists() and not (tmp_path / "db").exists()


def test_config_that_is_a_folder(ok_glb, tmp_path, capsys):
    """--config FOLDER was an IsADirectoryError traceback."""
    folder = tmp_path / "cfg"
    folder.mkdir()
    code, err = run(capsys, "synthesize", ok_glb, "-o", tmp_path / "out.glb", "--config", folder)
    assert (code, err) == (2, [f"usdhands: error: {folder}: is a folder, not a file"])


def test_negative_seed(tmp_path, capsys):
    """--seed -1 was numpy's 'expected non-negative integer' traceback (evaluate: after the whole holdout)."""
    for argv in (["evaluate", "--holdout", "--samples", "--seed", "-1"], ["samples", tmp_path / "s", "--seed", "-1"]):
        code, err = run(capsys, *argv)
        assert (code, err) == (2, ["usdhands: error: --seed must be 0 or more, got -1"]), argv
    assert list(tmp_path.iterdir()) == []


def test_splice_bad_marker_file_is_the_only_line(ok_glb, shared_assets, tmp_path, capsys):
    """The note 'HANDS has no left hand' was printed before a bad marker file's error: two lines."""
    bad = tmp_path / "markers.csv"
    bad.write_text("a,b\n1,2\n")
    leap = shared_assets / "leap_hands" / "fingers-ok.bvh"
    code, err = run(capsys, "splice", ok_glb, leap, "-o", tmp_path / "out.glb", "--body-markers", bad)
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith(f"usdhands: error: {bad}: row 1: unknown column 'a'")
    assert not (tmp_path / "out.glb").exists()


@pytest.mark.parametrize("value", ["nan", "inf"])
def test_splice_hand_yaw_must_be_finite(value, ok_glb, shared_assets, tmp_path, capsys):
    """--hand-yaw nan was accepted and spliced with a NaN heading."""
    leap = shared_assets / "leap_hands" / "fingers-ok.bvh"
    code, err = run(capsys, "splice", ok_glb, leap, "-o", tmp_path / "out.glb", "--yaw", "trunk",
                    "--hand-yaw", value)
    assert (code, err) == (2, [f"usdhands: error: bad --hand-yaw {value}: expected a finite angle in degrees"])
    assert not (tmp_path / "out.glb").exists()


def test_reduction_model_with_non_finite_numbers(ok_glb, tmp_path, capsys):
    """A NaN constant passed the model checks and expand silently kept the input's curve."""
    import json

    model = tmp_path / "model.json"
    assert run(capsys, "reduce", ok_glb, "--model", model)[0] == 0
    d = json.loads(model.read_text())
    cases = []
    for name, edit, message in (
            ("nan_constant", lambda m: m["constants"][0].update(value=float("nan")),
             "reduction model file is not valid JSON: NaN is not a JSON number"),
            ("inf_mean", lambda m: m["means"].update({next(iter(m["means"])): float("inf")}),
             "reduction model file is not valid JSON: Infinity is not a JSON number"),
            ("overflowing_mean", lambda m: m["means"].update({next(iter(m["means"])): "1e999"}),
             f"mean of {next(iter(d['means']))!r} is not finite (inf)")):
        m = json.loads(model.read_text())
        edit(m)
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps(m).replace('"1e999"', "1e999"))  # parses as inf
        cases.append((path, message))
    for path, message in cases:
        code, err = run(capsys, "expand", ok_glb, "--model", path, "-o", tmp_path / "out.glb")
        assert (code, err) == (2, [f"usdhands: error: {path}: {message}"])
    assert not (tmp_path / "out.glb").exists()


# -- options a command would not use (issue 8: command-line misuse) ----------------------------

#: batch job -> the job options it reads (from each job's options class: what the job does with them)
BATCH_READS = {
    "synthesize": {"--animation", "--handmap", "--hands", "--db", "--k", "--config", "--finger-reference", "--props",
                   "--margin", "--self", "--attach", "--prop-units", "--prop-up", "--interaction-config"},
    "correct": {"--animation", "--handmap", "--props", "--margin", "--self", "--attach", "--prop-units", "--prop-up",
                "--interaction-config"},
    "reduce": {"--animation", "--handmap", "--hands", "--steps"},
    "expand": {"--animation", "--model"},
    "convert": {"--animation", "--to", "--fps", "--bvh-units"},
    "check": {"--require-provenance", "--tolerance", "--props", "--self", "--attach", "--prop-units", "--prop-up",
              "--interaction-config"},
}
#: every job option of batch -> the arguments it is given with (at the default value where it has one:
#: given is given)
BATCH_OPTION_ARGS = {
    "--animation": ["0"], "--handmap": ["m.json"], "--hands": ["left"], "--db": ["db"], "--k": ["3"],
    "--config": ["c.json"], "--finger-reference": ["rest"], "--steps": ["pca"], "--model": ["m.json"],
    "--to": ["usda"], "--fps": ["30"], "--bvh-units": ["cm"], "--require-provenance": [], "--props": ["p.obj"],
    "--margin": ["0"], "--self": [], "--attach": ["p=LeftHand"], "--prop-units": ["1"], "--prop-up": ["Y"],
    "--interaction-config": ["i.json"], "--tolerance": ["0.5"],
}


def test_batch_job_options_are_the_ones_classified_here():
    from usdhands.cli import build_parser

    batch = build_parser()._subparsers._group_actions[0].choices["batch"]
    [group] = [g for g in batch._action_groups if g.title == "job options"]
    assert {a.option_strings[-1] for a in group._group_actions} == set(BATCH_OPTION_ARGS)
    assert set(BATCH_READS) == set(batch._option_string_actions["--job"].choices)


@pytest.mark.parametrize("job, option", [(j, o) for j in sorted(BATCH_READS) for o in BATCH_OPTION_ARGS
                                         if o not in BATCH_READS[j]])
def test_batch_refuses_an_option_its_job_does_not_use(job, option, ok_glb, tmp_path, capsys):
    """`--job reduce --props x`, `--job convert --handmap m.json`... were accepted and did nothing."""
    out = tmp_path / "out"
    code, err = run(capsys, "batch", ok_glb, "--job", job, "--out", out, option, *BATCH_OPTION_ARGS[option])
    assert (code, err) == (2, [f"usdhands: error: {option} is not an option of --job {job}"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.glb"]


@pytest.mark.parametrize("job", sorted(BATCH_READS))
def test_batch_takes_the_options_its_job_uses(job, tmp_path, capsys):
    """Each option a job reads gets past that check (the run then stops at the missing input clip)."""
    for option in sorted(BATCH_READS[job]):
        code, err = run(capsys, "batch", tmp_path / "none.glb", "--job", job, "--out", tmp_path / "out", option,
                        *BATCH_OPTION_ARGS[option])
        assert code == 2 and len(err) == 1 and "is not an option of" not in err[0], (option, err)


#: command line (without the prop options) -> the prop options it takes
PROP_COMMANDS = {
    "synthesize": (["synthesize", "{clip}", "-o", "{out}.glb"], PROP_OPTIONS := ["--self", "--interaction-config",
                                                                                "--attach", "--prop-units",
                                                                                "--prop-up", "--margin"]),
    "db build": (["db", "build", "{clip}", "-o", "{out}_db"], PROP_OPTIONS),
    "check": (["check", "{clip}"], [o for o in PROP_OPTIONS if o != "--margin"]),
    "batch synthesize": (["batch", "{clip}", "--job", "synthesize", "--out", "{out}_batch"], PROP_OPTIONS),
    "batch check": (["batch", "{clip}", "--job", "check", "--out", "{out}_batch"],
                    [o for o in PROP_OPTIONS if o != "--margin"]),
}
PROP_VALUES = {"--self": [], "--interaction-config": ["{config}"], "--attach": ["p=LeftHand"], "--prop-units": ["1"],
               "--prop-up": ["Y"], "--margin": ["2"]}


@pytest.mark.parametrize("command, option", [(c, o) for c in sorted(PROP_COMMANDS) for o in PROP_COMMANDS[c][1]])
def test_prop_options_without_props_refused(command, option, ok_glb, tmp_path, capsys):
    """`--self` and `--interaction-config` without `--props` were accepted and did nothing (exit 0)."""
    config = tmp_path / "interaction.json"
    config.write_text('{"tip_fraction": 0.8}\n')
    argv, _ = PROP_COMMANDS[command]
    fill = {"clip": ok_glb, "out": tmp_path / "out", "config": config}
    code, err = run(capsys, *[a.format(**fill) for a in argv + [option, *PROP_VALUES[option]]])
    assert (code, err) == (2, [f"usdhands: error: {option} needs --props (nothing else reads it)"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["interaction.json", "ok.glb"]


@pytest.mark.parametrize("command", sorted(PROP_COMMANDS))
def test_a_missing_interaction_config_without_props_is_named(command, ok_glb, tmp_path, capsys):
    argv, _ = PROP_COMMANDS[command]
    missing = tmp_path / "missing.json"
    code, err = run(capsys, *[a.format(clip=ok_glb, out=tmp_path / "out") for a in argv],
                    "--interaction-config", missing)
    assert code == 2 and len(err) == 1 and err[0].startswith(f"usdhands: error: {missing}: no such"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.glb"]


def test_jobs_refuse_prop_options_without_props(ok_glb, tmp_path):
    """The same through the jobs API (a pipeline's script, batch's workers)."""
    from usdhands.errors import UsdHandsError
    from usdhands.jobs.database import BuildDbOptions, build_db
    from usdhands.jobs.synthesis import SynthesizeOptions, synthesize
    from pxr import Usd

    from usdhands.formats.io import read_asset, write_asset
    from usdhands.jobs.validation import CheckOptions, check
    from usdhands.usd import check_stage

    usda = tmp_path / "ok.usda"
    write_asset(read_asset(ok_glb), usda)
    calls = [lambda: synthesize(ok_glb, tmp_path / "o.glb", SynthesizeOptions(self_collision=True)),
             lambda: build_db([ok_glb], tmp_path / "db", BuildDbOptions(self_collision=True)),
             lambda: check([ok_glb], CheckOptions(self_collision=True)),
             lambda: check_stage(Usd.Stage.Open(str(usda)), CheckOptions(self_collision=True))]
    for call in calls:
        with pytest.raises(UsdHandsError, match=r"^--self needs --props \(nothing else reads it\)$"):
            call()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.glb", "ok.usda"]

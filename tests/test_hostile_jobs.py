"""Side files given to the jobs API (library callers, pipelines, stage hooks) get the CLI's checks.

A named pipe blocks a read forever and ``/dev/zero`` never ends: the command line refuses
them before any work (``check_paths``), and so must every job and stage hook a pipeline
calls directly, for every side file (hand maps, configurations, databases and the arrays
inside them, props, models, marker files). Each call runs in one subprocess under resource
limits, each case under an alarm: a hang is a failure, not a stuck test run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from hostile import ROOT, _limits  # noqa: E402  (tests/ is on sys.path)

DRIVER = textwrap.dedent('''
    import json, os, shutil, signal, sys
    from pathlib import Path

    class Hang(Exception):
        pass

    def alarm(*_):
        raise Hang()

    signal.signal(signal.SIGALRM, alarm)
    import usdhands
    from usdhands.errors import UsdHandsError

    samples, folder, kind = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
    good = folder / "good.glb"
    shutil.copy(samples / "gestures" / "ok_00.glb", good)
    body = folder / "body.glb"
    shutil.copy(samples / "conversation_bodyonly.glb", body)
    x = folder / "side.json"
    if kind == "fifo":
        os.mkfifo(x)
    elif kind == "devzero":
        x.symlink_to("/dev/zero")
    else:
        x.mkdir()
    table = samples / "props" / "table.obj"
    cup = folder / "cup.glb"
    shutil.copy(samples / "interaction" / "cup_grasp.glb", cup)
    S = usdhands.SynthesizeOptions

    def stage_hook(**options):
        from pxr import Usd
        from usdhands.usd import synthesize_stage
        stage = Usd.Stage.Open(str(samples / "humanoid.usda"))
        return synthesize_stage(stage, options=S(**options))

    def database_array():
        db = folder / "db"
        shutil.copytree(Path(usdhands.__file__).parent / "data" / "gesture_db", db)
        (db / "fingers.npy").unlink()
        if kind == "folder":
            (db / "fingers.npy").mkdir()
        else:
            os.replace(x, db / "fingers.npy") if kind == "fifo" else (db / "fingers.npy").symlink_to("/dev/zero")
            if kind == "fifo":
                os.mkfifo(x)
        return usdhands.synthesize(body, folder / "o.glb", S(db=db))

    def read_props():
        from usdhands.formats.props import read_props
        return read_props(x, meters_per_unit=0.01, up_axis="Y")

    calls = {
        "synthesize handmap": lambda: usdhands.synthesize(body, folder / "o.glb", S(handmap=x)),
        "synthesize config": lambda: usdhands.synthesize(body, folder / "o.glb", S(config=x)),
        "synthesize db": lambda: usdhands.synthesize(body, folder / "o.glb", S(db=x)),
        "synthesize props": lambda: usdhands.synthesize(body, folder / "o.glb", S(props=(x,))),
        "synthesize interaction_config": lambda: usdhands.synthesize(body, folder / "o.glb",
                                                                    S(props=(table,), interaction_config=x)),
        "synthesize database array": database_array,
        "reduce handmap": lambda: usdhands.reduce(good, None, usdhands.ReduceOptions(handmap=x)),
        "expand model": lambda: usdhands.expand(good, x, folder / "o.glb"),
        "splice body_markers": lambda: usdhands.splice(body, good, folder / "o.glb",
                                                       usdhands.SpliceOptions(body_markers=x)),
        "splice hands_markers": lambda: usdhands.splice(body, good, folder / "o.glb",
                                                        usdhands.SpliceOptions(hands_markers=x)),
        "splice hands_handmap": lambda: usdhands.splice(body, good, folder / "o.glb",
                                                        usdhands.SpliceOptions(hands_handmap=x)),
        "correct props": lambda: usdhands.correct(cup, folder / "o.glb", usdhands.CorrectOptions(props=(x,))),
        "correct handmap": lambda: usdhands.correct(cup, folder / "o.glb",
                                                    usdhands.CorrectOptions(props=(table,), handmap=x)),
        "correct interaction_config": lambda: usdhands.correct(
            cup, folder / "o.glb", usdhands.CorrectOptions(props=(table,), interaction_config=x)),
        "stage hook handmap": lambda: stage_hook(handmap=x),
        "stage hook config": lambda: stage_hook(config=x),
        "stage hook db": lambda: stage_hook(db=x),
        "read_props": read_props,
    }
    results = {}
    for name, call in calls.items():
        signal.alarm(60)
        try:
            call()
            results[name] = "no error"
        except Hang:
            results[name] = "HANG"
        except UsdHandsError as e:
            results[name] = "error: " + str(e)
        except Exception as e:
            results[name] = f"{type(e).__name__}: {e}"
        finally:
            signal.alarm(0)
        left = sorted(p.name for p in folder.iterdir() if p.name.startswith("o"))
        if left:
            results[name] += f" (left {left})"
            for p in folder.glob("o*"):
                p.unlink()
    print(json.dumps(results))
''')

#: kind of side file -> what the one-line error must say (a database "file" is a folder name)
WORDS = {"fifo": ("not a regular file",), "devzero": ("not a regular file",),
         "folder": ("is a folder", "finger database")}


@pytest.mark.parametrize("kind", sorted(WORDS))
def test_jobs_refuse_side_files_that_are_not_regular_files(kind, sample_assets, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", DRIVER, str(sample_assets), str(tmp_path), kind], env=env,
                          capture_output=True, text=True, timeout=900, preexec_fn=_limits(3 * 1024 ** 3, 600))
    assert done.returncode == 0, done.stderr[-3000:]
    results = json.loads(done.stdout.strip().splitlines()[-1])
    wrong = {name: r for name, r in results.items()
             if not (r.startswith("error: ") and any(w in r for w in WORDS[kind]) and "\n" not in r
                     and "(left" not in r)}
    assert wrong == {}, json.dumps(wrong, indent=1)


@pytest.mark.parametrize("named", ["../fingers.npy", "/etc/passwd"])
def test_a_database_manifest_names_files_inside_its_folder(named, tmp_path):
    """A manifest naming an array outside its folder is refused before anything is read there."""
    import shutil
    from pathlib import Path

    import usdhands
    from usdhands.algorithms.synthesis.database import load_database
    from usdhands.errors import ConfigError

    db = tmp_path / "db"
    shutil.copytree(Path(usdhands.__file__).parent / "data" / "gesture_db", db)
    manifest = json.loads((db / "manifest.json").read_text())
    manifest["arrays"]["fingers"]["file"] = named
    (db / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ConfigError) as e:
        load_database(db)  # the schema allows a plain file name only
    assert str(e.value).startswith(f"{db / 'manifest.json'}: invalid database manifest at arrays/fingers/file")
    with pytest.raises(ConfigError) as e:
        load_database(db, check_schema=False)  # how the bundled database is loaded: checked all the same
    assert str(e.value) == f"{db / 'manifest.json'}: array 'fingers': file {named!r} is outside the database folder"

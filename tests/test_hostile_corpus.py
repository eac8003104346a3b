"""A hostile corpus, generated from the samples, run through every command.

Each class of bad input of issue 8 (missing, folder, named pipe, /dev/zero, empty,
truncated, not UTF-8, JSON nested 100,000 deep, NaN, huge integers, lying offsets,
absurd sizes, a newline in the name, outputs that cannot be written, unknown options,
crafted .usdc files, a reader warning before the error)
is built by code, given to every command in :data:`COMMANDS` as its main input and to
each side-file option in :data:`SIDE_FILES`, and must keep the promise: exit status 2,
exactly one stderr line ``usdhands: error: FILE: ...`` naming the bad file (USD's own
diagnostics included: file descriptor 2 is captured), nothing written or left behind,
every input unchanged. Each command's cases run in one subprocess under resource
limits (tests/hostile.py).

Adding a command is one line in :data:`COMMANDS` (and one in :data:`SIDE_FILES` for
its side-file options).
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from hostile import crate_lies, crate_seed, deep_json, glb_bytes, listing, run_batch, sha  # noqa: E402

#: command -> its argument list; {input} is the hostile (or good) main input, {ext} its extension,
#: {out} an output path without extension, {good} a good clip, {body} a body-only clip,
#: {model} a reduction model
COMMANDS: dict[str, list[str]] = {
    "inspect": ["inspect", "{input}"],
    "handmap": ["handmap", "{input}", "-o", "{out}.json"],
    "convert": ["convert", "{input}", "{out}.usda"],
    "db build": ["db", "build", "{input}", "-o", "{out}_db"],
    "synthesize": ["synthesize", "{input}", "-o", "{out}{ext}"],
    "evaluate": ["evaluate", "{input}", "{good}", "--labels", "(.)"],
    "splice": ["splice", "{body}", "{input}", "-o", "{out}.glb"],
    "reduce": ["reduce", "{input}", "-o", "{out}{ext}"],
    "expand": ["expand", "{input}", "--model", "{model}", "-o", "{out}{ext}"],
    "correct": ["correct", "{input}", "--props", "{prop}", "-o", "{out}{ext}"],
    "check": ["check", "{input}"],
    "batch": ["batch", "{input}", "--job", "convert", "--to", "usda", "--out", "{out}_batch", "--workers", "1"],
}

#: command -> side-file option -> (kind of file it takes, "json" or "csv"; option of the
#: command's template it replaces, or None)
SIDE_FILES: dict[str, dict[str, tuple[str, str | None]]] = {
    "inspect": {"--handmap": ("json", None)},
    "handmap": {"--handmap": ("json", None)},
    "db build": {"--handmap": ("json", None), "--config": ("json", None), "--labels-file": ("csv", None),
                 "--props": ("mesh", None), "--interaction-config": ("json", None)},
    "synthesize": {"--handmap": ("json", None), "--config": ("json", None), "--props": ("mesh", None),
                   "--interaction-config": ("json", None)},
    "evaluate": {"--config": ("json", None), "--labels-file": ("csv", "--labels"), "--handmap": ("json", None)},
    "splice": {"--hands-markers": ("csv", None), "--body-markers": ("csv", None), "--body-handmap": ("json", None),
               "--hands-handmap": ("json", None)},
    "reduce": {"--handmap": ("json", None)},
    "expand": {"--model": ("json", "--model")},
    "correct": {"--handmap": ("json", None), "--interaction-config": ("json", None), "--props": ("mesh", "--props")},
    "check": {"--props": ("mesh", None), "--interaction-config": ("json", None)},
    # batch refuses its side files before any clip runs (the content of props is read per clip); each is
    # given to a job that reads it (BATCH_JOB_OF)
    "batch": {"--handmap": ("json", None), "--config": ("json", None), "--model": ("json", None),
              "--interaction-config": ("json", None), "--props": ("file", None), "--db": ("folder", None)},
}

#: batch side-file option -> the job options (in place of the template's ``--job convert --to usda``) of a
#: job that reads it: batch refuses an option its job does not use
BATCH_JOB_OF = {"--handmap": ["--job", "reduce"], "--config": ["--job", "synthesize"], "--model": ["--job", "expand"],
                "--interaction-config": ["--job", "correct", "--props", "{prop}"], "--props": ["--job", "check"],
                "--db": ["--job", "synthesize"]}


def _split_glb(raw: bytes) -> tuple[dict, bytes]:
    n = int.from_bytes(raw[12:16], "little")
    return json.loads(raw[20:20 + n]), raw[20 + n + 8:]


def main_input_cases(folder: Path, samples: Path) -> dict[str, tuple[Path, str]]:
    """Hostile main inputs: class -> (path, piece of the expected message)."""
    ok = (samples / "gestures" / "ok_00.glb").read_bytes()
    doc, binary = _split_glb(ok)
    usda = (samples / "humanoid.usda").read_text()
    bvh_lines = (samples / "humanoid.bvh").read_text().splitlines()
    cases: dict[str, tuple[Path, str]] = {}

    def add(name: str, filename: str, content, message: str) -> None:
        path = folder / filename
        if isinstance(content, str):
            path.write_text(content)
        elif isinstance(content, bytes):
            path.write_bytes(content)
        else:
            content(path)
        cases[name] = (path, message)

    add("missing", "missing.glb", lambda p: None, "no such file")
    add("folder", "folder.glb", lambda p: p.mkdir(), "")  # evaluate reads a folder's files
    add("fifo", "pipe.glb", lambda p: os.mkfifo(p), "not a regular file")
    add("devzero", "zero.bvh", lambda p: p.symlink_to("/dev/zero"), "not a regular file")
    add("empty", "empty.glb", b"", "")
    add("truncated", "half.glb", ok[:len(ok) // 2], "truncated .glb")
    # a reader warning (an unusable recorded fps) before the error (a channel naming a missing sampler):
    # at default verbosity the error alone
    warned = json.loads(json.dumps(doc))
    broken = json.loads(json.dumps(warned["animations"][0]))
    warned["animations"][0]["extras"] = {"usdhands": {"fps": -1}}
    broken["channels"][0]["sampler"] = 99
    warned["animations"].append(broken)
    add("warning_then_error", "warned.glb", glb_bytes(warned, binary), "sampler 99 out of range")
    add("newline_in_name", "new\nline.glb", ok[:30], "")
    add("deep_json", "deep.gltf", '{"asset": {"version": "2.0"}, "extras": ' + deep_json(100_000) + "}",
        "nested 100001 deep")
    add("nan_json", "nan.glb", glb_bytes(json.dumps(doc).replace('"scene": 0', '"scene": NaN', 1), binary),
        "NaN is not a JSON number")
    big = dict(doc, bufferViews=[dict(v, byteOffset=-1e308) for v in doc["bufferViews"]])
    add("byte_offset", "offset.glb", glb_bytes(json.dumps(big), binary), "is not an integer from 0 to 2^53")
    many = {"asset": {"version": "2.0"}, "nodes": [{"children": [i + 1]} for i in range(100_000)] + [{}]}
    add("many_nodes", "many.gltf", json.dumps(many), "more than 10,000 are refused")
    add("usda_not_utf8", "latin.usda", usda.encode()[:200] + b"\xff\xfe\xfd" + usda.encode()[200:], "")
    add("usd_far_time", "far.usda", usda.replace("quatf[] rotations.timeSamples = {",
                                                 "quatf[] rotations.timeSamples = {\n 1e12: [(1, 0, 0, 0)],", 1),
        "more than 1,000,000 are refused")
    add("usd_mpu_zero", "mpu0.usda", usda.replace("metersPerUnit = 0.01", "metersPerUnit = 0"),
        "metersPerUnit 0")
    first = next(k for k, line in enumerate(bvh_lines) if line.startswith("Frame Time")) + 1
    far = list(bvh_lines)
    far[first] = " ".join(["1e308"] + far[first].split()[1:])
    add("bvh_far_root", "far.bvh", "\n".join(far) + "\n", "beyond 1e+30")
    motion = bvh_lines.index("MOTION")
    add("bvh_unclosed", "open.bvh", "\n".join(bvh_lines[:motion - 1] + bvh_lines[motion:]) + "\n", "")
    # usdc fuzz findings: a table of contents of 117 million sections (> 3 GB), a token index past the table
    # (a segfault), a section past the end (USD's posix_madvise line on stderr), a prim spec typed as a Mapper
    # and a listed child without a spec (SIGABRT), also through a sublayer
    lies = crate_lies(crate_seed(samples, folder))
    for name in ("toc_sections", "token_index", "section_past_end", "spec_type", "child_without_spec"):
        data, message = lies[name]
        add(f"usdc_{name}", f"{name}.usdc", data, message)
    (folder / "lie_sub.usdc").write_bytes(lies["token_index"][0])
    add("usda_composes_lie", "composes.usda", "#usda 1.0\n(\n    subLayers = [@./lie_sub.usdc@]\n)\n",
        "composes")
    return cases


#: kind of side file -> its extension; "file": any file whose content is read later (the classes
#: every reader refuses alike), "folder": a folder (a finger database)
SIDE_KINDS = {"json": ".json", "csv": ".csv", "mesh": ".obj", "file": ".glb", "folder": ""}


def side_file_cases(folder: Path, kind: str) -> dict[str, tuple[Path, str]]:
    """Hostile side files of a kind (:data:`SIDE_KINDS`): class -> (path, piece of the expected message)."""
    ext = SIDE_KINDS[kind]
    cases: dict[str, tuple[Path, str]] = {}

    def add(name: str, content, message: str) -> None:
        path = folder / f"{name}{ext}"
        if isinstance(content, (str, bytes)):
            path.write_bytes(content.encode() if isinstance(content, str) else content)
        else:
            content(path)
        cases[name] = (path, message)

    add("missing", lambda p: None, "no such")
    if kind == "folder":
        add("a_file", b"not a database\n", "is a file, not a finger database")
    else:
        add("folder", lambda p: p.mkdir(), "is a folder")
    add("fifo", lambda p: os.mkfifo(p), "not a regular file")
    add("devzero", lambda p: p.symlink_to("/dev/zero"), "not a regular file")
    if kind in ("json", "csv"):
        add("not_utf8", b"\xff\xfe\x00\x81 not text\n", "not UTF-8")
    if kind == "mesh":
        triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
        add("empty", b"", "has no triangles")
        add("nan_vertex", triangle.replace("v 0 0 0", "v nan 0 0") + "f 1 2 3\n", "NaN or infinite coordinates")
        add("face_index", triangle + "f 1 2 99\n", "cannot read as a mesh")
        add("far_vertices", "v 1e308 0 0\nv -1e308 0 0\nv 0 1e308 0\nf 1 2 3\n", "")
    if kind == "json":
        add("deep", '{"a": ' + deep_json(100_000) + "}", "nested 100001 deep")
        add("nan", '{"a": NaN}', "NaN is not a JSON number")
        add("bigint", '{"a": ' + "7" * 5000 + "}", "4300 digits")
    return cases


@pytest.fixture(scope="module")
def corpus(tmp_path_factory, sample_assets):
    """Good inputs (a take, a body-only clip, a reduction model) and the hostile files, in one folder."""
    from usdhands.cli import main

    folder = tmp_path_factory.mktemp("hostile")
    good = folder / "good_ok.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", good)
    body = folder / "good_body.glb"
    shutil.copy(sample_assets / "conversation_bodyonly.glb", body)
    model = folder / "good_model.json"
    assert main(["reduce", str(good), "--model", str(model)]) == 0
    (folder / "main").mkdir()
    main_cases = main_input_cases(folder / "main", sample_assets)
    side = {}
    for kind in SIDE_KINDS:
        (folder / kind).mkdir()
        side[kind] = side_file_cases(folder / kind, kind)
    prop = folder / "good_table.obj"
    shutil.copy(sample_assets / "props" / "table.obj", prop)
    return {"folder": folder, "good": good, "body": body, "model": model, "prop": prop, "main": main_cases,
            "side": side}


def _fill(template: list[str], corpus, input_path: Path, out: Path) -> list[str]:
    values = {"input": input_path, "good": corpus["good"], "body": corpus["body"], "model": corpus["model"],
              "prop": corpus["prop"], "out": out, "ext": input_path.suffix or ".glb"}
    return [a.format(**values) for a in template]


def _check(results, expected, corpus, command: str = ""):
    """The failures among ``results``: each must be one error line naming the file, exit 2; or, for
    ``check``, its findings on that file (exit 1, the summary line alone on stderr); or, for
    ``batch``, the clip recorded as failed with that line in ``report.json`` (exit 1: a failing
    clip does not stop a batch), nothing else written (the batch's folder is then removed)."""
    inputs = [corpus["good"], corpus["body"], corpus["model"]]
    failures = []
    for (label, path, message, out_dir), result in zip(expected, results):
        lines = result["stderr"].rstrip("\n").split("\n") if result["stderr"].strip() else []
        shown = str(path).replace("\n", "\\n")
        ok = (result["code"] == 2 and len(lines) == 1 and lines[0].startswith(f"usdhands: error: {shown}")
              and message in lines[0])
        if not ok and command == "check" and result["code"] == 1:  # a rule found something in the file
            found = result["stdout"].splitlines()
            ok = (found != [] and all(f.startswith(str(path)) for f in found) and len(lines) == 1
                  and lines[0].startswith("checked 1 file(s): 0 passed"))
        if not ok and command == "batch" and result["code"] == 1 and out_dir is not None:
            report = json.loads((out_dir / "report.json").read_text())
            [clip] = report["clips"]
            ok = (clip["status"] == "failed" and clip["error"].startswith(shown) and message in clip["error"]
                  and sorted(p.name for p in out_dir.iterdir()) == ["batch_options.json", "report.json"]
                  and "Traceback" not in result["stderr"] and "\n" not in clip["error"])
        if out_dir is not None and out_dir.exists():
            shutil.rmtree(out_dir)
        if not ok:
            failures.append(f"{label}: exit {result['code']}, stderr {result['stderr'][-400:]!r}")
    return failures, inputs


def _batch_out(argv: list[str]) -> Path | None:
    """The ``--out`` folder of a batch command line (None for other commands)."""
    return Path(argv[argv.index("--out") + 1]) if argv[0] == "batch" else None


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_hostile_input_keeps_the_promise(command, corpus):
    folder = corpus["folder"]
    out_folder = folder / "out" / command.replace(" ", "_")
    out_folder.mkdir(parents=True)
    cases, expected = [], []
    for name, (path, message) in corpus["main"].items():
        cases.append(_fill(COMMANDS[command], corpus, path, out_folder / f"case{len(cases)}"))
        expected.append((f"input {name}", path, message, _batch_out(cases[-1])))
    for option, (kind, replaces) in SIDE_FILES.get(command, {}).items():
        for name, (path, message) in corpus["side"][kind].items():
            template = COMMANDS[command]
            if command == "batch":
                k = template.index("--job")
                template = template[:k] + BATCH_JOB_OF[option] + template[k + 4:]
            argv = _fill(template, corpus, corpus["good"], out_folder / f"case{len(cases)}")
            if replaces is not None:  # drop the template's option this one stands for
                k = argv.index(replaces)
                del argv[k:k + 2]
            argv += [option, str(path)]
            cases.append(argv)
            expected.append((f"{option} {name}", path, message, None))
    # outputs that cannot be written, and a misused option (the message names the output or nothing)
    before = {p: sha(p) for p in (corpus["good"], corpus["body"], corpus["model"])}
    files_before = listing(folder)
    results = run_batch(cases)
    failures, inputs = _check(results, expected, corpus, command)
    assert failures == [], "\n".join(failures)
    assert listing(folder) == files_before, "an output or a temporary file was left behind"
    assert {p: sha(p) for p in inputs} == before


@pytest.mark.parametrize("command", sorted(c for c in COMMANDS if "{out}" in " ".join(COMMANDS[c])))
def test_unwritable_outputs_and_bad_options(command, corpus):
    folder = corpus["folder"]
    templates = COMMANDS[command]
    cases, expected = [], []
    blocker = folder / "a_file"
    blocker.touch()
    for label, out in (("folder is a file", blocker / "out"), ("name too long", folder / ("n" * 300))):
        argv = _fill(templates, corpus, corpus["good"], out)
        shown = next(a for a in argv if a.startswith(str(out)))
        cases.append(argv)
        expected.append((label, shown, "", None))
    cases.append(_fill(templates, corpus, corpus["good"], folder / "out") + ["--bogus"])
    expected.append(("unknown option", "", "unrecognized arguments: --bogus", None))
    files_before = listing(folder)
    results = run_batch(cases)
    failures, _ = _check(results, expected, corpus)
    assert failures == [], "\n".join(failures)
    assert listing(folder) == files_before

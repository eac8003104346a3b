"""Each finding of issue 8 ("everything else that broke") as a case built here, run bounded.

Every case is built from the committed samples by code (no stored binaries) and run
as ``python -m usdhands ...`` in a subprocess under ``resource`` limits (see
tests/hostile.py), and must keep the whole promise: one line
``usdhands: error: FILE: ...``, exit status 2, nothing written or left behind, every
input byte-identical.
"""

from __future__ import annotations

import json
import os
import shutil
import struct

import pytest

from hostile import check_promise, deep_json, run_bounded  # noqa: E402  (tests/ is on sys.path)


def glb_bytes(doc: dict | str, bin_chunk: bytes = b"") -> bytes:
    """A GLB file from a JSON document (or its text) and an optional binary chunk."""
    j = (doc if isinstance(doc, str) else json.dumps(doc)).encode()
    j += b" " * (-len(j) % 4)
    chunks = struct.pack("<II", len(j), 0x4E4F534A) + j
    if bin_chunk:
        bin_chunk += b"\0" * (-len(bin_chunk) % 4)
        chunks += struct.pack("<II", len(bin_chunk), 0x004E4942) + bin_chunk
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


def deep_gltf_text(depth: int) -> str:
    return '{"asset": {"version": "2.0"}, "extras": ' + deep_json(depth) + "}"


@pytest.mark.parametrize("kind", ["gltf", "glb", "handmap"])
def test_json_nested_100000_deep(kind, sample_assets, tmp_path):
    """RecursionError traceback from json.loads."""
    if kind == "gltf":
        bad = tmp_path / "deep.gltf"
        bad.write_text(deep_gltf_text(100_000))
        argv, inputs = ["inspect", bad], [bad]
    elif kind == "glb":
        bad = tmp_path / "deep.glb"
        bad.write_bytes(glb_bytes(deep_gltf_text(100_000)))
        argv, inputs = ["inspect", bad], [bad]
    else:
        glb = tmp_path / "ok.glb"
        shutil.copy(sample_assets / "gestures" / "ok_00.glb", glb)
        bad = tmp_path / "map.json"
        bad.write_text('{"left": ' + deep_json(100_000) + "}")
        argv, inputs = ["handmap", glb, "--handmap", bad, "-o", tmp_path / "out.json"], [glb, bad]
    check_promise(argv, folder=tmp_path, inputs=inputs, names=bad, message="nested 100001 deep")


def bvh_chain(joints: int) -> str:
    """A BVH whose joints form one chain ``joints`` deep, one frame of zeros."""
    lines = ["HIERARCHY", "ROOT j0", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
    for i in range(1, joints):
        lines += [f"JOINT j{i}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * joints
    lines += ["MOTION", "Frames: 1", "Frame Time: 0.033333", " ".join(["0"] * (6 + 3 * (joints - 1)))]
    return "\n".join(lines) + "\n"


def test_bvh_10000_joints_deep_reads_and_writes(tmp_path):
    """RecursionError in the hierarchy parser (and the writer): both are iterative now."""
    src = tmp_path / "deep.bvh"
    src.write_text(bvh_chain(10_000))
    out = tmp_path / "out.bvh"
    run = run_bounded(["convert", src, out])
    assert run.code == 0, run.stderr[-2000:]
    back = run_bounded(["inspect", "--json", out])
    assert back.code == 0, back.stderr[-2000:]
    skeleton = json.loads(back.stdout)["skeletons"][0]
    assert skeleton["num_joints"] == 10_001  # the chain and its End Site


def test_bvh_unclosed_deep_hierarchy_names_the_line(tmp_path):
    bad = tmp_path / "open.bvh"
    bad.write_text(bvh_chain(3000).replace("}\n}\nMOTION", "MOTION"))
    check_promise(["inspect", bad], folder=tmp_path, inputs=[bad], names=bad, message="missing '}'")


def test_config_with_a_5000_digit_integer(sample_assets, tmp_path):
    body = tmp_path / "body.glb"
    shutil.copy(sample_assets / "conversation_bodyonly.glb", body)
    cfg = tmp_path / "config.json"
    cfg.write_text('{"k": ' + "9" * 5000 + "}")
    check_promise(["synthesize", body, "--config", cfg, "-o", tmp_path / "out.glb"], folder=tmp_path,
                  inputs=[body, cfg], names=cfg, message="4300 digits")


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity"])
def test_config_with_non_finite_weights(literal, sample_assets, tmp_path):
    """NaN and Infinity were accepted ('mean cS nan' in the report)."""
    body = tmp_path / "body.glb"
    shutil.copy(sample_assets / "conversation_bodyonly.glb", body)
    cfg = tmp_path / "config.json"
    cfg.write_text('{"weights": {"velocity": %s}}' % literal)
    check_promise(["synthesize", body, "--config", cfg, "-o", tmp_path / "out.glb"], folder=tmp_path,
                  inputs=[body, cfg], names=cfg, message=f"{literal.lstrip('-')} is not a JSON number")


def test_labels_csv_not_utf8(sample_assets, tmp_path):
    clips = tmp_path / "clips"
    clips.mkdir()
    for name in ("ok_00.glb", "ok_01.glb"):
        shutil.copy(sample_assets / "gestures" / name, clips / name)
    labels = tmp_path / "labels.csv"
    labels.write_bytes(b"ok_00.glb,ok\nok_01.glb,\xff\xfe\n")
    check_promise(["evaluate", clips, "--labels-file", labels], folder=tmp_path,
                  inputs=[labels, *clips.iterdir()], names=labels, message="not UTF-8")


def test_output_name_over_the_file_system_limit(sample_assets, tmp_path):
    src = tmp_path / "ok.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", src)
    out = tmp_path / ("a" * 300 + ".usda")
    check_promise(["convert", src, out], folder=tmp_path, inputs=[src], names=out, message="File name too long")


def test_db_build_into_a_folder_that_cannot_be_made(sample_assets, tmp_path):
    """PermissionError / FileNotFoundError traceback from mkdtemp (root writes anywhere, so a file
    stands where the folder should be)."""
    src = tmp_path / "ok.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", src)
    blocker = tmp_path / "blocker"
    blocker.write_text("a file, not a folder")
    out = blocker / "db"
    check_promise(["db", "build", src, "-o", out], folder=tmp_path, inputs=[src, blocker], names=out,
                  message="cannot write into folder")


@pytest.mark.parametrize("kind", ["fifo", "devzero"])
@pytest.mark.parametrize("role", ["input", "handmap", "config", "labels", "model"])
def test_non_regular_files_are_refused(kind, role, sample_assets, tmp_path):
    """A named pipe hung forever; a symlink to /dev/zero ran out of memory."""
    src = tmp_path / "ok.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", src)
    odd = tmp_path / {"input": "odd.glb", "handmap": "map.json", "config": "config.json",
                      "labels": "labels.csv", "model": "model.json"}[role]
    if kind == "fifo":
        os.mkfifo(odd)
    else:
        odd.symlink_to("/dev/zero")
    out = tmp_path / "out.glb"
    argv = {"input": ["inspect", odd],
            "handmap": ["inspect", src, "--handmap", odd],
            "config": ["synthesize", src, "--config", odd, "-o", out],
            "labels": ["evaluate", src, "--labels-file", odd],
            "model": ["expand", src, "--model", odd, "-o", out]}[role]
    what = "a named pipe" if kind == "fifo" else "a device"
    check_promise(argv, folder=tmp_path, inputs=[src], names=odd, message=f"is {what}, not a regular file",
                  wall=60)


@pytest.mark.parametrize("argv,message", [
    (["convert", "--bogus", "a.glb", "b.glb"], "unrecognized arguments: --bogus"),
    (["convert", "--fps", "fast", "a.glb", "b.glb"], "argument --fps: invalid float value: 'fast'"),
    (["convert", "--bvh-units", "furlong", "a.bvh", "b.glb"], "argument --bvh-units: invalid choice: 'furlong'"),
    (["no-such-command"], "invalid choice: 'no-such-command'"),
])
def test_usage_errors_are_one_line(argv, message, tmp_path):
    """argparse printed its usage text (up to 4 lines) before the error."""
    run = run_bounded(argv, cwd=tmp_path)
    assert run.code == 2
    assert len(run.lines) == 1, run.stderr
    assert run.lines[0].startswith("usdhands: error: ") and message in run.lines[0], run.lines[0]


def test_help_keeps_its_usage(tmp_path):
    run = run_bounded(["convert", "--help"], cwd=tmp_path)
    assert run.code == 0 and run.stdout.startswith("usage: usdhands convert")


def test_file_name_with_a_newline_is_escaped(tmp_path):
    bad = tmp_path / "two\nlines.glb"
    bad.write_bytes(b"junk")
    check_promise(["inspect", bad], folder=tmp_path, inputs=[bad], names=str(bad).replace("\n", "\\n"),
                  message="truncated .glb")

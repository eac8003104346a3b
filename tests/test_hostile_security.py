"""Issue 8, "Security first": glTF URIs kept inside the glTF's folder, inputs that are not
regular files refused, and no output ever written over an input (side files included).

Every case is built here in ``tmp_path``: a ``.gltf`` whose buffer is an external file
(from the sample ``ok_00.glb``), files outside its folder, symlinks, FIFOs and hard links.
Cases that would block or run out of memory if the code were wrong run in a subprocess
with a timeout and an address-space limit.
"""

from __future__ import annotations

import base64
import hashlib
import os
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pygltflib
import pytest

from cli_helpers import run
from usdhands.formats.gltf_container import load_gltf, read_external, save_gltf
from usdhands.formats.io import read_clip

ROOT = Path(__file__).resolve().parent.parent
SECRET_SIZE = 123457  # the outside file's size: must never appear in a message
OUTSIDE_URI = "../../outside/secret.bin"


# --------------------------------------------------------------------------- helpers


def sha(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def snapshot(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (symlinks as their target) and its checksum: "nothing written"."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        if p.is_symlink():
            out[rel] = "-> " + os.readlink(p)
        elif p.is_file():
            out[rel] = sha(p)
        elif p.is_dir():
            out[rel] = "dir"
        else:
            out[rel] = "special"
    return out


def make_gltf(ok_glb: Path, folder: Path, uri: str | None = "humanoid.bin", images=()) -> Path:
    """``folder/humanoid.gltf`` with its buffer in ``folder/humanoid.bin`` (named by ``uri``) and
    unreferenced images of the given URIs; returns the .gltf."""
    doc = load_gltf(ok_glb)
    g = doc.gltf
    data = doc.buffers[0][: g.buffers[0].byteLength]
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "humanoid.bin").write_bytes(data)
    g.buffers[0].uri = uri
    g.images = [pygltflib.Image(uri=u) for u in images]
    save_gltf(g, [data], folder / "humanoid.gltf", glb=False)
    return folder / "humanoid.gltf"


@pytest.fixture()
def scene(ok_glb, tmp_path):
    """``tmp/a/b/humanoid.gltf`` (+ .bin, tex.png) and ``tmp/outside/secret.bin`` (the real buffer
    padded to SECRET_SIZE bytes, so reading it would succeed: the bug was exit 0)."""
    gltf = make_gltf(ok_glb, tmp_path / "a" / "b")
    (tmp_path / "outside").mkdir()
    data = (gltf.parent / "humanoid.bin").read_bytes()
    (tmp_path / "outside" / "secret.bin").write_bytes(data + b"\0" * (SECRET_SIZE - len(data)))
    (tmp_path / "outside" / "tex.png").write_bytes(b"\x89PNG outside")
    (gltf.parent / "tex.png").write_bytes(b"\x89PNG inside")
    ok_glb.unlink()
    return gltf


def set_uri(gltf: Path, uri: str, *, image: bool = False) -> None:
    g = pygltflib.GLTF2.gltf_from_json(gltf.read_text())
    if image:
        g.images = [pygltflib.Image(uri=uri)]
    else:
        g.buffers[0].uri = uri
    gltf.write_text(g.gltf_to_json())


def subprocess_python(*argv, cwd: Path, timeout: float = 120, memory: int = 1 << 30):
    """``python ARGV`` with a time and an address-space limit: (exit, stderr lines)."""
    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

    env = dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1")
    r = subprocess.run([sys.executable, *map(str, argv)], cwd=cwd, env=env, preexec_fn=limit,
                       capture_output=True, text=True, timeout=timeout)
    return r.returncode, r.stderr.strip().splitlines()


def subprocess_cli(*argv, cwd: Path, timeout: float = 120):
    """``usdhands ARGV`` in a subprocess under limits (:func:`subprocess_python`)."""
    return subprocess_python("-m", "usdhands", *argv, cwd=cwd, timeout=timeout)


# --------------------------------------------------------------------------- buffer URIs


def _escape_variants(tmp_path: Path, gltf: Path) -> dict[str, str]:
    """name -> buffer URI, each reaching tmp/outside/secret.bin (or a device) from gltf's folder."""
    folder = gltf.parent
    os.symlink(tmp_path / "outside" / "secret.bin", folder / "linked.bin")
    os.symlink(tmp_path / "outside", folder / "res")
    os.symlink("/dev/zero", folder / "zero.bin")
    return {
        "relative": OUTSIDE_URI,
        "percent-encoded": "..%2F..%2Foutside%2Fsecret.bin",
        "percent-encoded dots": "%2E%2E/%2E%2E/outside/secret.bin",
        "absolute": str(tmp_path / "outside" / "secret.bin"),
        "absolute percent-encoded": "%2F" + str(tmp_path / "outside" / "secret.bin").lstrip("/"),
        "deep relative": "../" * 12 + str(tmp_path / "outside" / "secret.bin").lstrip("/"),
        "symlinked file": "linked.bin",
        "symlinked folder": "res/secret.bin",
        "dev zero": "/dev/zero",
        "symlink to dev zero": "zero.bin",
        "inside then out": "sub/../../../outside/secret.bin",
    }


ESCAPES = ["relative", "percent-encoded", "percent-encoded dots", "absolute", "absolute percent-encoded",
           "deep relative", "symlinked file", "symlinked folder", "dev zero", "symlink to dev zero",
           "inside then out"]


@pytest.mark.parametrize("variant", ESCAPES)
def test_buffer_uri_out_of_folder_refused(scene, tmp_path, capsys, variant):
    uri = _escape_variants(tmp_path, scene)[variant]
    set_uri(scene, uri)
    before = snapshot(tmp_path)
    # a device read whole would exhaust memory: those cases run under limits in a subprocess
    cli = (lambda *a: subprocess_cli(*a, cwd=tmp_path)) if "zero" in variant else (lambda *a: run(capsys, *a))
    code, err = cli("inspect", scene)
    assert (code, err) == (2, [f"usdhands: error: {scene}: buffers[0]: buffer URI {uri!r} points outside "
                               "the glTF's folder"])
    assert str(SECRET_SIZE) not in err[0]
    out = tmp_path / "out.glb"
    code, err = cli("convert", scene, out)
    assert code == 2 and len(err) == 1 and "points outside the glTF's folder" in err[0]
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("uri", ["file:///etc/passwd", "http://example.com/humanoid.bin", "C:/x/humanoid.bin"])
def test_buffer_uri_with_a_scheme_refused(scene, capsys, uri):
    set_uri(scene, uri)
    code, err = run(capsys, "inspect", scene)
    assert (code, err) == (2, [f"usdhands: error: {scene}: buffers[0]: buffer URI {uri!r} is not a relative "
                               "file path"])


def test_etc_passwd_size_never_shown(scene, capsys):
    uri = "../" * 30 + "etc/passwd"
    set_uri(scene, uri)
    code, err = run(capsys, "inspect", scene)
    assert (code, err) == (2, [f"usdhands: error: {scene}: buffers[0]: buffer URI {uri!r} points outside "
                               "the glTF's folder"])
    assert str(os.path.getsize("/etc/passwd")) not in err[0]


def test_buffer_that_is_a_folder_refused(scene, capsys):
    (scene.parent / "sub").mkdir()
    set_uri(scene, "sub")
    code, err = run(capsys, "inspect", scene)
    assert (code, err) == (2, [f"usdhands: error: {scene}: buffers[0]: buffer file 'sub' is not a regular file"])


def test_buffer_that_is_a_fifo_refused_without_blocking(scene, tmp_path):
    (scene.parent / "humanoid.bin").unlink()
    os.mkfifo(scene.parent / "humanoid.bin")
    before = snapshot(tmp_path)
    code, err = subprocess_cli("inspect", scene, cwd=tmp_path, timeout=60)
    assert (code, err) == (2, [f"usdhands: error: {scene}: buffers[0]: buffer file 'humanoid.bin' is not a "
                               "regular file"])
    assert snapshot(tmp_path) == before


def test_buffer_file_longer_than_byte_length_read_only_up_to_it(scene, tmp_path, capsys):
    """A longer file is valid (the rest is not the buffer's); a 4 GiB sparse tail is never read:
    under a 1 GiB address-space limit, reading it whole would fail."""
    reference = read_clip(scene)
    data = (scene.parent / "humanoid.bin").read_bytes()
    with open(scene.parent / "humanoid.bin", "r+b") as f:
        f.truncate(4 << 30)
    assert read_external(scene, "humanoid.bin", "buffer", "buffers[0]", len(data)) == data
    again = read_clip(scene)
    assert np.array_equal(again.rotations, reference.rotations)
    assert np.array_equal(again.translations, reference.translations)
    code, err = subprocess_cli("inspect", scene, cwd=tmp_path, timeout=120)
    assert (code, err) == (0, [])


def test_buffer_file_shorter_than_byte_length_refused(scene, capsys):
    data = (scene.parent / "humanoid.bin").read_bytes()
    (scene.parent / "humanoid.bin").write_bytes(data[:-10])
    code, err = run(capsys, "inspect", scene)
    assert (code, err) == (2, [f"usdhands: error: {scene}: buffers[0]: buffer holds {len(data) - 10} bytes, "
                               f"byteLength says {len(data)}"])


def test_buffer_with_negative_byte_length_refused(scene, capsys):
    g = pygltflib.GLTF2.gltf_from_json(scene.read_text())
    g.buffers[0].byteLength = -1            # read(-1) would read the whole file
    scene.write_text(g.gltf_to_json())
    code, err = run(capsys, "inspect", scene)
    assert (code, err) == (2, [f"usdhands: error: {scene}: buffers[0]: byteLength -1 is not a number of bytes"])


def test_symlinked_gltf_folder_is_its_folder(scene, tmp_path, capsys):
    """The glTF's own folder reached through a symlink: its files are inside it."""
    os.symlink(scene.parent, tmp_path / "via")
    code, err = run(capsys, "inspect", tmp_path / "via" / "humanoid.gltf")
    assert (code, err) == (0, [])


# --------------------------------------------------------------------------- image URIs (carried on write)


@pytest.mark.parametrize("variant", ESCAPES)
def test_image_uri_out_of_folder_refused_on_write(scene, tmp_path, capsys, variant):
    uri = _escape_variants(tmp_path, scene)[variant].replace("secret.bin", "tex.png")
    set_uri(scene, uri, image=True)
    before = snapshot(tmp_path)
    out = scene.parent / "out.gltf"
    code, err = run(capsys, "reduce", scene, "-o", out)
    assert (code, err) == (2, [f"usdhands: error: {scene}: images[0]: image URI {uri!r} points outside "
                               "the glTF's folder"])
    assert snapshot(tmp_path) == before


def test_image_uri_with_a_scheme_refused_on_write(scene, tmp_path, capsys):
    set_uri(scene, "file:///etc/passwd", image=True)
    code, err = run(capsys, "reduce", scene, "-o", scene.parent / "out.gltf")
    assert (code, err) == (2, [f"usdhands: error: {scene}: images[0]: image URI 'file:///etc/passwd' is not a "
                               "relative file path"])
    assert not (scene.parent / "out.gltf").exists()


def test_external_files_carried_into_another_folder(scene, tmp_path, capsys):
    """Output in a parent folder: relative URIs into the source's folder. Output elsewhere:
    the buffer and the image embedded (a reference out of the output's folder would be
    refused on reading it back)."""
    set_uri(scene, "tex.png", image=True)
    up = tmp_path / "a" / "up.gltf"
    code, _ = run(capsys, "reduce", scene, "-o", up)
    assert code == 0
    g = pygltflib.GLTF2.gltf_from_json(up.read_text())
    assert g.buffers[0].uri == "b/humanoid.bin" and g.images[0].uri == "b/tex.png"
    (tmp_path / "elsewhere").mkdir()
    away = tmp_path / "elsewhere" / "away.gltf"
    code, _ = run(capsys, "reduce", scene, "-o", away)
    assert code == 0
    g = pygltflib.GLTF2.gltf_from_json(away.read_text())
    assert g.images[0].uri == "data:image/png;base64," + base64.b64encode(b"\x89PNG inside").decode()
    assert g.buffers[0].uri.startswith("data:application/octet-stream;base64,")
    assert np.array_equal(read_clip(up).rotations, read_clip(away).rotations)
    for out in (up, away):
        code, err = run(capsys, "inspect", out)
        assert (code, err) == (0, [])


def test_image_fifo_refused_when_embedded(scene, tmp_path):
    (scene.parent / "tex.png").unlink()
    os.mkfifo(scene.parent / "tex.png")
    set_uri(scene, "tex.png", image=True)
    (tmp_path / "elsewhere").mkdir()
    out = tmp_path / "elsewhere" / "away.gltf"
    code, err = subprocess_cli("reduce", scene, "-o", out, cwd=tmp_path, timeout=120)
    assert (code, err) == (2, [f"usdhands: error: {scene}: images[0]: image file 'tex.png' is not a "
                               "regular file"])
    assert list((tmp_path / "elsewhere").iterdir()) == []


# --------------------------------------------------------------------------- inputs that are not regular files


@pytest.mark.parametrize("kind", ["fifo", "dev zero symlink"])
def test_main_input_not_a_regular_file(tmp_path, kind):
    path = tmp_path / "in.glb"
    if kind == "fifo":
        os.mkfifo(path)
    else:
        os.symlink("/dev/zero", path)
    for argv in (["inspect", path], ["convert", path, tmp_path / "out.glb"], ["handmap", path]):
        code, err = subprocess_cli(*argv, cwd=tmp_path, timeout=60)
        assert (code, err) == (2, [f"usdhands: error: {path}: not a regular file"]), argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.glb"]


def test_side_input_fifo_refused(ok_glb, tmp_path):
    os.mkfifo(tmp_path / "map.json")
    code, err = subprocess_cli("inspect", ok_glb, "--handmap", tmp_path / "map.json", cwd=tmp_path, timeout=60)
    assert (code, err) == (2, [f"usdhands: error: {tmp_path / 'map.json'}: not a regular file"])


@pytest.mark.parametrize("kind", ["fifo", "dev zero symlink"])
def test_read_asset_refuses_what_is_not_a_regular_file(tmp_path, kind):
    """The library's own check (the CLI refuses earlier, in check_paths)."""
    path = tmp_path / "in.bvh"
    os.mkfifo(path) if kind == "fifo" else os.symlink("/dev/zero", path)
    code, err = subprocess_python("-c", "from usdhands.formats.io import read_asset\n"
                                  "try:\n    read_asset('in.bvh')\n"
                                  "except Exception as e:\n    print(type(e).__name__, e, file=__import__('sys').stderr)",
                                  cwd=tmp_path, timeout=60)
    assert (code, err) == (0, ["AssetReadError in.bvh: not a regular file"])


# --------------------------------------------------------------------------- outputs over inputs


# (argv, the side input the output lands on, the label in the message); "{side}" is replaced by
# the output's spelling, "{in}" by the side input's path, "{clip}" by the main input
CASES = {
    "handmap --handmap": (["handmap", "{clip}", "--handmap", "{in}", "-o", "{side}"], "map.json", "--handmap"),
    "handmap input": (["handmap", "{clip}", "-o", "{side}"], "ok.glb", "input"),
    "convert input": (["convert", "{clip}", "{side}"], "ok.glb", "input"),
    "db build input": (["db", "build", "{clip}", "-o", "{side}"], "ok.glb", "input"),
    "db build --labels-file": (["db", "build", "{clip}", "--labels-file", "{in}", "-o", "{side}"], "labels.csv",
                               "--labels-file"),
    "db build --config": (["db", "build", "{clip}", "--config", "{in}", "-o", "{side}"], "config.json", "--config"),
    "db build --handmap": (["db", "build", "{clip}", "--handmap", "{in}", "-o", "{side}"], "map.json", "--handmap"),
    "synthesize --config": (["synthesize", "{clip}", "--config", "{in}", "-o", "{side}"], "config.glb", "--config"),
    "synthesize --handmap": (["synthesize", "{clip}", "--handmap", "{in}", "-o", "{side}"], "map.glb", "--handmap"),
    "splice HANDS": (["splice", "{clip}", "{in}", "-o", "{side}"], "hands.glb", "input"),
    "splice --body-markers": (["splice", "{clip}", "{clip}", "--body-markers", "{in}", "-o", "{side}"], "m.csv",
                              "--body-markers"),
    "splice --hands-markers": (["splice", "{clip}", "{clip}", "--hands-markers", "{in}", "-o", "{side}"], "m.csv",
                               "--hands-markers"),
    "splice --body-handmap": (["splice", "{clip}", "{clip}", "--body-handmap", "{in}", "-o", "{side}"], "m.glb",
                              "--body-handmap"),
    "splice --hands-handmap": (["splice", "{clip}", "{clip}", "--hands-handmap", "{in}", "-o", "{side}"], "m.glb",
                               "--hands-handmap"),
    "reduce --handmap": (["reduce", "{clip}", "--handmap", "{in}", "-o", "{side}"], "map.glb", "--handmap"),
    "reduce --model over --handmap": (["reduce", "{clip}", "--handmap", "{in}", "--model", "{side}"], "map.json",
                                      "--handmap"),
    "reduce --model over input": (["reduce", "{clip}", "--model", "{side}"], "ok.glb", "input"),
    "reduce --model over -o": (["reduce", "{clip}", "-o", "{in}", "--model", "{side}"], "new.glb", "-o"),
    "expand --model": (["expand", "{clip}", "--model", "{in}", "-o", "{side}"], "model.json", "--model"),
    "handmap --write-schema over input": (["handmap", "{clip}", "--write-schema", "{side}"], "ok.glb", "input"),
    "db build --props": (["db", "build", "{clip}", "--props", "{in}", "-o", "{side}"], "prop.obj", "--props"),
    "db build --interaction-config": (["db", "build", "{clip}", "--interaction-config", "{in}", "-o", "{side}"],
                                      "ic.json", "--interaction-config"),
    "synthesize --props": (["synthesize", "{clip}", "--props", "{in}", "-o", "{side}"], "prop.glb", "--props"),
    "synthesize --interaction-config": (["synthesize", "{clip}", "--interaction-config", "{in}", "-o", "{side}"],
                                        "ic.glb", "--interaction-config"),
    "correct --props": (["correct", "{clip}", "--props", "{in}", "-o", "{side}"], "prop.glb", "--props"),
    "correct --handmap": (["correct", "{clip}", "--props", "{clip}", "--handmap", "{in}", "-o", "{side}"],
                          "map.glb", "--handmap"),
    "correct --interaction-config": (["correct", "{clip}", "--props", "{clip}", "--interaction-config", "{in}",
                                      "-o", "{side}"], "ic.glb", "--interaction-config"),
}
SPELLINGS = ["same", "symlink", "hard link", "./", "../dir/"]


@pytest.mark.parametrize("spelling", SPELLINGS)
@pytest.mark.parametrize("case", sorted(CASES))
def test_output_never_lands_on_an_input(ok_glb, tmp_path, capsys, monkeypatch, case, spelling):
    argv, name, label = CASES[case]
    side = tmp_path / name
    if not side.exists():
        side.write_text(f"side input of {case}\n")
    monkeypatch.chdir(tmp_path)
    out = {"same": side, "symlink": tmp_path / f"link{side.suffix}", "hard link": tmp_path / f"hard{side.suffix}",
           "./": f"./{name}", "../dir/": f"../{tmp_path.name}/{name}"}[spelling]
    if spelling == "symlink":
        os.symlink(side, out)
    elif spelling == "hard link":
        os.link(side, out)
    checksum = sha(side)
    before = snapshot(tmp_path)
    code, err = run(capsys, *[a.format(side=out, clip=ok_glb, **{"in": side}) for a in argv])
    folder = "folder" if argv[:2] == ["db", "build"] else "file"
    what = "the input" if label == "input" else f"the {label} file"
    assert (code, err) == (2, [f"usdhands: error: {Path(out)}: output path equals {what}; choose another {folder}"])
    assert sha(side) == checksum and snapshot(tmp_path) == before


#: batch side file -> the job options of a job that reads it
BATCH_SIDE = {"--handmap": ["--job", "reduce"], "--config": ["--job", "synthesize"], "--model": ["--job", "expand"],
              "--interaction-config": ["--job", "correct", "--props", "{clip}"]}


@pytest.mark.parametrize("spelling", ["same", "symlink", "hard link"])
@pytest.mark.parametrize("written", ["report.json", "batch_options.json"])
@pytest.mark.parametrize("option", BATCH_SIDE)
def test_batch_never_writes_its_own_files_over_a_side_file(ok_glb, tmp_path, capsys, option, written, spelling):
    """``batch --out DIR`` writes DIR/report.json and DIR/batch_options.json: a side file there (or a
    link to one) is refused before any clip runs (it was overwritten, exit 0)."""
    out = tmp_path / "out"
    out.mkdir()
    side = tmp_path / "side.json" if spelling != "same" else out / written
    side.write_text("{}\n")
    if spelling == "symlink":
        os.symlink(side, out / written)
    elif spelling == "hard link":
        os.link(side, out / written)
    checksum = sha(side)
    before = snapshot(tmp_path)
    code, err = run(capsys, "batch", ok_glb, *[a.format(clip=ok_glb) for a in BATCH_SIDE[option]], "--out", out,
                    "--workers", "1", option, out / written)
    assert (code, err) == (2, [f"usdhands: error: {out / written}: batch writes {written} over the {option} file; "
                               "choose another --out folder"])
    assert sha(side) == checksum and snapshot(tmp_path) == before


def test_batch_clip_output_hard_linked_to_an_input_fails_that_clip(ok_glb, tmp_path, capsys):
    """A clip's output that is a hard link of an input clip is refused by batch itself before the job
    runs (the resolved-path comparison alone missed it; a pipeline's own job function may not check)."""
    (tmp_path / "takes").mkdir()
    a = tmp_path / "takes" / "a.glb"
    ok_glb.rename(a)
    os.link(a, tmp_path / "takes" / "a.usda")  # the convert output of a.glb there: a hard link of a.glb
    checksum = sha(a)
    code, _ = run(capsys, "batch", a, "--job", "convert", "--to", "usda", "--out", tmp_path / "takes",
                  "--workers", "1")
    report = __import__("json").loads((tmp_path / "takes" / "report.json").read_text())
    assert code == 1 and [c["error"] for c in report["clips"]] == ["the output would overwrite an input"]
    assert sha(a) == checksum and sha(tmp_path / "takes" / "a.usda") == checksum


def test_db_build_output_folder_holding_an_input_refused(ok_glb, tmp_path, capsys):
    db = tmp_path / "db"
    code, _ = run(capsys, "db", "build", "--samples", "-o", db)
    assert code == 0
    clip = db / "ok.glb"
    ok_glb.rename(clip)
    (db / "cfg.json").write_text("{}\n")
    before = snapshot(tmp_path)
    code, err = run(capsys, "db", "build", clip, "-o", db)
    assert (code, err) == (2, [f"usdhands: error: {db}: output folder holds an input {str(clip)!r}, and is "
                               "replaced whole; choose another folder"])
    cfg = tmp_path / "db" / ".." / "db" / "cfg.json"
    code, err = run(capsys, "db", "build", "--samples", "--config", cfg, "-o", db)
    assert (code, err) == (2, [f"usdhands: error: {db}: output folder holds --config {str(cfg)!r}, and is "
                               "replaced whole; choose another folder"])
    assert snapshot(tmp_path) == before

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

import pytest

from hostile import check_promise, deep_json, glb_bytes, run_bounded  # noqa: E402  (tests/ is on sys.path)


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


def _random_json(rng, depth: int = 0):
    """A random JSON value: nested containers, strings full of quotes, backslashes and brackets."""
    kind = rng.randrange(6 if depth < 6 else 3)
    if kind == 0:
        return rng.choice([0, -1.5, 1e300, True, None])
    if kind in (1, 2):
        return "".join(rng.choice('ab"\\[]{},:') for _ in range(rng.randrange(8)))
    if kind in (3, 4):
        return [_random_json(rng, depth + 1) for _ in range(rng.randrange(5))]
    return {_random_json(rng, 9): _random_json(rng, depth + 1) for _ in range(rng.randrange(5))}


@pytest.mark.parametrize("chunk", [1, 2, 3, 7, 64, 1 << 22])
def test_json_structure_scan_equals_its_naive_twin(chunk, monkeypatch):
    """The chunked, vectorised scan that bounds nesting and size before parsing (a 208 MB glTF of
    10^7 keys ran out of memory in the old whole-text scan) against a byte-by-byte one."""
    import random

    import usdhands.input_files as input_files

    monkeypatch.setattr(input_files, "_CHUNK", chunk)
    rng = random.Random(chunk)
    for _ in range(300):
        text = json.dumps(_random_json(rng))
        assert input_files._structure(text) == input_files._structure_naive(text), text
    assert input_files._structure('{"a": [1, "x\\\\", {"b": "[,"}], "c": 2}') == (3, 3)


def test_gltf_json_of_ten_million_keys(tmp_path):
    """A 200 MB .gltf whose extras hold 10^7 keys: refused before parsing, in bounded memory and time
    (it took 66 s, then a MemoryError traceback under 3 GB)."""
    bad = tmp_path / "keys.gltf"
    with open(bad, "w") as f:
        f.write('{"asset": {"version": "2.0"}, "extras": {')
        f.write(",".join(f'"k{i}": {i}' for i in range(10 ** 7)))
        f.write("}}")
    check_promise(["inspect", bad], folder=tmp_path, inputs=[bad], names=bad,
                  message="holds more than 5,000,000 values", memory=1536 * 1024 ** 2, cpu=60)


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


@pytest.fixture()
def immutable_folder(tmp_path):
    """``tmp/ro``, a folder nobody may write into, root included (``chattr +i``: the tests run as root,
    where permission bits stop nothing); skipped where the file system or the user cannot set it."""
    import subprocess

    folder = tmp_path / "ro"
    folder.mkdir()
    if shutil.which("chattr") is None or subprocess.run(["chattr", "+i", str(folder)],
                                                        capture_output=True).returncode != 0:
        pytest.skip("chattr +i not available here")
    try:
        yield folder
    finally:
        subprocess.run(["chattr", "-i", str(folder)], check=True)


WRITES = {  # command -> (argv; the output named in the error)
    "convert usdc": (["convert", "{src}", "{ro}/x.usdc"], "{ro}/x.usdc"),
    "db build": (["db", "build", "{src}", "-o", "{ro}/db"], "{ro}/db"),
    "synthesize": (["synthesize", "{src}", "-o", "{ro}/x.glb"], "{ro}/x.glb"),
    "reduce --model": (["reduce", "{src}", "--model", "{ro}/m.json"], "{ro}/m.json"),
    "handmap": (["handmap", "{src}", "-o", "{ro}/h.json"], "{ro}/h.json"),
    "splice": (["splice", "{src}", "{src}", "-o", "{ro}/s.glb"], "{ro}/s.glb"),
    "batch": (["batch", "{src}", "--job", "convert", "--to", "usda", "--out", "{ro}", "--workers", "1"],
              "{ro}/batch_options.json"),
}


@pytest.mark.parametrize("command", sorted(WRITES))
def test_writing_into_a_folder_that_refuses_writes(command, sample_assets, tmp_path, immutable_folder):
    """PermissionError in 'db build -o'; after that fix, 'reduce --model' and 'batch' still named their
    temporary files (m.json.tmp, .batch_options.json.XXXX) instead of the output."""
    src = tmp_path / "ok.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", src)
    argv, named = WRITES[command]
    fill = {"src": src, "ro": immutable_folder}
    check_promise([a.format(**fill) for a in argv], folder=tmp_path, inputs=[src], names=named.format(**fill),
                  message=f"cannot write into folder {str(immutable_folder)!r}")


def test_reduce_model_leaves_a_file_named_like_its_temporary_alone(sample_assets, tmp_path):
    """The model was written to the fixed name MODEL.tmp, then renamed: a user's file of that name
    was overwritten and removed."""
    src = tmp_path / "ok.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", src)
    keep = tmp_path / "m.json.tmp"
    keep.write_text("the user's own file\n")
    run = run_bounded(["reduce", src, "--model", tmp_path / "m.json"])
    assert run.code == 0, run.stderr
    assert keep.read_text() == "the user's own file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.json", "m.json.tmp", "ok.glb"]


def test_db_build_over_a_database_leaves_a_folder_named_like_its_old_copy_alone(sample_assets, tmp_path):
    """Rebuilding a database moved the old one to the fixed name '.DB.old', removing first a folder of
    that name (a user's, with whatever it held)."""
    src = tmp_path / "ok.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", src)
    for k in range(2):  # built, then rebuilt over itself
        if k == 1:
            (tmp_path / ".db.old").mkdir()
            (tmp_path / ".db.old" / "notes.txt").write_text("the user's own\n")
        run = run_bounded(["db", "build", src, "-o", tmp_path / "db"])
        assert run.code == 0, run.stderr
    assert (tmp_path / ".db.old" / "notes.txt").read_text() == "the user's own\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == [".db.old", "db", "ok.glb"]


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
    check_promise(argv, folder=tmp_path, inputs=[src], names=odd, message="not a regular file", wall=60)


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


def humanoid_usda_text(sample_assets) -> str:
    return (sample_assets / "humanoid.usda").read_text()


def test_usd_time_sample_at_1e12(sample_assets, tmp_path):
    """np.arange over a trillion frames: 'Unable to allocate 7.28 TiB'."""
    bad = tmp_path / "far.usda"
    bad.write_text(humanoid_usda_text(sample_assets).replace(
        "quatf[] rotations.timeSamples = {", "quatf[] rotations.timeSamples = {\n 1000000000000: [(1, 0, 0, 0)],", 1))
    check_promise(["convert", bad, tmp_path / "out.glb"], folder=tmp_path, inputs=[bad], names=bad,
                  message="more than 1,000,000 are refused")


def test_usd_meters_per_unit_zero(sample_assets, tmp_path):
    bad = tmp_path / "mpu0.usda"
    bad.write_text(humanoid_usda_text(sample_assets).replace("metersPerUnit = 0.01", "metersPerUnit = 0"))
    check_promise(["convert", bad, tmp_path / "out.glb"], folder=tmp_path, inputs=[bad], names=bad,
                  message="metersPerUnit 0 is not a positive finite number")


def test_usd_all_zero_bind_transforms(sample_assets, tmp_path):
    """LinAlgError: Singular matrix when convert inverted the binds for glTF."""
    import re

    text = humanoid_usda_text(sample_assets)
    start = text.index("uniform matrix4d[] bindTransforms = [")
    end = text.index("\n", start)
    count = len(re.findall(r"\( \(", text[start:end]))
    zero = "( (0, 0, 0, 0), (0, 0, 0, 0), (0, 0, 0, 0), (0, 0, 0, 0) )"
    bad = tmp_path / "zerobind.usda"
    bad.write_text(text[:start] + "uniform matrix4d[] bindTransforms = [" + ", ".join([zero] * count) + "]"
                   + text[end:])
    check_promise(["convert", bad, tmp_path / "out.glb"], folder=tmp_path, inputs=[bad], names=bad,
                  message="bindTransforms of joint 'Hips' is singular")


@pytest.mark.parametrize("attr", ["bindTransforms", "restTransforms"])
def test_usd_joint_transform_that_is_not_affine(attr, sample_assets, tmp_path):
    """usda fuzz (76 findings in 10 minutes): a bindTransform whose fourth column reads 0 0 0 0 instead
    of 0 0 0 1 passed the 3x3 check; solving a child's rest from it raised LinAlgError (file without
    restTransforms, as usdhands writes from a glTF). A restTransform like it is refused as well."""
    import re

    text = humanoid_usda_text(sample_assets)
    if attr == "bindTransforms":
        text = re.sub(r"\n\s*uniform matrix4d\[\] restTransforms = \[[^\n]*", "", text, count=1)
    start = text.index(f"uniform matrix4d[] {attr} = [")
    end = text.index("\n", start)
    line = text[start:end]
    second = [m.start() for m in re.finditer(r", 1\) \)", line)][1]
    bad = tmp_path / "projective.usda"
    bad.write_text(text[:start] + line[:second] + ", 0) )" + line[second + len(", 1) )"):] + text[end:])
    check_promise(["convert", bad, tmp_path / "out.glb"], folder=tmp_path, inputs=[bad], names=bad,
                  message=f"{attr} of joint 'Hips/Spine' is not an affine transform (its fourth column is not 0 0 0 1)")


@pytest.mark.parametrize("attr", ["bindTransforms", "restTransforms"])
def test_usd_joint_transforms_holding_strings(attr, sample_assets, tmp_path):
    """usdc fuzz: a corrupt crate's restTransforms held strings, one per joint (ValueError converting
    them to floats); a .usda typing the attribute string[] reaches the same code."""
    import re

    text = humanoid_usda_text(sample_assets)
    start = text.index(f"uniform matrix4d[] {attr} = [")
    end = text.index("\n", start)
    count = len(re.findall(r"\( \(", text[start:end]))
    strings = ", ".join(['"usdhands"'] * count)
    bad = tmp_path / "strings.usda"
    bad.write_text(text[:start] + f"uniform string[] {attr} = [{strings}]" + text[end:])
    check_promise(["convert", bad, tmp_path / "out.glb"], folder=tmp_path, inputs=[bad], names=bad,
                  message=f"{attr} holds StringArray values, not matrix4d[]")


@pytest.mark.parametrize("attr", ["point3f[] points", "quatf[] rotations.timeSamples"])
def test_usd_numbers_typed_as_strings(attr, sample_assets, tmp_path):
    """Found auditing the usdc finding above: a mesh's points or an animation's rotations typed
    string[] (as a corrupt crate can hold them) raised ValueError converting them."""
    import re

    text = humanoid_usda_text(sample_assets)
    start = text.index(attr)
    end = text.index("}", start) if "timeSamples" in attr else text.index("\n", start)
    body = re.sub(r"\[[^\]]*\]", lambda m: "[" + ", ".join(['"x"'] * m.group(0).count("(")) + "]", text[start:end])
    bad = tmp_path / "strings.usda"
    bad.write_text(text[:start] + body.replace(attr.split()[0], "string[]", 1) + text[end:])
    check_promise(["convert", bad, tmp_path / "out.glb"], folder=tmp_path, inputs=[bad], names=bad,
                  message="cannot read as USD: an attribute holds values of another type than its schema's")


def test_usd_joints_that_are_no_array(sample_assets, tmp_path):
    """usdc fuzz (rerun after the fixes, 706 of 3,485 findings): a corrupt crate's joints held a
    Variability ('not iterable' TypeError); a .usda typing joints float reaches the same code."""
    import re

    text = humanoid_usda_text(sample_assets)
    bad = tmp_path / "joints.usda"
    bad.write_text(re.sub(r"uniform token\[\] joints = \[[^\n]*", "uniform float joints = 1.5", text, count=1))
    check_promise(["convert", bad, tmp_path / "out.glb"], folder=tmp_path, inputs=[bad], names=bad,
                  message="joints holds a float, not token[]")


class _Spec:
    """A stand-in for an Sdf spec whose children field holds what a corrupt crate held."""

    path = "/Root"

    def __init__(self, held):
        self.held = held

    def HasInfo(self, key):
        return True

    def GetInfo(self, key):
        if isinstance(self.held, type) and issubclass(self.held, Exception):
            raise self.held("utf-8", b"\xe6", 0, 1, "invalid continuation byte") \
                if self.held is UnicodeDecodeError else self.held("No to_python converter")
        return self.held


@pytest.mark.parametrize("held,message", [
    (1.5, "holds no list of names"),                       # 'float' object is not iterable (1,264 findings)
    (TypeError, "holds no list of names"),                 # No to_python converter for layer offsets (799)
    (UnicodeDecodeError, "holds names that are not UTF-8"),  # tokens that are not UTF-8 (616)
    ([1, 2], "holds no list of names"),
])
def test_crate_children_fields_holding_other_values(held, message, tmp_path):
    """usdc fuzz (rerun after the fixes): the check that every listed child has a spec read the
    children fields (primChildren, properties...) as they were: a float, layer offsets Python cannot
    hold, tokens that are not UTF-8 raised tracebacks."""
    from usdhands.errors import AssetReadError
    from usdhands.formats.usd_common import _children

    with pytest.raises(AssetReadError) as e:
        _children(_Spec(held), "primChildren", tmp_path / "x.usdc")
    assert str(e.value) == f"{tmp_path / 'x.usdc'}: cannot read as USD: primChildren of </Root> {message}"
    assert _children(_Spec(["Hips", "Body"]), "primChildren", tmp_path / "x.usdc") == ["Hips", "Body"]


@pytest.mark.parametrize("edit,message", [
    (lambda t: t.replace("elementSize = 5", "elementSize = 3", 1), "elementSize 3 / 5"),
    (lambda t: t.replace("elementSize = 5", "elementSize = 2147483647", 2), "elementSize 2147483647 / 2147483647"),
    (lambda t: t.replace("int[] primvars:skel:jointIndices = [", "int[] primvars:skel:jointIndices = [7, ", 1),
     "have 2081 / 2080 values"),
    (lambda t: t.replace("int[] primvars:skel:jointIndices = [0,", "int[] primvars:skel:jointIndices = [2000000000,",
                         1), "skel:jointIndices outside 0..64"),
])
@pytest.mark.parametrize("ext", ["usda", "usdc"])
def test_usd_skinning_checked_before_usdskel_sees_it(edit, message, ext, sample_assets, tmp_path):
    """A mutated .usdc mesh crashed the interpreter (exit 139) in UsdSkel's influence computation."""
    text = humanoid_usda_text(sample_assets)
    mutated = edit(text)
    assert mutated != text
    bad = tmp_path / f"skin.{ext}"
    if ext == "usda":
        bad.write_text(mutated)
    else:
        from pxr import Sdf

        layer = Sdf.Layer.CreateAnonymous(".usda")
        assert layer.ImportFromString(mutated)
        assert layer.Export(str(bad))
    check_promise(["convert", bad, tmp_path / "out.glb"], folder=tmp_path, inputs=[bad], names=bad,
                  message=message)


def test_corrupt_usdc_values_fail_in_one_line(sample_assets, tmp_path):
    """A .usdc whose compressed value section is damaged opens, then raised pxr.Tf.ErrorException (LZ4)."""
    from pxr import Sdf

    layer = Sdf.Layer.CreateAnonymous(".usda")
    assert layer.ImportFromString(humanoid_usda_text(sample_assets))
    good = tmp_path / "good.usdc"
    assert layer.Export(str(good))
    data = bytearray(good.read_bytes())
    # the crate's table of contents sits at the end; damage the compressed sections before it
    bad = tmp_path / "bad.usdc"
    toc = int.from_bytes(data[16:24], "little")
    for k in range(toc - 4000, toc - 100, 7):
        data[k] ^= 0x5A
    bad.write_bytes(bytes(data))
    good.unlink()
    run = check_promise(["inspect", bad], folder=tmp_path, inputs=[bad], names=bad, message="")
    assert "Traceback" not in run.stderr


def _crate_with_unknown_sample_type(sample_assets, folder):
    """A .usdc of 4 frames whose rotation time samples (quatf[] value reps: type byte 17, array flag
    0x80) claim type 239: the crate check does not walk time-sample values, USD's reader fails on
    them when they are read, and its Python binding printed the value it could not convert."""
    from usdhands.formats.io import read_asset, write_asset
    from usdhands.model.asset import Asset

    asset = read_asset(sample_assets / "gestures" / "ok_00.glb")
    clip = asset.clips[0]
    short = clip.__class__(clip.skeleton, clip.fps, clip.rotations[:4], clip.translations[:4], clip.scales[:4],
                           name=clip.name)
    good = folder / "good.usdc"
    write_asset(Asset("fuzz seed", asset.skeletons, (short,), asset.meshes), good)
    data = bytearray(good.read_bytes())
    good.unlink()
    reps = [k for k in range(len(data) - 1) if data[k] == 17 and data[k + 1] == 0x80]
    assert len(reps) == 4, reps  # one a frame: the rotations' samples
    for k in reps:
        data[k] = 239
    bad = folder / "bad.usdc"
    bad.write_bytes(bytes(data))
    return bad


def test_usd_time_samples_of_an_unknown_type_fail_in_one_line(sample_assets, tmp_path):
    """Found by the .usdz fuzz target (session 7): 'TypeError: No to_python (by-value) converter found
    for C++ type: ...VtBackgroundType' on stderr before usdhands' own line."""
    bad = _crate_with_unknown_sample_type(sample_assets, tmp_path)
    check_promise(["inspect", bad], folder=tmp_path, inputs=[bad], names=bad,
                  message="cannot read as USD: Attempted to unpack unsupported type enum value 239")


def test_usd_binding_prints_dropped_only_inside_the_read(sample_assets, tmp_path, monkeypatch):
    """The library's read drops the binding's print without losing an application's own excepthook:
    it is not called for the print, and it is the hook again after the read."""
    import sys

    from usdhands.errors import AssetReadError
    from usdhands.formats.io import read_asset

    bad = _crate_with_unknown_sample_type(sample_assets, tmp_path)
    seen = []

    def own_hook(kind, value, tb):
        seen.append(kind.__name__)

    monkeypatch.setattr(sys, "excepthook", own_hook)
    with pytest.raises(AssetReadError, match="unsupported type enum value 239"):
        read_asset(bad)
    assert seen == []
    assert sys.excepthook is own_hook


def gltf_with_data_uri(sample_assets, edit) -> str:
    """The sample take as a .gltf with an embedded buffer, ``edit(doc)`` applied to its JSON."""
    import base64

    from hostile import gltf_json

    src = sample_assets / "gestures" / "ok_00.glb"
    raw = src.read_bytes()
    doc = gltf_json(src)
    n = int.from_bytes(raw[12:16], "little")
    binary = raw[20 + n + 8:]
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
    edit(doc)
    return json.dumps(doc)


def rotation_output(doc) -> dict:
    anim = doc["animations"][0]
    channel = next(c for c in anim["channels"] if c["target"]["path"] == "rotation")
    return doc["accessors"][anim["samplers"][channel["sampler"]]["output"]]


def _set_byte_offset(doc):
    doc["bufferViews"][0]["byteOffset"] = -1e308


def _rotation_unsigned_int(doc):
    rotation_output(doc)["componentType"] = 5125


def _stride_below_element(doc):
    acc = rotation_output(doc)
    doc["bufferViews"][acc["bufferView"]]["byteStride"] = 4


@pytest.mark.parametrize("edit,message", [
    (_set_byte_offset, "byteOffset -1e+308 is not an integer from 0 to 2^53"),
    (_rotation_unsigned_int, "have componentType 5125 not normalized; glTF allows FLOAT or normalized"),
    (_stride_below_element, "byteStride 4 is smaller than one VEC4 element (16 bytes)"),
])
def test_gltf_accessor_lies(edit, message, sample_assets, tmp_path):
    """OverflowError on byteOffset -1e308; UNSIGNED_INT rotations and a 4-byte stride for VEC4 floats
    were read silently (integers as rotations, overlapping elements)."""
    bad = tmp_path / "bad.gltf"
    bad.write_text(gltf_with_data_uri(sample_assets, edit))
    check_promise(["convert", bad, tmp_path / "out.usda"], folder=tmp_path, inputs=[bad], names=bad,
                  message=message)


def node_chain(n: int, skin: bool) -> str:
    nodes = [{"name": f"n{i}", "children": [i + 1], "translation": [0, 0.01, 0]} for i in range(n - 1)]
    nodes.append({"name": f"n{n - 1}"})
    doc = {"asset": {"version": "2.0"}, "nodes": nodes, "scenes": [{"nodes": [0]}], "scene": 0}
    if skin:
        doc["skins"] = [{"joints": list(range(n))}]
    return json.dumps(doc)


@pytest.mark.parametrize("n,skin", [(100_000, False), (20_000, True)])
def test_gltf_node_chains_past_the_limit(n, skin, tmp_path):
    """inspect had not finished after 600 s (100,000 nodes); a 20,000-joint skin took 76 s."""
    bad = tmp_path / "chain.gltf"
    bad.write_text(node_chain(n, skin))
    check_promise(["inspect", bad], folder=tmp_path, inputs=[bad], names=bad,
                  message=f"{n:,} nodes: more than 10,000 are refused", cpu=30)


def test_gltf_skin_chain_at_the_limit_reads(tmp_path):
    """10,000 joints in one chain: read within the CPU bound (hierarchy work is linear)."""
    src = tmp_path / "chain.gltf"
    src.write_text(node_chain(10_000, True))
    run = run_bounded(["inspect", "--json", src], cpu=60)
    assert run.code == 0, run.stderr[-2000:]
    assert json.loads(run.stdout)["skeletons"][0]["num_joints"] == 10_000


def test_expand_with_an_overflowing_model_names_the_model(ok_glb, tmp_path):
    """A scale of 1e308 overflowed (RuntimeWarning lines) and the error named the output."""
    model = tmp_path / "model.json"
    assert run_bounded(["reduce", ok_glb, "--model", model]).code == 0
    d = json.loads(model.read_text())
    d["relations"][0]["scale"] = 1e308
    big = tmp_path / "big.json"
    big.write_text(json.dumps(d))
    check_promise(["expand", ok_glb, "--model", big, "-o", tmp_path / "out.glb"], folder=tmp_path,
                  inputs=[ok_glb, big, model], names=big, message="scale 1e+308")


def test_bvh_root_at_1e308_is_refused_not_written(sample_assets, tmp_path):
    """The .glb written had infinite translations, which usdhands itself then refused."""
    lines = (sample_assets / "humanoid.bvh").read_text().splitlines()
    first = next(k for k, line in enumerate(lines) if line.startswith("Frame Time")) + 1
    values = lines[first].split()
    values[0] = "1e308"
    lines[first] = " ".join(values)
    bad = tmp_path / "far.bvh"
    bad.write_text("\n".join(lines) + "\n")
    check_promise(["convert", bad, tmp_path / "out.glb"], folder=tmp_path, inputs=[bad], names=bad,
                  message="translations beyond 1e+30")


def test_usd_quaternion_of_magnitude_1e38_converts_to_a_valid_glb(sample_assets, tmp_path, gltf_validator):
    """The .glb kept the 1e38 quaternion and failed the Khronos validator: rotations are normalized."""
    text = humanoid_usda_text(sample_assets)
    start = text.index("quatf[] rotations.timeSamples = {")
    first = text.index("(", text.index(": [", start))
    close = text.index(")", first)
    src = tmp_path / "big.usda"
    src.write_text(text[:first] + "(1e38, 0, 0, 0)" + text[close + 1:])
    out = tmp_path / "out.glb"
    run = run_bounded(["convert", src, out])
    assert run.code == 0, run.stderr
    report = gltf_validator(out)[0]
    assert report["numErrors"] == 0, report
    assert run_bounded(["inspect", out]).code == 0


def _signalled_mid_write(src, out, sig):
    """Run ``convert SRC OUT`` (``db build`` for an OUT ending in _db) and send ``sig`` once its
    temporary output (``.OUT.XXXX``) exists: (the finished process, its stderr)."""
    import subprocess
    import sys
    import time

    from hostile import ROOT

    argv = ["db", "build", src, "-o", out] if out.name.endswith("_db") else ["convert", src, out]
    import signal

    # SIGINT as a terminal gives it: a shell that starts jobs in the background (a CI runner's) has the
    # tests ignore SIGINT, and Python keeps an ignored SIGINT ignored in the child
    proc = subprocess.Popen([sys.executable, "-m", "usdhands", *map(str, argv)],
                            env=dict(os.environ, PYTHONPATH=str(ROOT)), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline:  # wait for the temporary output
        if any(name.startswith(f".{out.stem}.") for name in os.listdir(out.parent)):
            proc.send_signal(sig)
            break
        time.sleep(0.002)
    _, err = proc.communicate(timeout=120)
    return proc, err


def _whole_and_alone_then_removed(proc, err, codes, src, out) -> None:
    """A run whose output ``out`` was renamed into place before its signal was handled: it exited
    with one of ``codes``, the output reads whole, and nothing but ``src`` is beside it; then
    the output is removed for the next attempt."""
    from hostile import listing

    assert proc.returncode in codes, (proc.returncode, err)
    folder, target = out.parent, out.name
    others = [p for p in listing(folder) if p != target and not p.startswith(target + os.sep)]
    assert others == [src.name], "temporary output left behind"
    check = folder / "check.glb"
    assert run_bounded(["inspect", out] if out.is_file() else ["synthesize", src, "--db", out, "-o", check]).code == 0
    shutil.rmtree(out) if out.is_dir() else out.unlink()
    check.unlink(missing_ok=True)


@pytest.mark.parametrize("target", ["out.usda", "out.usdc", "out.glb", "out_db", "rebuilt_db"])
def test_sigterm_mid_write_leaves_nothing(target, sample_assets, tmp_path):
    """14 of 25 runs left .out.XXXX.usdc (and USD's own temporary) beside the target; every writer
    (USD text and crate, glTF binary, a database folder) is signalled while its temporary exists."""
    import signal

    from hostile import listing, sha

    src = tmp_path / "long.glb"
    shutil.copy(sample_assets / "conversation.glb", src)
    terminated = 0
    kept = []  # rebuilt_db: the database being replaced, which a signal must leave as it was
    if target == "rebuilt_db":
        assert run_bounded(["db", "build", src, "-o", tmp_path / target]).code == 0
        kept = listing(tmp_path)
        old_bytes = {p: sha(tmp_path / p) for p in kept}
    for attempt in range(5):
        out = tmp_path / target
        proc, err = _signalled_mid_write(src, out, signal.SIGTERM)
        if out.exists() and not kept:  # in place before the signal was handled (exit 0, or 143 when the
            # signal came between the rename and the exit)
            _whole_and_alone_then_removed(proc, err, (0, -signal.SIGTERM, 143), src, out)
            continue
        if kept and proc.returncode in (0, -signal.SIGTERM):  # the new database took the old one's place
            assert listing(tmp_path) == kept
            continue
        assert proc.returncode == 143, (proc.returncode, err)
        assert err.strip().splitlines() == ["usdhands: terminated"]
        terminated += 1
        assert listing(tmp_path) == (kept or ["long.glb"]), "temporary output left behind"
        if kept:
            assert {p: sha(tmp_path / p) for p in kept} == old_bytes, "the old database changed"
    assert terminated >= 1


@pytest.mark.parametrize("target", ["out.usdc", "out_db"])
def test_sigint_mid_write_leaves_nothing(target, sample_assets, tmp_path):
    """Ctrl-C (SIGINT) while the temporary output exists: exit 130, one line, nothing left (the issue
    found this held; kept so that it goes on holding)."""
    import signal

    from hostile import listing

    src = tmp_path / "long.glb"
    shutil.copy(sample_assets / "conversation.glb", src)
    interrupted = 0
    for attempt in range(4):
        out = tmp_path / target
        proc, err = _signalled_mid_write(src, out, signal.SIGINT)
        if out.exists():  # in place before the signal was handled (exit 0, or 130 when the interrupt came
            # between the rename and the exit)
            _whole_and_alone_then_removed(proc, err, (0, 130), src, out)
            continue
        assert (proc.returncode, err.strip().splitlines()) == (130, ["usdhands: interrupted"])
        interrupted += 1
        assert listing(tmp_path) == ["long.glb"], "temporary output left behind"
    assert interrupted >= 1


@pytest.mark.parametrize("signal_name, code, line", [("SIGTERM", 143, "usdhands: terminated"),
                                                     ("SIGINT", 130, "usdhands: interrupted")])
def test_a_signal_whose_exception_c_code_replaced_still_ends_the_run_as_the_signal(signal_name, code, line, ok_glb,
                                                                                   tmp_path, capsys, monkeypatch):
    """SIGTERM during db build over a database (full suite under load 12): exit 1 and a traceback,
    'TypeError: expected str, bytes or os.PathLike object, not BufferedWriter' from numpy's tofile,
    which replaces an exception raised while it writes (18 of 3,000 timer signals). Here the job is
    signalled, and the exception replaced, as numpy did."""
    import signal

    from cli_helpers import run
    from usdhands.jobs import conversion

    def write_like_numpy(*args, **kwargs):
        try:
            signal.raise_signal(getattr(signal, signal_name))
        except BaseException:
            raise TypeError("expected str, bytes or os.PathLike object, not BufferedWriter") from None

    monkeypatch.setattr(conversion, "convert", write_like_numpy)
    # SIGINT's default disposition, as a terminal gives it (a shell running jobs in the background ignores it)
    saved = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        before = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
        assert run(capsys, "convert", ok_glb, tmp_path / "out.usda") == (code, [line])
        assert (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)) == before
    finally:
        signal.signal(signal.SIGINT, saved)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.glb"]


def test_parallel_runs_writing_one_output(sample_assets, tmp_path):
    """Four conversions of two different takes into one output at once: every run succeeds, no
    temporary file is left, and the output is whole: byte for byte one of the two conversions."""
    import subprocess
    import sys

    from hostile import ROOT, listing, sha

    takes = [tmp_path / "a.glb", tmp_path / "b.glb"]
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", takes[0])
    shutil.copy(sample_assets / "gestures" / "ok_01.glb", takes[1])
    expected = set()
    for take in takes:  # each conversion alone
        alone = tmp_path / f"alone_{take.stem}.usdc"
        assert run_bounded(["convert", take, alone]).code == 0
        expected.add(sha(alone))
        alone.unlink()
    assert len(expected) == 2
    out = tmp_path / "out.usdc"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for _ in range(3):
        procs = [subprocess.Popen([sys.executable, "-m", "usdhands", "convert", str(takes[k % 2]), str(out)], env=env,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for k in range(4)]
        results = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
        assert [code for code, _ in results] == [0, 0, 0, 0], results
        assert listing(tmp_path) == ["a.glb", "b.glb", "out.usdc"], "temporary file left behind"
        assert sha(out) in expected
        out.unlink()


# -- found by fuzzing (tests/fuzz/run.py), rebuilt here from the samples ----------------------

def _node_translation_1e308(doc):
    doc["nodes"][2]["translation"] = [1e308, 0, 0]


def test_fuzz_gltf_node_translation_1e308(sample_assets, tmp_path):
    """'RuntimeWarning: overflow encountered in dot' (the quaternion norm), then a zero rotation used."""
    bad = tmp_path / "far.gltf"
    bad.write_text(gltf_with_data_uri(sample_assets, _node_translation_1e308))
    check_promise(["inspect", bad], folder=tmp_path, inputs=[bad], names=bad,
                  message="nodes[2]: node translation, rotation or scale is not finite (or absurdly large)")


def test_fuzz_usdc_token_not_utf8(tmp_path):
    """UnicodeDecodeError from pxr when a joint token of a .usdc holds the byte 0x80."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent / "fuzz"))
    from fuzz_target import seeds

    data = bytearray(seeds("usdc")[0])  # the sample take written as .usdc
    k = data.index(b"Pinky")
    data[k + 3] = 0x80
    bad = tmp_path / "token.usdc"
    bad.write_bytes(bytes(data))
    check_promise(["inspect", bad], folder=tmp_path, inputs=[bad], names=bad,
                  message="cannot read as USD: a name or token is not UTF-8")


def test_fuzz_usda_attribute_of_unknown_type(sample_assets, tmp_path):
    """TypeError: object of type 'UnregisteredValue' has no len() (48 atheris findings on .usda)."""
    bad = tmp_path / "unknown.usda"
    bad.write_text(humanoid_usda_text(sample_assets).replace("uniform matrix4d[] bindTransforms",
                                                             "uniform matrix4q[] bindTransforms"))
    check_promise(["inspect", bad], folder=tmp_path, inputs=[bad], names=bad,
                  message="bindTransforms holds UnregisteredValue values, not matrix4d[]")


def test_fuzz_usdc_array_attribute_holding_a_payload(sample_assets, tmp_path):
    """TypeError: object of type 'Payload' has no len() (13 atheris findings on .usdc: restTransforms held a Payload)."""
    from pxr import Sdf

    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.TransferContent(Sdf.Layer.FindOrOpen(str(sample_assets / "humanoid.usda")))
    layer.GetAttributeAtPath("/Root/Humanoid.restTransforms").SetInfo("default", Sdf.Payload("x.usd"))
    bad = tmp_path / "payload.usdc"
    layer.Export(str(bad))
    check_promise(["inspect", bad], folder=tmp_path, inputs=[bad], names=bad,
                  message="restTransforms holds Payload values, not matrix4d[]")

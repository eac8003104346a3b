"""Deterministic fuzz of the readers: corrupted files never escape as a traceback.

For each format a real small file (the first 6 frames of a Leap Motion BVH, converted to
.glb, .gltf, .usda, .usdc and packed as .usdz) is corrupted in about 20 ways: truncated at
several points, bytes flipped in the header / JSON chunk / binary chunk, a line deleted
from the BVH hierarchy, non-UTF-8 bytes, an empty file, a folder with the file's name.
``usdhands inspect`` and ``usdhands convert`` run in-process on every variant and must
either succeed or print exactly one ``usdhands: error: FILE: ...`` line, exit with status
2 and leave no output behind.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from usdhands.cli import main

FORMATS = ("bvh", "glb", "gltf", "usda", "usdc", "usdz")


@pytest.fixture(scope="module")
def originals(shared_assets, tmp_path_factory) -> dict[str, bytes]:
    """The bytes of one small valid file per format."""
    folder = tmp_path_factory.mktemp("fuzz_src")
    lines = (shared_assets / "leap_hands" / "fingers-ok.bvh").read_text().splitlines()
    frames = next(k for k, line in enumerate(lines) if line.startswith("Frames"))
    bvh = folder / "small.bvh"
    bvh.write_text("\n".join(lines[:frames] + ["Frames: 6"] + lines[frames + 1:frames + 8]) + "\n")
    for ext in ("glb", "gltf", "usda", "usdc"):
        assert main(["convert", str(bvh), str(folder / f"small.{ext}")]) == 0
    from pxr import UsdUtils

    assert UsdUtils.CreateNewUsdzPackage(str(folder / "small.usdc"), str(folder / "small.usdz"))
    return {ext: (folder / f"small.{ext}").read_bytes() for ext in FORMATS}


def flip(data: bytes, start: int, stop: int, step: int = 1) -> bytes:
    """``data`` with every ``step``-th byte in [start, stop) inverted."""
    out = bytearray(data)
    for k in range(max(0, start), min(len(out), stop), step):
        out[k] ^= 0xFF
    return bytes(out)


def truncations(data: bytes) -> list[tuple[str, bytes]]:
    n = len(data)
    return [(f"trunc{cut}", data[:cut]) for cut in sorted({1, 4, 11, 12, 20, n // 4, n // 2, n - 1})]


def common_variants(data: bytes) -> list[tuple[str, bytes]]:
    n = len(data)
    return truncations(data) + [
        ("empty", b""),
        ("zeros", b"\0" * 64),
        ("nonutf8_head", b"\xff\xfe\x80\x81" + data[4:]),
        ("nonutf8_mid", data[:n // 2] + b"\xc3\x28\xa0\xa1" + data[n // 2 + 4:]),
        ("flip_head", flip(data, 0, 16)),
        ("flip_quarter", flip(data, n // 4, n // 4 + 32)),
        ("flip_mid", flip(data, n // 2, n // 2 + 64, 3)),
        ("flip_tail", flip(data, n - 40, n)),
        ("doubled", data + data),
    ]


def bvh_variants(data: bytes) -> list[tuple[str, bytes]]:
    text = data.decode()
    lines = text.splitlines()
    motion = lines.index("MOTION")

    def without(pred) -> bytes:
        k = next(i for i, line in enumerate(lines) if pred(line))
        return ("\n".join(lines[:k] + lines[k + 1:]) + "\n").encode()

    channels = [i for i, line in enumerate(lines[:motion]) if "CHANNELS" in line]
    extra = list(lines)
    extra[channels[1]] = extra[channels[1]].replace("CHANNELS 3", "CHANNELS 4") + " Xposition"
    return [
        ("no_hierarchy_brace", without(lambda line: line.strip() == "}")),
        ("no_offset", without(lambda line: line.strip().startswith("OFFSET"))),
        ("no_channels", without(lambda line: "CHANNELS" in line)),
        ("no_frames_line", without(lambda line: line.startswith("Frames"))),
        ("no_frame_time", without(lambda line: line.startswith("Frame Time"))),
        ("no_motion", ("\n".join(lines[:motion]) + "\n").encode()),
        ("one_motion_value_short", ("\n".join(lines[:-1] + [lines[-1].rsplit(" ", 1)[0]]) + "\n").encode()),
        ("nan_value", ("\n".join(lines[:-1] + ["nan " + lines[-1].split(" ", 1)[1]]) + "\n").encode()),
        ("word_value", ("\n".join(lines[:-1] + ["abc " + lines[-1].split(" ", 1)[1]]) + "\n").encode()),
        ("extra_channel", ("\n".join(extra) + "\n").encode()),
        ("frame_time_zero", text.replace("Frame Time: 0.025", "Frame Time: 0").encode()),
        ("frames_more", text.replace("Frames: 6", "Frames: 60").encode()),
        ("frame_time_tiny", text.replace("Frame Time: 0.025", "Frame Time: 1e-300").encode()),
        ("frame_time_huge", text.replace("Frame Time: 0.025", "Frame Time: 1e308").encode()),
    ]


def glb_variants(data: bytes) -> list[tuple[str, bytes]]:
    json_len = struct.unpack_from("<I", data, 12)[0]
    bin_start = 20 + json_len
    return [
        ("flip_json", flip(data, 20, 20 + json_len, 7)),
        ("flip_json_start", flip(data, 20, 24)),
        ("flip_bin", flip(data, bin_start + 8, len(data), 5)),
        ("flip_bin_header", flip(data, bin_start, bin_start + 8)),
        ("bad_length", data[:8] + struct.pack("<I", len(data) * 3) + data[12:]),
        ("bad_json_length", data[:12] + struct.pack("<I", json_len + 1000) + data[16:]),
        ("version1", data[:4] + struct.pack("<I", 1) + data[8:]),
        ("no_bin_chunk", data[:8] + struct.pack("<I", bin_start) + data[12:bin_start]),
    ]


def gltf_variants(data: bytes) -> list[tuple[str, bytes]]:
    doc = json.loads(data)

    def edited(fn) -> bytes:
        d = json.loads(data)
        fn(d)
        return json.dumps(d).encode()

    def set_(path, value):
        def fn(d):
            obj = d
            for key in path[:-1]:
                obj = obj[key]
            obj[path[-1]] = value
        return fn

    uri = doc["buffers"][0]["uri"]
    return [
        ("json_list", b"[1, 2, 3]"),
        ("json_string", b'"gltf"'),
        ("no_asset", edited(lambda d: d.pop("asset"))),
        ("accessor_out_of_range", edited(set_(["accessors", 0, "bufferView"], 99))),
        ("accessor_count_huge", edited(set_(["accessors", 0, "count"], 10 ** 6))),
        ("accessor_type_string", edited(set_(["accessors", 0, "type"], 7))),
        ("node_children_self", edited(lambda d: d["nodes"][0].update(children=[0]))),
        ("skin_joint_missing", edited(set_(["skins", 0, "joints", 0], 999))),
        ("buffer_uri_missing_file", edited(set_(["buffers", 0, "uri"], "nope.bin"))),
        ("buffer_bad_base64", edited(set_(["buffers", 0, "uri"], uri[:60] + "!!!" + uri[63:]))),
        ("buffer_short", edited(set_(["buffers", 0, "uri"], uri[:len(uri) // 2]))),
        ("sampler_input_out_of_range", edited(set_(["animations", 0, "samplers", 0, "input"], 999))),
        ("channel_node_out_of_range",
         edited(lambda d: d["animations"][0]["channels"][0]["target"].update(node=999))),
        ("rotation_as_string", edited(lambda d: d["nodes"][1].update(rotation="x"))),
        ("matrix_zero", edited(lambda d: d["nodes"][1].update(matrix=[0.0] * 16))),
        ("matrix_huge", edited(lambda d: d["nodes"][1].update(matrix=[1e300] * 16))),
        ("scale_zero", edited(lambda d: d["nodes"][1].update(scale=[0.0, 0.0, 0.0]))),
    ]


def usda_variants(data: bytes) -> list[tuple[str, bytes]]:
    text = data.decode()
    lines = text.splitlines()
    return [
        ("no_header", "\n".join(lines[1:]).encode()),
        ("drop_line_10", ("\n".join(lines[:10] + lines[11:]) + "\n").encode()),
        ("drop_joints", "\n".join(ln for ln in lines if "uniform token[] joints" not in ln).encode()),
        ("drop_rotations", "\n".join(ln for ln in lines if "rotations" not in ln).encode()),
        ("drop_rest", "\n".join(ln for ln in lines if "restTransforms" not in ln).encode()),
        ("bad_brace", text.replace("{", "(", 3).encode()),
    ]


def usdc_variants(data: bytes) -> list[tuple[str, bytes]]:
    toc = struct.unpack_from("<Q", data, 16)[0]  # crate header: magic, version, table of contents offset
    return [
        ("version_99", data[:8] + bytes([0, 99, 0]) + data[11:]),
        ("toc_offset_past_end", data[:16] + struct.pack("<Q", len(data) * 2) + data[24:]),
        ("toc_offset_zero", data[:16] + struct.pack("<Q", 0) + data[24:]),
        ("flip_toc", flip(data, toc, len(data), 2)),
    ]


def usdz_variants(data: bytes) -> list[tuple[str, bytes]]:
    inner = data.index(b"PXR-USDC")
    return [
        ("flip_inner_header", flip(data, inner, inner + 24)),
        ("flip_zip_directory", flip(data, len(data) - 120, len(data) - 22)),
        ("inner_truncated", data[:inner + 200] + data[-200:]),
        ("not_zip", b"PK\x03\x04" + b"\0" * 200),
    ]


VARIANTS = {
    "bvh": bvh_variants,
    "glb": glb_variants,
    "gltf": gltf_variants,
    "usda": usda_variants,
    "usdc": usdc_variants,
    "usdz": usdz_variants,
}


def run(capsys, argv) -> tuple[int, list[str]]:
    code = main([str(a) for a in argv])  # an exception escaping fails the test
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


@pytest.mark.parametrize("fmt", FORMATS)
def test_corrupted_inputs_fail_in_one_line(fmt, originals, tmp_path, capsys):
    data = originals[fmt]
    variants = common_variants(data) + VARIANTS[fmt](data)
    assert len(variants) >= 17
    failures = 0
    problems = []
    for name, content in variants:
        src = tmp_path / f"{name}.{fmt}"
        src.write_bytes(content)
        for argv, out in ((["inspect", src], None),
                          (["convert", src, tmp_path / f"{name}_out.usda"], tmp_path / f"{name}_out.usda"),
                          (["convert", src, tmp_path / f"{name}_out.glb"], tmp_path / f"{name}_out.glb")):
            before = sorted(p.name for p in tmp_path.iterdir())
            try:
                code, err = run(capsys, argv)
            except Exception as e:  # noqa: BLE001 - collected so that one run lists every failure
                problems.append((name, argv[0], f"{type(e).__name__}: {e}"[:300]))
                continue
            if code not in (0, 2):
                problems.append((name, argv[0], code, err))
            elif code == 2:
                failures += 1
                if len(err) != 1 or not err[0].startswith(f"usdhands: error: {src}: "):
                    problems.append((name, argv[0], err))
                elif sorted(p.name for p in tmp_path.iterdir()) != before:
                    problems.append((name, argv[0], "output left behind"))
            elif out is not None:
                if not out.is_file():
                    problems.append((name, argv[0], "exit 0 without output"))
                else:
                    out.unlink()
    assert not problems, "\n".join(map(str, problems))
    assert failures >= len(variants)  # most variants are refused, not silently read


def test_folder_named_like_a_file(tmp_path, capsys):
    for ext in FORMATS:
        folder = tmp_path / f"x.{ext}"
        folder.mkdir()
        for argv in (["inspect", folder], ["convert", folder, tmp_path / "out.usda"]):
            code, err = run(capsys, argv)
            assert code == 2
            assert len(err) == 1 and err[0].startswith(f"usdhands: error: {folder}: "), err
        assert not (tmp_path / "out.usda").exists()


def test_usd_singular_or_huge_rest_transform(originals, tmp_path, capsys):
    """A zero-scale or overflowing restTransforms entry was a scipy ValueError traceback."""
    lines = originals["usda"].decode().splitlines()
    k = next(i for i, line in enumerate(lines) if "restTransforms" in line)
    first = "( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1) )"
    for name, matrix, message in (
            ("zero", "( (0, 0, 0, 0), (0, 0, 0, 0), (0, 0, 0, 0), (0, 0, 0, 1) )", "is singular"),
            ("huge", "( (1e300, 0, 0, 0), (0, 1e300, 0, 0), (0, 0, 1e300, 0), (0, 0, 0, 1) )", "is not finite")):
        edited = list(lines)
        assert first in edited[k]
        edited[k] = edited[k].replace(first, matrix, 1)
        src = tmp_path / f"{name}.usda"
        src.write_text("\n".join(edited) + "\n")
        code, err = run(capsys, ["inspect", src])
        assert code == 2
        assert err == [f"usdhands: error: {src}: /Root/small: restTransforms of joint 'rHand' {message}"
                       + (" (a zero scale or collapsed axes)" if name == "zero" else " (or overflows)")]


def test_usda_not_utf8(originals, tmp_path, capsys):
    """USD quotes a non-UTF-8 line in its parse error, whose str() raised UnicodeDecodeError."""
    data = originals["usda"]
    src = tmp_path / "latin1.usda"
    src.write_bytes(data[:400] + b"\xc3\x28\xa0\xa1" + data[404:])
    code, err = run(capsys, ["convert", src, tmp_path / "out.glb"])
    assert code == 2
    assert err == [f"usdhands: error: {src}: cannot read as USD: not valid UTF-8 text (corrupt or not a USD file)"]
    assert not (tmp_path / "out.glb").exists()


def test_gltf_singular_node_matrix(originals, tmp_path, capsys):
    """A zero or overflowing node matrix was 'malformed glTF (ValueError: Non-positive determinant ...'."""
    for name, matrix, message in (("zero", [0.0] * 16, "node matrix is singular (a zero scale or collapsed axes)"),
                                  ("huge", [1e300] * 16, "node matrix is not finite (or absurdly large)")):
        doc = json.loads(originals["gltf"])
        for key in ("translation", "rotation", "scale"):
            doc["nodes"][1].pop(key, None)
        doc["nodes"][1]["matrix"] = matrix
        src = tmp_path / f"{name}.gltf"
        src.write_text(json.dumps(doc))
        code, err = run(capsys, ["inspect", src])
        assert code == 2
        assert err == [f"usdhands: error: {src}: nodes[1]: {message}"]


def test_usd_parse_error_is_short_and_relative_path_kept(originals, tmp_path, capsys, monkeypatch):
    """The text parser quotes the whole offending line (a whole array: thousands of characters);
    with a relative path, the absolute path in USD's message was half replaced ('/tmp/x/line 32:13')."""
    lines = originals["usda"].decode().splitlines()
    k = next(i for i, line in enumerate(lines) if "restTransforms" in line)
    lines[k] = lines[k].replace("(0, 0, 20, 1) ), (", "(0, 0, 20, 1) ) (", 1)  # a missing comma
    (tmp_path / "broken.usda").write_text("\n".join(lines) + "\n")
    monkeypatch.chdir(tmp_path)
    code, err = run(capsys, ["inspect", "broken.usda"])
    assert code == 2 and len(err) == 1
    assert err[0].startswith("usdhands: error: broken.usda: cannot read as USD: line "), err
    assert str(tmp_path) not in err[0]
    assert len(err[0]) < 300


def test_bvh_frame_time_bounds_and_tabs(originals, tmp_path, capsys):
    """'Frame Time: 1e-300' read as 1e300 fps and convert died in the glTF writer ('frame times do
    not increase in float32' ValueError); 'Frame<TAB>Time:' was refused as a missing header."""
    text = originals["bvh"].decode()
    tiny = tmp_path / "tiny.bvh"
    tiny.write_text(text.replace("Frame Time: 0.025", "Frame Time: 1e-300"))
    code, err = run(capsys, ["convert", tiny, tmp_path / "tiny.glb"])
    assert (code, err) == (2, [f"usdhands: error: {tiny}: line 109: frame time 1e-300 s is outside 0.0001..1000 s "
                               "(at most 10000 frames per second)"])
    tabs = tmp_path / "tabs.bvh"
    tabs.write_text(text.replace("Frame Time: 0.025", "Frame\tTime:\t0.025").replace("Frames: 6", "Frames:\t6"))
    from usdhands.formats.io import read_clip

    spaces = tmp_path / "spaces.bvh"
    spaces.write_bytes(originals["bvh"])
    a, b = read_clip(tabs), read_clip(spaces)
    assert (a.num_frames, a.fps) == (b.num_frames, b.fps) == (6, 40.0)
    np.testing.assert_array_equal(a.rotations, b.rotations)


@pytest.mark.parametrize("tcps", ["0", "-24", "nan", "1e300", "1e-300"])
def test_usd_time_codes_per_second_out_of_range(tcps, originals, tmp_path, capsys):
    """timeCodesPerSecond 0 was a ZeroDivisionError, -24 and NaN 'Expected fps > 0' ValueErrors,
    1e300 and 1e-300 died in the glTF writer (float32 key times)."""
    from pxr import Usd

    src = tmp_path / "tcps.usda"
    src.write_bytes(originals["usda"])
    stage = Usd.Stage.Open(str(src))
    stage.SetTimeCodesPerSecond(float(tcps))
    stage.GetRootLayer().Save()
    shown = f"{float(tcps):g}"
    for argv in (["inspect", src], ["convert", src, tmp_path / "out.glb"]):
        code, err = run(capsys, argv)
        assert (code, err) == (2, [f"usdhands: error: {src}: timeCodesPerSecond {shown} is outside 0.001..10000"])
    assert not (tmp_path / "out.glb").exists()


def test_usd_time_samples_too_close(originals, tmp_path, capsys):
    """Time samples a millionth of a time code apart made 4e7 fps."""
    from pxr import Usd, UsdSkel

    src = tmp_path / "close.usda"
    src.write_bytes(originals["usda"])
    stage = Usd.Stage.Open(str(src))
    for prim in stage.Traverse():
        if prim.IsA(UsdSkel.Animation):
            for attr in prim.GetAttributes():
                values = [attr.Get(t) for t in attr.GetTimeSamples()]
                if values:
                    attr.Clear()
                    for k, v in enumerate(values):
                        attr.Set(v, k * 1e-6)
    stage.GetRootLayer().Save()
    code, err = run(capsys, ["convert", src, tmp_path / "out.glb"])
    assert (code, err) == (2, [f"usdhands: error: {src}: /Root/small_2: time samples give 4e+07 frames per second "
                               "(outside 0.001..10000)"])


def _gltf_with_key_times(data: bytes, times) -> str:
    """The .gltf ``data`` with the key times of its (shared) animation input accessor replaced."""
    import base64

    doc = json.loads(data)
    inputs = {s["input"] for s in doc["animations"][0]["samplers"]}
    assert len(inputs) == 1
    acc = doc["accessors"][inputs.pop()]
    view = doc["bufferViews"][acc["bufferView"]]
    head, b64 = doc["buffers"][0]["uri"].split(",", 1)
    buf = bytearray(base64.b64decode(b64))
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    values = np.asarray(times, dtype=np.float32)
    assert values.size == acc["count"]
    buf[start:start + 4 * values.size] = values.tobytes()
    acc["min"], acc["max"] = [float(np.nanmin(values))], [float(np.nanmax(values))]
    doc["buffers"][0]["uri"] = head + "," + base64.b64encode(bytes(buf)).decode()
    return json.dumps(doc)


@pytest.mark.parametrize("name, times, message", [
    ("nan", [0, np.nan, np.nan, np.nan, np.nan, np.nan], "animations[0].channels[0]: sampler input times are not finite"),
    ("tiny", np.arange(6) * 1e-9, "animations[0]: key times 1e-09 s apart give 1e+09 frames per second (at most 10000)"),
    # the rate is the one the writer recorded in extras (the BVH source is at 40 fps): the keys sit on its frames
    ("huge", np.arange(6) * 1e30, "animations[0]: key times span 5e+30 s: over 1e+07 frames at 40 fps"),
])
def test_gltf_key_times_out_of_range(name, times, message, originals, tmp_path, capsys):
    """NaN key times were 'malformed glTF (ValueError: cannot convert float NaN to integer)', times 1e30 s
    apart 'malformed glTF (ValueError: Maximum allowed size exceeded)', 1e-9 s apart read at 1e9 fps."""
    src = tmp_path / f"{name}.gltf"
    src.write_text(_gltf_with_key_times(originals["gltf"], times))
    for argv in (["inspect", src], ["convert", src, tmp_path / "out.usda"]):
        code, err = run(capsys, argv)
        assert (code, err) == (2, [f"usdhands: error: {src}: {message}"]), argv
    assert not (tmp_path / "out.usda").exists()

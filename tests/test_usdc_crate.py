"""The .usdc (crate) check before USD opens a file (usdhands/formats/usdc_crate.py).

USD's crate reader trusts the counts and indices a file states. The usdc fuzzer found
files that made it allocate more than 3 GB (a table of contents of 117 million
sections), print ``failed call to posix_madvise`` on stderr (a section or a value
offset past the file), and crash (a token index past the token table). Each class is
built here from the sample humanoid and must fail in one line; every file USD itself
writes (dictionaries, references, payloads, list ops, compressed arrays, time samples,
packages) must pass the check untouched.
"""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

from hostile import crate_lies, crate_seed, run_batch  # noqa: E402  (tests/ is on sys.path)
from usdhands.compiled import kernel_module
from usdhands.errors import AssetReadError
from usdhands.formats.usdc_crate import check_crate, check_crate_bytes, lz4_block_decompress


def rich_layer(path):
    """A .usdc holding every kind of value the check walks, written by USD itself."""
    from pxr import Gf, Sdf, Usd, Vt

    layer = Sdf.Layer.CreateNew(str(path))
    layer.customLayerData = {"a": 1, "b": {"c": "x", "d": Vt.IntArray([1, 2, 3])}, "e": Sdf.AssetPath("x.usd")}
    stage = Usd.Stage.Open(layer)
    root = stage.DefinePrim("/Root", "Xform")
    root.SetCustomData({"k": "v", "n": 3.5, "l": ["a", "b"]})
    root.GetReferences().AddInternalReference("/Other", Sdf.LayerOffset(1, 2))
    root.GetPayloads().AddInternalPayload("/Other", Sdf.LayerOffset(3))
    root.GetInherits().AddInherit("/Class")
    variants = root.GetVariantSets().AddVariantSet("look")
    variants.AddVariant("red")
    variants.SetVariantSelection("red")
    root.SetMetadata("apiSchemas", Sdf.TokenListOp.Create(prependedItems=["SkelBindingAPI"], deletedItems=["X"]))
    stage.DefinePrim("/Other")
    prim = stage.DefinePrim("/Root/Attrs")
    T = Sdf.ValueTypeNames
    values = {
        "ints": (T.IntArray, Vt.IntArray(list(range(100)))),  # compressed integers
        "ints64": (T.Int64Array, Vt.Int64Array([2 ** 40 + i for i in range(50)])),
        "floats_int": (T.FloatArray, Vt.FloatArray([float(i) for i in range(64)])),  # 'i' code
        "floats_lut": (T.FloatArray, Vt.FloatArray([0.5, 0.25] * 40)),  # 't' code: lookup table
        "floats_raw": (T.FloatArray, Vt.FloatArray([i / 7 for i in range(100)])),
        "halfs": (T.HalfArray, Vt.HalfArray([1.0] * 40)),
        "tokens": (T.TokenArray, Vt.TokenArray(["a", "b", "c"] * 20)),
        "strings": (T.StringArray, Vt.StringArray(["x", "yy"] * 20)),
        "assets": (T.AssetArray, Sdf.AssetPathArray([Sdf.AssetPath("a.png")] * 3)),
        "matrices": (T.Matrix4dArray, Vt.Matrix4dArray([Gf.Matrix4d(2)] * 5)),
        "quats": (T.QuatfArray, Vt.QuatfArray([Gf.Quatf(1, 0, 0, 0)] * 700)),  # zero-copy sized
        "empty": (T.IntArray, Vt.IntArray()),
        "token": (T.Token, "hello"),
        "string": (T.String, "a string"),
        "matrix": (T.Matrix4d, Gf.Matrix4d(3)),
    }
    for name, (kind, value) in values.items():
        prim.CreateAttribute(name, kind).Set(value)
    animated = prim.CreateAttribute("animated", T.Float3Array)
    for frame in range(20):
        animated.Set(Vt.Vec3fArray([Gf.Vec3f(frame, 0, 0)] * 30), frame)
    prim.CreateRelationship("rel").SetTargets(["/Root", "/Root/Attrs"])
    layer.Save()


def test_files_usd_writes_pass(sample_assets, tmp_path):
    rich = tmp_path / "rich.usdc"
    rich_layer(rich)
    check_crate(rich)
    check_crate(sample_assets / "conversation_bodyonly.usdc")
    check_crate_bytes(crate_seed(sample_assets, tmp_path))
    text = sample_assets / "humanoid.usda"
    check_crate(text)  # not a crate: nothing to check


def test_third_party_package_passes(shared_assets):
    check_crate(shared_assets / "usd_cesiumman" / "CesiumMan.usdz")


@pytest.mark.parametrize("lie", ["toc_sections", "section_past_end", "token_index", "array_count", "token_count",
                                 "spec_type", "value_offset"])
def test_each_lie_is_refused_by_the_check(lie, sample_assets, tmp_path):
    data, message = crate_lies(crate_seed(sample_assets, tmp_path))[lie]
    with pytest.raises(AssetReadError) as e:
        check_crate_bytes(data, tmp_path / "x.usdc")
    assert message in str(e.value)
    assert str(e.value).startswith(f"{tmp_path / 'x.usdc'}: cannot read as USD: ")


def test_a_listed_child_without_a_spec_is_refused_before_usd_composes(sample_assets, tmp_path):
    """The crate's byte layout is sound here; the lie is in what a spec lists (checked through Sdf)."""
    from usdhands.formats.usd_common import open_stage

    data, message = crate_lies(crate_seed(sample_assets, tmp_path))["child_without_spec"]
    check_crate_bytes(data)  # nothing the bytes cannot hold
    bad = tmp_path / "child.usdc"
    bad.write_bytes(data)
    with pytest.raises(AssetReadError) as e:
        open_stage(bad)
    assert str(e.value) == f"{bad}: cannot read as USD: {message}"


def test_lies_keep_the_promise_in_every_reading_command(sample_assets, tmp_path):
    """One subprocess, fd 2 captured: USD's own posix_madvise line would be a second line."""
    lies = crate_lies(crate_seed(sample_assets, tmp_path))
    cases, expected = [], []
    for name, (data, message) in lies.items():
        path = tmp_path / f"{name}.usdc"
        path.write_bytes(data)
        for argv in (["inspect", path], ["convert", path, tmp_path / f"{name}_out.glb"]):
            cases.append(argv)
            expected.append((name, path, message))
    before = sorted(p.name for p in tmp_path.iterdir())
    for (name, path, message), result in zip(expected, run_batch(cases)):
        lines = result["stderr"].splitlines()
        assert result["code"] == 2, (name, result)
        assert lines == [lines[0]] and lines[0].startswith(f"usdhands: error: {path}: cannot read as USD: "), (
            name, result["stderr"])
        assert message in lines[0], (name, lines[0])
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_a_package_holding_a_lying_crate_names_the_member(sample_assets, tmp_path):
    data, message = crate_lies(crate_seed(sample_assets, tmp_path))["token_count"]
    package = tmp_path / "bad.usdz"
    with zipfile.ZipFile(package, "w", compression=zipfile.ZIP_STORED) as z:
        z.writestr("root.usdc", data)
    with pytest.raises(AssetReadError) as e:
        check_crate(package)
    assert str(e.value).startswith(f"{package}: root.usdc: cannot read as USD: ")
    assert message in str(e.value)


def test_a_package_member_is_checked_whatever_its_checksum_says(sample_assets, tmp_path):
    """USD reads a stored member without its CRC: a member whose CRC does not match was skipped by the
    check (zipfile refused to read it) and handed to USD unchecked."""
    import struct

    data, message = crate_lies(crate_seed(sample_assets, tmp_path))["token_count"]
    package = tmp_path / "bad_crc.usdz"
    with zipfile.ZipFile(package, "w", compression=zipfile.ZIP_STORED) as z:
        z.writestr("root.usdc", data)
    crc = struct.pack("<I", zipfile.ZipFile(package).getinfo("root.usdc").CRC)
    raw = package.read_bytes()
    assert raw.count(crc) == 2  # the local header's and the central directory's
    package.write_bytes(raw.replace(crc, struct.pack("<I", ~struct.unpack("<I", crc)[0] & 0xFFFFFFFF)))
    with pytest.raises(zipfile.BadZipFile):
        zipfile.ZipFile(package).read("root.usdc")
    with pytest.raises(AssetReadError) as e:
        check_crate(package)
    assert str(e.value).startswith(f"{package}: root.usdc: cannot read as USD: ")
    assert message in str(e.value)
    good = tmp_path / "good.usdz"
    with zipfile.ZipFile(good, "w", compression=zipfile.ZIP_STORED) as z:
        z.writestr("root.usdc", crate_seed(sample_assets, tmp_path))
        z.writestr("notes.txt", b"not a crate")
    assert check_crate(good)


@pytest.mark.parametrize("how", ["central directory elsewhere", "no central directory", "local size larger",
                                 "second member", "directory version too new", "a line break in the name"])
def test_a_package_member_found_by_its_local_header_is_checked(sample_assets, tmp_path, how):
    """USD finds a package's members by walking their local headers from the start: a crate whose
    central directory entry pointed elsewhere (usdz fuzz: the entry's offset changed) was skipped
    by the check and handed to USD, which mapped 9.6 GB reading it. Each member the walk finds is
    checked too (a member's data as long as either size its local header gives); a central directory
    zipfile cannot read ("zip file version 11.6": a NotImplementedError out of the check) leaves the walk."""
    import struct

    data, message = crate_lies(crate_seed(sample_assets, tmp_path))["token_count"]
    package = tmp_path / "walk.usdz"
    with zipfile.ZipFile(package, "w", compression=zipfile.ZIP_STORED) as z:
        if how == "second member":
            z.writestr("notes.txt", b"not a crate")
        z.writestr("root.usdc", data)
    raw = bytearray(package.read_bytes())
    directory = raw.rindex(b"PK\x01\x02")  # the last member's central directory entry
    if how == "central directory elsewhere":
        raw[directory + 42:directory + 46] = struct.pack("<I", 52)  # its local header's offset
    elif how == "no central directory":
        del raw[raw.index(b"PK\x01\x02"):]
    elif how == "directory version too new":  # zipfile raised NotImplementedError (usdz fuzz)
        raw[directory + 6:directory + 8] = struct.pack("<H", 116)
    elif how == "local size larger":  # both sizes of the local header, not the directory's
        at = raw.rindex(b"PK\x03\x04", 0, directory)
        raw[at + 18:at + 26] = struct.pack("<II", len(data) + 64, len(data) + 64)
        raw[directory + 42:directory + 46] = struct.pack("<I", 52)
    elif how == "a line break in the name":  # named in the error as \\n, one line (usdz fuzz)
        at = raw.rindex(b"PK\x03\x04", 0, directory)
        raw[at + 30:at + 39] = b"root.u\nPK"
        raw[directory + 42:directory + 46] = struct.pack("<I", 52)
    package.write_bytes(bytes(raw))
    with pytest.raises(AssetReadError) as e:
        check_crate(package)
    name = "root.u\\nPK" if how == "a line break in the name" else "root.usdc"
    assert str(e.value).startswith(f"{package}: {name}: cannot read as USD: ")
    assert message in str(e.value) and "\n" not in str(e.value)


def test_a_member_only_the_central_directory_names_is_not_read(sample_assets, tmp_path):
    """The check reads the members USD reads: those a walk of the local headers reaches from the start of
    the package (Sdf.ZipFile lists the same), not what the central directory names besides. A lying crate
    behind bytes the walk cannot cross, named by the directory alone, is not USD's to read: the package
    passes and opens; the same crate where the walk reaches it is refused."""
    import struct

    from pxr import Sdf

    good = (tmp_path / "good.usdc")
    Sdf.Layer.CreateAnonymous(".usdc").Export(str(good))
    data, message = crate_lies(crate_seed(sample_assets, tmp_path))["token_count"]
    package = tmp_path / "hidden.usdz"
    with zipfile.ZipFile(package, "w", compression=zipfile.ZIP_STORED) as z:
        z.writestr("root.usdc", good.read_bytes())
        z.writestr("lie.usdc", data)
    raw = bytearray(package.read_bytes())
    second = raw.index(b"PK\x03\x04", 4)
    gap = b"\0" * 64  # the walk stops here: no local header after the first member's data
    raw[second:second] = gap
    directory = raw.index(b"PK\x01\x02")
    for entry in (directory, raw.index(b"PK\x01\x02", directory + 4)):  # the directory's offsets moved too
        offset, = struct.unpack_from("<I", raw, entry + 42)
        if offset >= second:
            raw[entry + 42:entry + 46] = struct.pack("<I", offset + len(gap))
    end = raw.rindex(b"PK\x05\x06")
    start, = struct.unpack_from("<I", raw, end + 16)
    raw[end + 16:end + 20] = struct.pack("<I", start + len(gap))
    package.write_bytes(bytes(raw))
    assert [i.filename for i in zipfile.ZipFile(package).infolist()] == ["root.usdc", "lie.usdc"]
    assert list(Sdf.ZipFile.Open(str(package)).GetFileNames()) == ["root.usdc"]
    assert check_crate(package)
    assert Sdf.Layer.FindOrOpen(str(package)) is not None
    del raw[second:second + len(gap)]  # the walk reaches it: refused
    reached = tmp_path / "reached.usdz"
    reached.write_bytes(bytes(raw))
    with pytest.raises(AssetReadError, match="lie.usdc: cannot read as USD: ") as e:
        check_crate(reached)
    assert message in str(e.value)


def test_the_rewritten_sections_of_the_cases_are_valid(sample_assets, tmp_path):
    """The spec-type case rewrites SPECS with its own encoder: unchanged types give a file USD reads."""
    import struct

    from hostile import _encode_ints, respec  # noqa: E402

    from usdhands.formats.io import read_asset
    from usdhands.formats.usdc_crate import _Crate, decode_ints

    values = [7, 6, 6, 1, 1, 8, 1, 300000, -5]
    body = _encode_ints(values)[8:]
    assert decode_ints(lz4_block_decompress(body[1:], 1000), len(values)).tolist() == values
    good = crate_seed(sample_assets, tmp_path)
    crate = _Crate(good)
    crate.table_of_contents()
    toc = struct.unpack_from("<q", good, 16)[0]
    names = [good[toc + 8 + 32 * k:toc + 24 + 32 * k].split(b"\0")[0] for k in range(6)]
    same = tmp_path / "same.usdc"
    same.write_bytes(respec(good, crate, toc, names, retype=False))
    check_crate(same)
    original = tmp_path / "original.usdc"
    original.write_bytes(good)
    a, b = read_asset(same), read_asset(original)
    assert a.skeletons[0].joint_names == b.skeletons[0].joint_names
    assert (a.clips[0].rotations == b.clips[0].rotations).all()


def test_spec_types_against_the_path_tree():
    """Root, prim and property entries carry their own spec types; an entry the tree never reaches has
    no path (USD leaves it empty) and is not judged (the usdc fuzz: 978 KeyErrors before this)."""
    import numpy as np

    from usdhands.formats.usdc_crate import _Corrupt, _Crate

    crate = _Crate(b"")
    # root -> /A (child) -> /A.x (property, last); entry 3 unreached
    paths = [np.array([0, 1, 2, 3]), np.array([0, 5, -6, 7]), np.array([-1, -1, -2, -2])]
    specs = [np.array([0, 1, 2, 3]), np.zeros(4, dtype=int), np.array([7, 6, 1, 4])]
    crate.spec_types(specs, paths)
    specs[2] = np.array([7, 4, 1, 4])
    with pytest.raises(_Corrupt, match="a spec of type 4 on a prim path"):
        crate.spec_types(specs, paths)
    specs[2] = np.array([7, 6, 1, 4])
    # entry 1's sibling jump lands on its own child: two tasks of USD would build entry 2 at once
    with pytest.raises(_Corrupt, match="reaches entry 2 twice"):
        crate.spec_types(specs, [paths[0], paths[1], np.array([-1, 1, -2, -2])])


def test_lz4_blocks():
    assert lz4_block_decompress(b"\x40abcd", 100) == b"abcd"
    # 'ab' then a match 2 back, 6 long (overlapping): the last two bytes repeated
    assert lz4_block_decompress(b"\x22ab\x02\x00", 100) == b"abababab"
    with pytest.raises(ValueError, match="offset outside the output"):
        lz4_block_decompress(b"\x22ab\x09\x00", 100)
    with pytest.raises(ValueError, match="more than 5 bytes"):
        lz4_block_decompress(b"\x22ab\x02\x00", 5)
    with pytest.raises(ValueError, match="literals run past"):
        lz4_block_decompress(b"\x90ab", 100)


def test_a_text_layer_composing_a_lying_crate_is_refused(sample_assets, tmp_path):
    """USD opens sublayers while composing: the crafted crate crashed the interpreter through a .usda."""
    data, message = crate_lies(crate_seed(sample_assets, tmp_path))["token_index"]
    (tmp_path / "lie.usdc").write_bytes(data)
    top = tmp_path / "shot.usda"
    top.write_text('#usda 1.0\n(\n    subLayers = [@./lie.usdc@]\n)\n')
    [result] = run_batch([["inspect", top]])
    assert result["code"] == 2, result
    assert result["stderr"].splitlines() == [
        f"usdhands: error: {top}: composes {tmp_path / 'lie.usdc'}: cannot read as USD: "
        + result["stderr"].split("cannot read as USD: ", 1)[1].rstrip("\n")]
    assert message in result["stderr"]


def test_each_layer_is_checked_once_whatever_path_names_it(tmp_path, monkeypatch):
    """The layers a stage composes are checked once per file: a sublayer naming the opened file through a
    symbolic link, and a crate named twice (once through a link), are the files already checked; the
    opened file's real path is compared with theirs (it is looked up only when a second layer comes)."""
    from pxr import Sdf

    from usdhands.formats import usd_common

    Sdf.Layer.CreateAnonymous(".usdc").Export(str(tmp_path / "a.usdc"))
    (tmp_path / "b.usdc").symlink_to(tmp_path / "a.usdc")
    (tmp_path / "alias.usda").symlink_to(tmp_path / "shot.usda")
    top = tmp_path / "shot.usda"
    top.write_text('#usda 1.0\n(\n    subLayers = [@./alias.usda@, @./a.usdc@, @./b.usdc@]\n)\n')
    checked = []
    real = usd_common.check_crate_file
    monkeypatch.setattr(usd_common, "check_crate_file", lambda path: checked.append(path.name) or real(path))
    layers = usd_common.checked_layers(top)
    assert len(checked) == 2 and checked[0] == "shot.usda" and checked[1] in ("a.usdc", "b.usdc")
    assert len(layers) == 2
    checked.clear()
    assert len(usd_common.checked_layers(tmp_path / "a.usdc")) == 1 and checked == ["a.usdc"]


def _decode_ints_one_by_one(encoded: bytes, n: int, width: int) -> list[int]:
    """Sdf's integer coding read integer by integer: a common delta, 2-bit codes, signed deltas, summed as int64."""
    codes_size = (2 * n + 7) // 8
    if len(encoded) < width + codes_size:
        raise ValueError
    common = int.from_bytes(encoded[:width], "little", signed=True)
    sizes = [0, 1, 2, 4] if width == 4 else [0, 2, 4, 8]
    pos, total, out = width + codes_size, 0, []
    for i in range(n):
        size = sizes[(encoded[width + i // 4] >> (2 * (i % 4))) & 3]
        if pos + size > len(encoded):
            raise ValueError
        total += common if size == 0 else int.from_bytes(encoded[pos:pos + size], "little", signed=True)
        total = (total + (1 << 63)) % (1 << 64) - (1 << 63)  # int64 sums wrap
        pos += size
        out.append(total)
    return out


@pytest.mark.parametrize("width", [4, 8])
def test_decode_ints_equals_decoding_one_by_one(width):
    from usdhands.formats.usdc_crate import decode_ints

    rng = np.random.default_rng(width)
    for trial in range(400):  # up to 40 (32-bit ones decoded one by one in Python), 60-300 (NumPy)
        n = int(rng.integers(0, 40)) if trial % 2 else int(rng.integers(60, 300))
        codes = rng.integers(0, 4, n)
        sizes = ([0, 1, 2, 4] if width == 4 else [0, 2, 4, 8])
        body = b"".join(int(rng.integers(-(1 << (8 * sizes[c] - 1)), 1 << (8 * sizes[c] - 1))).to_bytes(
            sizes[c], "little", signed=True) for c in codes if sizes[c])
        packed = bytearray((2 * n + 7) // 8)
        for i, c in enumerate(codes):
            packed[i // 4] |= int(c) << (2 * (i % 4))
        common = int(rng.integers(-1000, 1000)).to_bytes(width, "little", signed=True)
        encoded = common + bytes(packed) + body
        for data in (encoded, encoded[:len(encoded) - int(rng.integers(1, 4))] if len(encoded) > 3 else b""):
            try:
                want = _decode_ints_one_by_one(data, n, width)
            except ValueError:
                with pytest.raises(ValueError):
                    decode_ints(data, n, width)
                continue
            got = decode_ints(data, n, width)
            assert got.dtype == np.int64 and got.tolist() == want


def test_a_layer_composing_a_path_with_a_nul_reads(tmp_path):
    """A sublayer path holding a NUL byte (usdz fuzz: a package's root.usda mutated) raised ValueError
    ('embedded null byte') from the layer walk before USD opened the stage: no such file, read as USD
    reads it (a missing sublayer)."""
    from usdhands.formats.io import read_asset

    p = tmp_path / "nul.usda"
    p.write_bytes(b"#usda 1.0\n(\n    subLayers = [@./x\x00y.usdc@]\n)\n")
    asset = read_asset(p)
    assert asset.skeletons == () and asset.clips == ()


def test_sorted_unique_is_numpys_unique():
    from usdhands.formats.usdc_crate import _sorted_unique

    rng = np.random.default_rng(0)
    for n in (0, 1, 2, 5, 40, 1800):
        a = rng.integers(0, 1 << 63, n, dtype=np.uint64)
        a[::3] = a[0] if n else a[::3]
        got = _sorted_unique(a)
        assert got.dtype == np.uint64 and got.tolist() == np.unique(a).tolist()


def _seed_reps(good: bytes):
    from usdhands.formats.usdc_crate import _Crate

    crate = _Crate(good)
    crate.table_of_contents()
    return crate, np.frombuffer(crate.structural(), dtype="<u8").tolist()


def test_a_short_run_of_indices_past_its_table_is_refused(sample_assets, tmp_path):
    """Runs of up to 8 indices are read by struct, longer ones by NumPy: a token vector of the seed
    (one or two entries) and a dictionary key (one string index) naming entries past their tables."""
    import struct

    good = crate_seed(sample_assets, tmp_path)
    crate, reps = _seed_reps(good)

    def payload(kind):
        return next(r & ((1 << 48) - 1) for r in reps
                    if (r >> 48) & 0xFF == kind and not r & (3 << 62) and r & ((1 << 48) - 1))

    vector = payload(41)  # a token vector: count, then uint32 token indices
    size = struct.unpack_from("<Q", good, vector)[0]
    assert 1 <= size <= 8
    for k in range(size):
        data = bytearray(good)
        struct.pack_into("<I", data, vector + 8 + 4 * k, 1_000_000)
        with pytest.raises(AssetReadError, match=f"a vector value names token 1000000 of {crate.tables['token']}"):
            check_crate_bytes(bytes(data))
    dictionary = payload(31)  # a dictionary: count, then a string index per key
    data = bytearray(good)
    struct.pack_into("<I", data, dictionary + 8, 70_000)
    with pytest.raises(AssetReadError, match=f"a dictionary key names string 70000 of {crate.tables['string']}"):
        check_crate_bytes(bytes(data))


def test_time_samples_claiming_more_times_than_values_are_refused(sample_assets, tmp_path):
    """usdc fuzz (on main too: 240 findings in 4 min): a time samples' times vector claiming more
    times than it has values made USD read the values past them by index (a Tf.CppException
    traceback, 'SdfReadOutOfBoundsError'); the check refuses it in one line."""
    import struct

    from usdhands.formats.io import read_asset

    good = crate_seed(sample_assets, tmp_path)
    _, reps = _seed_reps(good)
    samples = next(r & ((1 << 48) - 1) for r in reps if (r >> 48) & 0xFF == 46 and not r & (1 << 62))
    times = samples + struct.unpack_from("<q", good, samples)[0]
    times_rep = struct.unpack_from("<Q", good, times)[0]
    assert (times_rep >> 48) & 0xFF == 48 and not times_rep & (3 << 62)
    values = times + 8 + struct.unpack_from("<q", good, times + 8)[0]
    n = struct.unpack_from("<Q", good, values)[0]
    data = bytearray(good)
    struct.pack_into("<Q", data, times_rep & ((1 << 48) - 1), n + 1)
    path = tmp_path / "times.usdc"
    path.write_bytes(bytes(data))
    with pytest.raises(AssetReadError, match=f"time samples claim {n + 1} times for {n} values"):
        read_asset(path)
    struct.pack_into("<Q", data, times_rep & ((1 << 48) - 1), n)  # as many: read
    path.write_bytes(bytes(data))
    assert read_asset(path).clips


_CRATE_COMPILED = kernel_module("formats._crate_compiled")
needs_crate_kernel = pytest.mark.skipif(_CRATE_COMPILED is None, reason="formats._crate_compiled was not built")


def _outcome(fn, *args):
    try:
        return ("ok", fn(*args))
    except ValueError as e:
        return ("ValueError", str(e))


def _lz4_block(rng) -> bytes:
    """An LZ4 block of random sequences: literals (some past 15 bytes: length bytes), matches near and far,
    overlapping ones, lengths of 255 and more; now and then a byte changed or the block cut short."""
    out, produced = bytearray(), 0
    for _ in range(int(rng.integers(0, 12))):
        lit = int(rng.choice([0, 1, 3, 15, 16, 40, 300]))
        match = int(rng.choice([0, 4, 11, 19, 20, 270, 600]))
        token_lit, token_match = min(lit, 15), min(max(match - 4, 0), 15)
        out.append((token_lit << 4) | token_match)
        if lit >= 15:
            rest = lit - 15
            while rest >= 255:
                out.append(255)
                rest -= 255
            out.append(rest)
        out += bytes(rng.integers(0, 256, lit, dtype=np.uint8))
        produced += lit
        offset = int(rng.integers(1, max(produced, 1) + 2))  # sometimes one past the output
        out += offset.to_bytes(2, "little")
        if token_match == 15:
            rest = match - 4 - 15
            while rest >= 255:
                out.append(255)
                rest -= 255
            out.append(rest)
        produced += max(match, 4)
    out += bytes([0x30]) + b"end"
    data = bytes(out)
    if rng.random() < 0.3 and data:
        k = int(rng.integers(0, len(data)))
        data = data[:k] + bytes([int(rng.integers(0, 256))]) + data[k + 1:]
    if rng.random() < 0.2:
        data = data[:int(rng.integers(0, len(data) + 1))]
    return data


@needs_crate_kernel
def test_compiled_lz4_equals_the_python_twin():
    """The same bytes or the same ValueError for valid blocks, blocks with a byte changed, cut short, random
    bytes, and limits below, at and above what a block decodes to."""
    from usdhands.formats.usdc_crate import lz4_block_decompress as python_lz4

    rng = np.random.default_rng(7)
    kinds = {"ok": 0, "ValueError": 0}
    for trial in range(3000):
        data = _lz4_block(rng) if trial % 4 else bytes(rng.integers(0, 256, int(rng.integers(0, 60)), dtype=np.uint8))
        full = _outcome(python_lz4, data, 1 << 20)
        limits = [1 << 20, 0, 1]
        if full[0] == "ok":
            limits += [len(full[1]), len(full[1]) - 1, len(full[1]) + 1]
        for limit in limits:
            want = _outcome(python_lz4, data, limit)
            assert _outcome(_CRATE_COMPILED.lz4_block_decompress, data, limit) == want, (data, limit)
            assert _outcome(_CRATE_COMPILED.lz4_block_decompress, memoryview(data), limit) == want
            kinds[want[0]] += 1
    assert kinds["ok"] > 1000 and kinds["ValueError"] > 1000, kinds


@needs_crate_kernel
@pytest.mark.parametrize("width", [4, 8])
def test_compiled_decode_ints_equals_the_python_twin(width):
    """Both of the Python function's paths (one by one up to 96 32-bit integers, NumPy past that), on
    coded integers whole, cut short and random; sums that wrap as int64 (8-byte deltas)."""
    from usdhands.formats.usdc_crate import decode_ints

    rng = np.random.default_rng(width + 10)
    kinds = {"ok": 0, "ValueError": 0}
    for trial in range(1500):
        n = int(rng.choice([0, 1, 5, 40, 96, 97, 300]))
        codes = rng.integers(0, 4, n)
        sizes = [0, 1, 2, 4] if width == 4 else [0, 2, 4, 8]
        body = b"".join(int(rng.integers(-(1 << (8 * sizes[c] - 1)), 1 << (8 * sizes[c] - 1), dtype=np.int64)).to_bytes(
            sizes[c], "little", signed=True) for c in codes if sizes[c])
        packed = bytearray((2 * n + 7) // 8)
        for i, c in enumerate(codes):
            packed[i // 4] |= int(c) << (2 * (i % 4))
        common = int(rng.integers(-(1 << 31), 1 << 31)).to_bytes(width, "little", signed=True)
        encoded = common + bytes(packed) + body
        cases = [encoded, encoded[:int(rng.integers(0, len(encoded) + 1))],
                 bytes(rng.integers(0, 256, int(rng.integers(0, 80)), dtype=np.uint8))]
        for data in cases:
            want = _outcome(decode_ints, data, n, width)
            got = _outcome(_CRATE_COMPILED.decode_ints, data, n, width)
            if want[0] == "ok":
                assert got[0] == "ok" and got[1].dtype == np.int64 and got[1].tolist() == want[1].tolist()
            else:
                assert got == want
            kinds[want[0]] += 1
    assert kinds["ok"] > 1000 and kinds["ValueError"] > 500, kinds


def test_the_check_refuses_the_same_lies_with_and_without_the_compiled_loops(sample_assets, tmp_path, monkeypatch):
    """Every crafted crate of the hostile corpus gives the same line with the Python loops and walks as with the
    compiled ones."""
    import usdhands.formats.usdc_crate as crate

    lies = crate_lies(crate_seed(sample_assets, tmp_path))
    lines = {}
    for python in (False, True):
        if python:
            monkeypatch.setattr(crate, "_lz4_block", crate.lz4_block_decompress)
            monkeypatch.setattr(crate, "_decode_ints", crate.decode_ints)
            monkeypatch.setattr(crate, "_walk_values", None)
            monkeypatch.setattr(crate, "_spec_types", None)
            monkeypatch.setattr(crate, "_check_structure", None)
        for name, (data, _) in lies.items():
            try:
                check_crate_bytes(data, "x.usdc")
                lines.setdefault(name, []).append(None)
            except AssetReadError as e:
                lines.setdefault(name, []).append(str(e))
    assert all(a == b for a, b in lines.values()), lines
    assert sum(a is not None for a, _ in lines.values()) >= len(lies) - 1


def _walk_seeds(sample_assets, tmp_path) -> list[bytes]:
    """Crate files whose values the walks check: every kind of value USD writes (rich_layer), the humanoid
    with a dictionary, and the sample conversation (885 frames of time samples)."""
    rich = tmp_path / "rich_walk.usdc"
    rich_layer(rich)
    return [rich.read_bytes(), crate_seed(sample_assets, tmp_path),
            (sample_assets / "conversation_bodyonly.usdc").read_bytes()]


def _walk_outcome(fn, *args):
    from usdhands.formats.usdc_crate import _Corrupt

    try:
        fn(*args)
        return ("ok",)
    except _Corrupt as e:
        return ("corrupt", str(e))


def _python_values(data, reps, version, tables):
    from usdhands.formats.usdc_crate import _Crate

    crate = _Crate(data)
    crate.version, crate.tables = version, dict(tables)
    crate.python_values(reps)


def _compiled_values(data, reps, version, tables):
    from usdhands.formats.usdc_crate import _Corrupt

    _CRATE_COMPILED.walk_values(data, reps, tables["token"], tables["string"], tables["path"], version >= (0, 7, 0),
                                version >= (0, 8, 0), _Corrupt)


def _changed_rep(rep: int, rng, size: int) -> int:
    """A value rep with its kind, flags or offset changed: a kind of every sort the walk knows (and others),
    the array / inlined / compressed / edit bits, an offset inside, near the end of or far past the file."""
    choice = int(rng.integers(0, 6))
    if choice == 0:
        kind = int(rng.choice([3, 7, 8, 10, 11, 12, 31, 32, 33, 34, 35, 36, 37, 40, 41, 45, 46, 47, 48, 49, 50, 52,
                               53, 54, 55, 57, 58, 14, 200]))
        return (rep & ~(0xFF << 48)) | (kind << 48)
    if choice == 1:
        return rep ^ (1 << int(rng.choice([60, 61, 62, 63])))
    if choice == 2:
        at = int(rng.choice([0, 1, 8, size - 9, size - 8, size - 1, size, size + 7, (1 << 48) - 1,
                             int(rng.integers(0, max(size, 1)))]))
        return (rep & ~((1 << 48) - 1)) | (at & ((1 << 48) - 1))
    if choice == 3:
        return (rep & ~0xFFFFFFFF) | int(rng.integers(0, 1 << 32))  # an inlined index or a changed offset
    if choice == 4:
        return int(rng.integers(0, 1 << 63, dtype=np.int64)) | (int(rng.integers(0, 2)) << 63)
    return rep


@needs_crate_kernel
def test_compiled_value_walk_equals_the_python_walk(sample_assets, tmp_path):
    """The compiled walk of the values gives the Python walk's outcome, the same message for the same first
    claim that does not fit, on files USD writes, on their value reps changed (kinds, flags, offsets,
    indices), on bytes of their values changed (counts, offsets, jumps, chunk tables), cut short, and
    against tables smaller than the indices they hold."""
    import struct

    from usdhands.formats.usdc_crate import _Crate

    rng = np.random.default_rng(12)
    outcomes: dict[str, int] = {}
    for seed in _walk_seeds(sample_assets, tmp_path):
        crate = _Crate(seed)
        crate.table_of_contents()
        reps = crate.structural()
        version, tables = crate.version, dict(crate.tables)
        assert version >= (0, 8, 0)
        count = len(reps) // 8
        cases = [(seed, reps, version, tables), (seed, reps, (0, 6, 0), tables), (seed, reps, (0, 7, 0), tables)]
        for trial in range(700):
            data, new_reps, new_tables = bytearray(seed), bytearray(reps), dict(tables)
            what = trial % 5
            if what == 0:  # value reps changed
                for _ in range(int(rng.integers(1, 4))):
                    k = int(rng.integers(0, count))
                    old = struct.unpack_from("<Q", new_reps, 8 * k)[0]
                    struct.pack_into("<Q", new_reps, 8 * k, _changed_rep(old, rng, len(seed)) & ((1 << 64) - 1))
            elif what == 1:  # bytes of the values changed: one byte, or an 8-byte count / offset
                for _ in range(int(rng.integers(1, 4))):
                    at = int(rng.integers(88, len(seed) - 8))
                    if rng.random() < 0.5:
                        data[at] = int(rng.integers(0, 256))
                    else:
                        value = int(rng.choice([0, 1, 7, 8, 16, 255, 1 << 20, 1 << 40, (1 << 63) - 1, -1, -(1 << 63),
                                                int(rng.integers(0, len(seed)))]))
                        struct.pack_into("<q", data, at, value)
            elif what == 2:  # cut short
                data = data[:int(rng.integers(0, len(seed)))]
            elif what == 3:  # smaller tables: one, or all three
                for table in (["token", "string", "path"] if rng.random() < 0.4 else
                              [str(rng.choice(["token", "string", "path"]))]):
                    new_tables[table] = int(rng.integers(0, max(tables[table], 1)))
            else:  # a rep copied onto another (a shared value, a different one)
                a, b = (int(x) for x in rng.integers(0, count, 2))
                new_reps[8 * a:8 * a + 8] = new_reps[8 * b:8 * b + 8]
                k = int(rng.integers(0, count))
                old = struct.unpack_from("<Q", new_reps, 8 * k)[0]
                struct.pack_into("<Q", new_reps, 8 * k, _changed_rep(old, rng, len(seed)) & ((1 << 64) - 1))
            cases.append((bytes(data), bytes(new_reps), version, new_tables))
        for data, new_reps, v, t in cases:
            want = _walk_outcome(_python_values, data, new_reps, v, t)
            got = _walk_outcome(_compiled_values, data, new_reps, v, t)
            assert got == want, (want, got)
            outcomes[want[-1] if want[0] == "corrupt" else "ok"] = outcomes.get(want[-1], 0) + 1
    messages = {m.split(" ")[0] + " " + m.split(" ")[1] for m in outcomes if m != "ok"}
    assert outcomes.get("ok", 0) > 300 and len(outcomes) > 200 and len(messages) > 12, (len(outcomes), messages)


@needs_crate_kernel
def test_compiled_spec_walk_equals_the_python_walk(sample_assets, tmp_path):
    """The compiled walk of the path tree and the specs' types gives the Python walk's outcome and message on
    the seeds' tables and on them changed: jumps (loops, past the table, near 2**63), elements (properties
    where prims were), spec types, spec and path indexes; the compiled one declines (False) only where
    path indexes leave the table or a jump could leave 64 bits."""
    from usdhands.formats.usdc_crate import _Corrupt, _Crate

    seen = []

    class Capture(_Crate):
        def spec_types(self, specs, paths):
            seen.append(([a.copy() for a in specs], [a.copy() for a in paths], True))

    for seed in _walk_seeds(sample_assets, tmp_path):
        crate = Capture(seed)
        crate.table_of_contents()
        crate.structural()
    assert len(seen) == 3
    rng = np.random.default_rng(13)
    outcomes: dict[str, int] = {}
    declined = 0
    for n in range(1, 13):  # small random trees: loops, jumps out of the table, properties with targets below
        for trial in range(800):
            p = [rng.permutation(n) if rng.random() < 0.8 else rng.integers(-1, n + 1, n),
                 rng.choice([-2, -1, 1, 2], n),
                 rng.choice([-2, -1, -1, -1, -1, -1, 0, 1, 2, n], n)]
            if rng.random() < 0.8:
                p[2][-1] = -2  # the last entry a leaf: a walk that ends
            if rng.random() < 0.1:
                p[2][int(rng.integers(0, n))] = int(rng.choice([1 << 62, (1 << 63) - 1, -(1 << 63)]))
            m = int(rng.integers(0, 4))
            s = [rng.integers(-1, n + 1, m), np.zeros(m, dtype=np.int64), rng.choice([1, 2, 6, 7, 8, 9, 10, 11, 12], m)]
            seen.append(([a.astype(np.int64) for a in s], [a.astype(np.int64) for a in p], False))
    for specs, paths, change in seen:
        for trial in range(600 if change else 1):
            s, p = [a.copy() for a in specs], [a.copy() for a in paths]
            for _ in range(int(rng.integers(0 if trial < 5 else 1, 3)) if change else 0):
                what = int(rng.integers(0, 5))
                if what == 0:
                    k = int(rng.integers(0, len(p[2])))
                    p[2][k] = int(rng.choice([-2, -1, 0, 1, 2, -k, len(p[2]) - k, len(p[2]) - k - 1, 1 << 40,
                                              (1 << 63) - 1, -(1 << 63), int(rng.integers(-5, len(p[2])))]))
                elif what == 1:
                    k = int(rng.integers(0, len(p[1])))
                    p[1][k] = -p[1][k] - 1
                elif what == 2:
                    k = int(rng.integers(0, len(s[2])))
                    s[2][k] = int(rng.integers(-1, 13))
                elif what == 3:
                    k = int(rng.integers(0, len(s[0])))
                    s[0][k] = int(rng.choice([-1, len(p[0]), int(rng.integers(0, len(p[0])))]))
                else:
                    k = int(rng.integers(0, len(p[0])))
                    p[0][k] = int(rng.choice([-1, len(p[0]), int(rng.integers(0, len(p[0])))]))
            crate = _Crate(b"")
            want = _walk_outcome(crate.python_spec_types, s, p)
            try:
                checked = _CRATE_COMPILED.spec_types(s[0], s[2], p[0], p[1], p[2], _Corrupt)
                got = ("ok",)
            except _Corrupt as e:
                checked, got = True, ("corrupt", str(e))
            if not checked:
                declined += 1
                assert (p[0] < 0).any() or (p[0] >= len(p[0])).any() or (p[2] > (1 << 62)).any()
                continue
            assert got == want, (want, got)
            key = want[1].split(" reaches")[0] if want[0] == "corrupt" else "ok"
            key = key.split(" of type")[0] + (" on a target path" if key.endswith("target path") else "")
            outcomes[key] = outcomes.get(key, 0) + 1
    assert outcomes.get("ok", 0) > 100 and outcomes.get("SPECS: a spec", 0) > 100, outcomes
    assert outcomes.get("PATHS: its jumps table", 0) > 100 and declined < sum(outcomes.values()) // 4, (outcomes, declined)
    assert outcomes.get("SPECS: a spec on a target path", 0) > 20, outcomes


@needs_crate_kernel
@pytest.mark.parametrize("levels, message", [(1, None), (63, None), (64, None), (65, "values nested more than 64 deep"),
                                             (200, "values nested more than 64 deep")])
def test_compiled_value_walk_nesting_and_shared_values(levels, message):
    """Values inside values (a VtValue holding the next): both walks refuse the same depth; a value that holds
    itself, or one reached twice, is walked once (no depth error, no endless walk)."""
    import struct

    tables = {"token": 10, "string": 10, "path": 10}
    data = bytearray(16 + 16 * levels + 16)
    reps = []
    for level in range(levels + 1):  # value k at 16 + 16 k: a jump of 8, then the rep of value k + 1
        reps.append((52 << 48) | (16 + 16 * level))
    for level in range(levels):
        struct.pack_into("<qQ", data, 16 + 16 * level, 8, reps[level + 1])
    struct.pack_into("<qQ", data, 16 + 16 * levels, 8, reps[levels])  # the last holds itself
    top = struct.pack("<QQ", reps[0], reps[0])
    want = ("corrupt", message) if message else ("ok",)
    assert _walk_outcome(_python_values, bytes(data), top, (0, 8, 0), tables) == want
    assert _walk_outcome(_compiled_values, bytes(data), top, (0, 8, 0), tables) == want


def _python_structure(data):
    from usdhands.formats.usdc_crate import _Crate

    crate = _Crate(data)
    crate.table_of_contents()
    captured = []
    crate.spec_types = lambda specs, paths: captured.append((specs, paths))  # the structure alone
    reps = crate.structural()
    specs, paths = captured[0] if captured else (None, None)
    return crate.version, crate.tables["token"], crate.tables["string"], crate.tables["path"], reps, specs, paths


def _structure_outcome(fn, data):
    from usdhands.formats.usdc_crate import _Corrupt

    try:
        version, tokens, strings, paths_n, reps, specs, paths = fn(data)
    except _Corrupt as e:
        return ("corrupt", str(e))
    if specs is None or paths is None:  # the Python methods hand them over only both, to spec_types
        specs = paths = None
    arrays = [None if x is None else [a.tolist() for a in x] for x in (specs, paths)]
    return ("ok", version, tokens, strings, paths_n, reps, *arrays)


@needs_crate_kernel
def test_compiled_structure_equals_the_python_checks(sample_assets, tmp_path):
    """The compiled table of contents and structural sections give the Python methods' outcome: the same
    version, table sizes, value reps, specs and paths, or the same message for the same first claim that
    does not fit; on files USD writes, on bytes of their header, table of contents and section heads
    changed (counts, offsets, sizes, chunk tables, LZ4 bytes), on any byte changed, and cut short."""
    import struct

    from usdhands.formats.usdc_crate import _Corrupt

    def compiled(data):
        return _CRATE_COMPILED.check_structure(data, _Corrupt)

    rng = np.random.default_rng(14)
    outcomes: dict[str, int] = {}
    for seed in _walk_seeds(sample_assets, tmp_path):
        toc = struct.unpack_from("<q", seed, 16)[0]
        n = struct.unpack_from("<Q", seed, toc)[0]
        heads = list(range(8, 24)) + list(range(toc, toc + 8 + 32 * n))
        for k in range(n):
            start, size = struct.unpack_from("<qq", seed, toc + 8 + 32 * k + 16)
            heads += list(range(start, min(start + 48, start + size)))
        cases = [seed, seed[:87], seed[:88], seed[:toc + 8], b""]
        for k in range(n):  # TOKENS claiming 0 to 2 tokens in 0 or 1 bytes
            if seed[toc + 8 + 32 * k:toc + 14 + 32 * k] == b"TOKENS":
                start = struct.unpack_from("<q", seed, toc + 8 + 32 * k + 16)[0]
                for count, raw in ((0, 0), (1, 0), (2, 0), (1, 1), (2, 1)):
                    data = bytearray(seed)
                    struct.pack_into("<QQ", data, start, count, raw)
                    cases.append(bytes(data))
        for trial in range(900):
            data = bytearray(seed)
            what = trial % 4
            for _ in range(int(rng.integers(1, 3))):
                at = int(rng.choice(heads)) if what < 2 else int(rng.integers(0, len(seed)))
                if what == 0 or what == 2:
                    data[at] = int(rng.integers(0, 256))
                elif at + 8 <= len(data):
                    value = int(rng.choice([0, 1, 2, 7, 8, 31, 32, 88, 255, 1 << 20, 1 << 40, (1 << 63) - 1, -1,
                                            -(1 << 63), len(seed) - at, int(rng.integers(0, len(seed)))]))
                    struct.pack_into("<q", data, at, value)
            if what == 3:
                data = data[:int(rng.integers(0, len(seed)))]
            cases.append(bytes(data))
        for data in cases:
            want = _structure_outcome(_python_structure, data)
            got = _structure_outcome(compiled, data)
            assert got == want, (want[:2], got[:2])
            key = "ok" if want[0] == "ok" else " ".join(w for w in want[1].split(" ")[:3] if not w.isdigit())
            outcomes[key] = outcomes.get(key, 0) + 1
    assert outcomes.get("ok", 0) > 300 and len(outcomes) > 15, outcomes

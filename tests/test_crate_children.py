"""The compiled decision of ``usd_common.check_children`` on crate files (``listed_children_have_specs``).

``check_children`` asks whether every child a crate layer's specs list has a spec; its walk through
Sdf (``usd_common._walk_children``) is the reference and gives the errors. The compiled decision
reads the same answer from the crate's bytes where that is simple and says False ("cannot say")
elsewhere: it must never say True where the walk would raise. Held here: every crate file USD
writes in the tests and the assets is decided True (so the walk is skipped on them); the lies the
hostile corpus builds, a listed prim or property without a spec and variant sets are False, with the
walk's own errors; and a fuzz of real crates (bytes changed in the structural sections and in the
token vectors, cut short, sections rewritten with indices, elements, jumps, types and field sets
changed) where, whenever the decision says True, the walk passes (run in a subprocess: USD may abort).
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hostile import _encode_ints, _lz4_literals, crate_lies, crate_seed  # noqa: E402  (tests/ is on sys.path)
from test_usdc_crate import rich_layer  # noqa: E402
from usdhands.errors import AssetReadError
from usdhands.formats import usd_common, usdc_crate
from usdhands.formats.usdc_crate import _Crate, _walk_local_headers, check_crate_bytes, check_crate_file

ROOT = Path(__file__).resolve().parent.parent

needs_decision = pytest.mark.skipif(usdc_crate._listed_children is None,
                                    reason="formats._crate_compiled was not built (or USDHANDS_COMPILED_KERNELS=0)")


def decision(data: bytes) -> bool | None:
    """The compiled decision on crate bytes; None where the byte check refuses them."""
    try:
        return check_crate_bytes(data, children=True)
    except AssetReadError:
        return None


def reference(layer_path: Path) -> str:
    """The Sdf walk on a crate file: 'ok', 'none' (USD did not open it) or the error's message."""
    from pxr import Sdf

    from usdhands.formats.usd_common import quiet_diagnostics

    with quiet_diagnostics():
        try:
            layer = Sdf.Layer.FindOrOpen(str(layer_path))
        except Exception:  # Tf.ErrorException: USD refused the file
            return "none"
        if layer is None:
            return "none"
        try:
            usd_common._walk_children(layer, layer_path)
        except AssetReadError as e:
            return str(e)
        except Exception as e:  # what the walk lets through (it is not the error promise's business here)
            return f"{type(e).__name__}: {e}"
    return "ok"


def rich_without_variants(path: Path) -> None:
    """:func:`rich_layer` (every kind of value the check walks) without its variant set."""
    from pxr import Sdf

    rich_layer(path)
    layer = Sdf.Layer.FindOrOpen(str(path))
    spec = layer.GetPrimAtPath("/Root")
    spec.variantSetNameList.ClearEdits()
    del spec.variantSets["look"]
    del spec.variantSelections["look"]
    layer.Save()


def package_root(data: bytes) -> bytes:
    """The crate bytes of a package's first member."""
    members = {}
    _walk_local_headers(data, members)
    start, size = min(members)
    return data[start:start + size]


def crate_files(sample_assets: Path, shared_assets: Path | None, tmp_path: Path) -> dict[str, bytes]:
    """Crate files USD wrote: the rich layer without variants, the humanoid seed, the sample and shared assets."""
    rich = tmp_path / "rich_plain.usdc"
    rich_without_variants(rich)
    files = {"rich": rich.read_bytes(), "seed": crate_seed(sample_assets, tmp_path)}
    folders = [sample_assets] + ([shared_assets] if shared_assets is not None else [])
    for folder in folders:
        for path in sorted(folder.rglob("*.usd[cz]")):
            data = path.read_bytes()
            files[str(path)] = package_root(data) if path.suffix == ".usdz" else data
    return files


# -- files USD writes ------------------------------------------------------------------------------

@needs_decision
def test_every_crate_usd_writes_is_decided_true_and_the_walk_passes(sample_assets, shared_assets, tmp_path):
    files = crate_files(sample_assets, shared_assets, tmp_path)
    assert any(name.endswith("CesiumMan.usdz") for name in files)
    assert any(name.endswith("conversation_bodyonly.usdc") for name in files)
    for name, data in files.items():
        assert decision(data) is True, name
        path = tmp_path / "one.usdc"
        path.write_bytes(data)
        assert reference(path) == "ok", name
        path.unlink()
    for path in [*sample_assets.rglob("*.usd[cz]"), *shared_assets.rglob("*.usd[cz]")]:
        assert check_crate_file(path) == (True, True), path


@needs_decision
def test_variant_sets_are_left_to_the_walk(tmp_path):
    """The rich layer with its variant set: False (variant fields are not decided), and it reads as before."""
    from usdhands.formats.usd_common import open_stage

    rich = tmp_path / "rich.usdc"
    rich_layer(rich)
    assert decision(rich.read_bytes()) is False
    assert check_crate_file(rich) == (True, False)
    assert reference(rich) == "ok"
    walks = []
    real = usd_common._walk_children
    with pytest.MonkeyPatch.context() as m:
        m.setattr(usd_common, "_walk_children", lambda *a: walks.append(a) or real(*a))
        stage = open_stage(rich)
    assert stage.GetPrimAtPath("/Root").GetVariantSets().GetNames() == ["look"] and len(walks) == 1


# -- the lies: False, and the walk's own message ---------------------------------------------------

def _tokens(data: bytes) -> list[bytes]:
    crate = _Crate(data)
    crate.table_of_contents()
    start, end = crate.sections["TOKENS"]
    raw, packed = struct.unpack_from("<QQ", data, start + 8)
    return crate.decompress(start + 24, packed, raw, "TOKENS", end).split(b"\0")[:-1]


def _token_vectors(data: bytes) -> list[tuple[str, int]]:
    """(field name, payload offset) of each token vector stored out of line in FIELDS."""
    crate = _Crate(data)
    crate.table_of_contents()
    reps = np.frombuffer(crate.structural(), dtype="<u8").tolist()
    start, end = crate.sections["FIELDS"]
    names, _ = crate.ints(start + 8, len(reps), "FIELDS", end)
    tokens = _tokens(data)
    return [(tokens[t].decode(), r & ((1 << 48) - 1)) for t, r in zip(names.tolist(), reps)
            if (r >> 48) & 0xFF == 41 and not r >> 60]


@needs_decision
def test_a_listed_prim_without_a_spec_is_false_and_refused_by_the_walk(sample_assets, tmp_path):
    from usdhands.formats.usd_common import open_stage

    data, message = crate_lies(crate_seed(sample_assets, tmp_path))["child_without_spec"]
    assert decision(data) is False
    bad = tmp_path / "child.usdc"
    bad.write_bytes(data)
    assert check_crate_file(bad) == (True, False)
    with pytest.raises(AssetReadError) as e:
        open_stage(bad)
    assert str(e.value) == f"{bad}: cannot read as USD: {message}"


def _assert_inspect_refuses(bad: Path, data: bytes, reason: str) -> None:
    """``data`` written to ``bad`` and inspected in a process of its own (an abort would end this one):
    exit status 2 and one line, ``cannot read as USD: <reason>``."""
    from hostile import run_batch

    bad.write_bytes(data)
    [result] = run_batch([["inspect", bad]])
    assert result["code"] == 2, result
    assert result["stderr"].splitlines() == [f"usdhands: error: {bad}: cannot read as USD: {reason}"]


def test_a_crate_without_its_pseudo_roots_spec_is_refused_in_one_line(sample_assets, tmp_path):
    """The humanoid's crate with the pseudo-root's spec dropped from SPECS (the fuzz found it): the walk
    raised AttributeError on the missing spec ('NoneType' has no 'HasInfo'), and without the walk USD
    aborted the interpreter reading the stage's metadata ('Dereferenced an invalid SdfPrimSpec'). Now
    one line, exit status 2, in a process of its own (an abort would end this one)."""
    seed = crate_seed(sample_assets, tmp_path)
    paths, sets, types = (list(a) for a in _decoded(seed)["SPECS"])
    k = types.index(7)
    for a in (paths, sets, types):
        del a[k]
    data = _with_specs(seed, paths, sets, types)
    assert decision(data) in (False, None)
    _assert_inspect_refuses(tmp_path / "rootless.usdc", data, "the layer has no spec for its pseudo-root")


def test_a_field_named_past_the_token_table_is_refused_in_one_line(sample_assets, tmp_path):
    """A field whose name is a token index past the table (the children decision's fuzz): USD's crate
    reader refuses the file ('Corrupt asset @path@'), which reads as one line naming the file once."""
    seed = crate_seed(sample_assets, tmp_path)
    d = _decoded(seed)
    fields = list(d["fields"])
    fields[3] = len(d["tokens"]) + 1000
    _assert_inspect_refuses(tmp_path / "field_name.usdc", _with_fields(seed, fields),
                            "corrupt crate file (USD's reader refused its contents)")


@needs_decision
def test_a_listed_property_without_a_spec_is_false_and_refused_by_the_walk(sample_assets, tmp_path):
    from pxr import Sdf

    from usdhands.formats.usd_common import open_stage

    good = crate_seed(sample_assets, tmp_path)
    tokens = _tokens(good)
    at = next(at for name, at in _token_vectors(good) if name == "properties")
    listed = [tokens[t].decode() for t in struct.unpack_from(f"<{struct.unpack_from('<Q', good, at)[0]}I", good, at + 8)]
    seed_path = tmp_path / "seed.usdc"
    seed_path.write_bytes(good)
    layer = Sdf.Layer.FindOrOpen(str(seed_path))
    owner = next(spec.path for spec in _prim_specs(layer) if list(spec.properties.keys()) == listed)
    del layer
    data = bytearray(good)
    struct.pack_into("<I", data, at + 8, tokens.index(b"primChildren"))  # a plain name no property has
    data = bytes(data)
    assert decision(data) is False
    bad = tmp_path / "property.usdc"
    bad.write_bytes(data)
    with pytest.raises(AssetReadError) as e:
        open_stage(bad)
    assert str(e.value) == (f"{bad}: cannot read as USD: properties of <{owner}> lists <{owner}.primChildren>, "
                            "which has no spec")


def _prim_specs(layer):
    todo = [layer.pseudoRoot]
    while todo:
        spec = todo.pop()
        yield spec
        todo.extend(spec.nameChildren)


@needs_decision
def test_each_hostile_lie_is_false_or_refused_by_the_check(sample_assets, tmp_path):
    for name, (data, _) in crate_lies(crate_seed(sample_assets, tmp_path)).items():
        assert decision(data) in (None, False), name


# -- the decision is used ------------------------------------------------------------------------

@needs_decision
def test_cesiumman_is_read_without_the_walk(shared_assets, monkeypatch):
    """Fails where the decision is wired but never used: CesiumMan.usdz's read walks nothing (and walks
    once where the decision is made to say False)."""
    from usdhands.formats.usd_common import open_stage

    walks = []
    real = usd_common._walk_children
    monkeypatch.setattr(usd_common, "_walk_children", lambda *a: walks.append(a) or real(*a))
    path = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    assert open_stage(path).GetPrimAtPath("/CesiumMan")
    assert walks == []
    monkeypatch.setattr(usdc_crate, "_listed_children", lambda *a: False)
    assert open_stage(path).GetPrimAtPath("/CesiumMan")
    assert len(walks) == 1


def test_without_the_compiled_module_every_crate_is_walked(shared_assets):
    """USDHANDS_COMPILED_KERNELS=0: no decision (the walk runs, as before it)."""
    code = ("import sys; from usdhands.formats import usdc_crate, usd_common\n"
            "walks = []; real = usd_common._walk_children\n"
            "usd_common._walk_children = lambda *a: walks.append(1) or real(*a)\n"
            "usd_common.open_stage(sys.argv[1])\n"
            "print(usdc_crate._listed_children is None, tuple(usdc_crate.check_crate_file(sys.argv[1])), len(walks))\n")
    path = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    env = dict(os.environ, USDHANDS_COMPILED_KERNELS="0", PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code, str(path)], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "(True,", "False)", "1"]


# -- the fuzz ------------------------------------------------------------------------------------

def _sections(data: bytes) -> dict[str, tuple[int, int, int]]:
    """name -> (entry of the table of contents, start, end)."""
    toc = struct.unpack_from("<q", data, 16)[0]
    out = {}
    for k in range(struct.unpack_from("<Q", data, toc)[0]):
        at = toc + 8 + 32 * k
        start, size = struct.unpack_from("<qq", data, at + 16)
        out.setdefault(data[at:at + 16].split(b"\0")[0].decode("latin-1"), (at, start, start + size))
    return out


def _decoded(data: bytes) -> dict:
    """The structural sections' integers: FIELDS' tokens, FIELDSETS, SPECS' and PATHS' arrays; the tokens."""
    crate = _Crate(data)
    crate.table_of_contents()
    out = {"tokens": _tokens(data)}
    start, end = crate.sections["FIELDS"]
    n = struct.unpack_from("<Q", data, start)[0]
    out["fields"] = crate.ints(start + 8, n, "FIELDS", end)[0].tolist()
    start, end = crate.sections["FIELDSETS"]
    n = struct.unpack_from("<Q", data, start)[0]
    out["fieldsets"] = [v & 0xFFFFFFFF for v in crate.ints(start + 8, n, "FIELDSETS", end)[0].tolist()]
    for name, at in (("SPECS", 8), ("PATHS", 16)):
        start, end = crate.sections[name]
        n = struct.unpack_from("<Q", data, start + at - 8)[0]
        arrays, pos = [], start + at
        for _ in range(3):
            values, pos = crate.ints(pos, n, name, end)
            arrays.append(values.tolist())
        out[name] = arrays
    out["paths_n"] = struct.unpack_from("<Q", data, crate.sections["PATHS"][0])[0]
    return out


def _rewritten(data: bytes, name: str, section: bytes) -> bytes:
    """``data`` with section ``name`` replaced by ``section`` (appended; the table of contents points at it)."""
    entry = _sections(data)[name][0]
    out = bytearray(data)
    struct.pack_into("<qq", out, entry + 16, len(data), len(section))
    return bytes(out) + section


def _with_specs(seed: bytes, paths: list, sets: list, types: list) -> bytes:
    """``seed`` with SPECS rewritten: the specs' path indexes, field sets and types."""
    return _rewritten(seed, "SPECS", struct.pack("<Q", len(paths)) + b"".join(_encode_ints(a) for a in (paths, sets, types)))


def _with_fields(seed: bytes, fields: list) -> bytes:
    """``seed`` with FIELDS' names (token indices) rewritten, its value reps as they were."""
    start, end = _sections(seed)["FIELDS"][1:]
    packed = struct.unpack_from("<Q", seed, start + 8)[0]
    return _rewritten(seed, "FIELDS", struct.pack("<Q", len(fields)) + _encode_ints(fields) + seed[start + 16 + packed:end])


def _mutants(seed: bytes, rng: np.random.Generator, count: int) -> list[bytes]:
    d = _decoded(seed)
    sections = _sections(seed)
    structural = [(s, e) for name, (_, s, e) in sections.items()]
    vectors = [at for _, at in _token_vectors(seed)]
    n_tokens = len(d["tokens"])
    out = []
    for trial in range(count):
        what = trial % 9
        data = bytearray(seed)
        if what == 0:  # bytes of the structural sections changed
            for _ in range(int(rng.integers(1, 3))):
                s, e = structural[int(rng.integers(len(structural)))]
                data[int(rng.integers(s, e))] = int(rng.integers(256))
        elif what == 1:  # a token vector's count or entries changed
            at = vectors[int(rng.integers(len(vectors)))]
            n = struct.unpack_from("<Q", seed, at)[0]
            at += int(rng.integers(0, 8 + 4 * n))
            data[at] = int(rng.integers(256))
        elif what == 2:  # a token vector's entry made another token (or two entries swapped)
            at = vectors[int(rng.integers(len(vectors)))]
            n = struct.unpack_from("<Q", seed, at)[0]
            if n == 0:
                continue
            k = int(rng.integers(n))
            if n > 1 and rng.random() < 0.3:
                j = int(rng.integers(n))
                a, b = struct.unpack_from("<II", seed, at + 8 + 4 * k)[0], struct.unpack_from("<I", seed, at + 8 + 4 * j)[0]
                struct.pack_into("<I", data, at + 8 + 4 * k, b)
                struct.pack_into("<I", data, at + 8 + 4 * j, a)
            elif rng.random() < 0.5:  # the name of another entry of the path tree (elsewhere, or of another kind)
                struct.pack_into("<I", data, at + 8 + 4 * k, abs(int(rng.choice(d["PATHS"][1]))))
            else:
                struct.pack_into("<I", data, at + 8 + 4 * k, int(rng.integers(n_tokens + 2)))
        elif what == 3:  # cut short
            data = data[:int(rng.integers(len(seed) // 2, len(seed)))]
        elif what == 4:  # SPECS: a spec dropped, moved to another path, retyped or given another field set
            paths, sets, types = (list(a) for a in d["SPECS"])
            k = int(rng.integers(len(paths)))
            change = int(rng.integers(4))
            if change == 0:
                for a in (paths, sets, types):
                    del a[k]
            elif change == 1:
                paths[k] = int(rng.choice(d["PATHS"][0])) if rng.random() < 0.8 else int(rng.integers(d["paths_n"] + 2))
            elif change == 2:
                types[k] = int(rng.integers(0, 12))
            else:
                sets[k] = int(rng.choice(sets))
            data = bytearray(_with_specs(seed, paths, sets, types))
        elif what == 5:  # PATHS: an element, a jump or a path index changed
            indexes, elements, jumps = (list(a) for a in d["PATHS"])
            k = int(rng.integers(len(indexes)))
            change = int(rng.integers(3))
            if change == 0:
                elements[k] = int(rng.choice([-1, 1])) * int(rng.integers(n_tokens)) if rng.random() < 0.7 \
                    else int(rng.choice(elements))
            elif change == 1:
                jumps[k] = int(rng.choice([-2, -1, 0, 1, 2, int(rng.integers(-3, len(jumps)))]))
            else:
                indexes[k] = int(rng.choice(indexes)) if rng.random() < 0.7 else int(rng.integers(d["paths_n"]))
            section = struct.pack("<QQ", d["paths_n"], len(indexes)) + b"".join(
                _encode_ints(a) for a in (indexes, elements, jumps))
            data = bytearray(_rewritten(seed, "PATHS", section))
        elif what == 6:  # FIELDSETS: a field replaced by another, dropped, or a run's end moved
            sets = list(d["fieldsets"])
            k = int(rng.integers(len(sets)))
            change = int(rng.integers(3))
            if change == 0 and sets[k] != 0xFFFFFFFF:
                sets[k] = int(rng.integers(len(d["fields"]) + 1))
            elif change == 1 and len(sets) > 1:
                del sets[k]
            else:
                sets[k] = 0xFFFFFFFF
            section = struct.pack("<Q", len(sets)) + _encode_ints(sets)
            data = bytearray(_rewritten(seed, "FIELDSETS", section))
        elif what == 7:  # FIELDS: a field's name made another token (its value kept)
            fields = list(d["fields"])
            fields[int(rng.integers(len(fields)))] = int(rng.integers(n_tokens))
            data = bytearray(_with_fields(seed, fields))
        else:  # TOKENS: a name renamed (to a plain, a namespaced, an odd or a duplicate name)
            tokens = list(d["tokens"])
            k = int(rng.integers(1, n_tokens))
            tokens[k] = [b"zz", b"a:b", b"a b", b"", b"9x", tokens[int(rng.integers(n_tokens))]][int(rng.integers(6))]
            text = b"\0".join(tokens) + b"\0"
            body = _lz4_literals(text)
            section = struct.pack("<QQQ", len(tokens), len(text), len(body)) + body
            data = bytearray(_rewritten(seed, "TOKENS", section))
        out.append(bytes(data))
    return out


_REFERENCE_RUNNER = """
import sys
sys.path.insert(0, sys.argv[1])
from pathlib import Path
from test_crate_children import reference
for line in sys.stdin:
    print(reference(Path(line.strip())).replace("\\n", " "), flush=True)
"""


def _references(paths: list[Path]) -> list[str]:
    """The walk on each file in a subprocess (restarted past a file that makes USD abort: 'crash')."""
    results: list[str] = []
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    while len(results) < len(paths):
        todo = paths[len(results):]
        proc = subprocess.run([sys.executable, "-c", _REFERENCE_RUNNER, str(ROOT / "tests")], env=env,
                              input="".join(f"{p}\n" for p in todo), capture_output=True, text=True)
        lines = proc.stdout.splitlines()
        results.extend(lines[:len(todo)])
        if len(lines) < len(todo):
            results.append("crash")
    return results


@needs_decision
def test_fuzz_whenever_the_decision_says_true_the_walk_passes(sample_assets, shared_assets, tmp_path):
    rng = np.random.default_rng(2026)
    rich = tmp_path / "rich_plain.usdc"
    rich_without_variants(rich)
    cesium = package_root((shared_assets / "usd_cesiumman" / "CesiumMan.usdz").read_bytes())
    gesture = (sample_assets / "gestures_bodyonly" / "ok_00_bodyonly.usdc").read_bytes()
    seeds = [crate_seed(sample_assets, tmp_path), rich.read_bytes(), cesium, gesture]
    cases, decided = [], []
    for s, seed in enumerate(seeds):
        for k, data in enumerate(_mutants(seed, rng, 900)):
            verdict = decision(data)
            if verdict is None:
                continue  # refused by the byte check: USD never opens it
            path = tmp_path / f"m{s}_{k}.usdc"
            path.write_bytes(data)
            cases.append(path)
            decided.append(verdict)
    results = _references(cases)
    unsound = [(p.name, r) for p, d, r in zip(cases, decided, results) if d and r not in ("ok", "none")]
    assert unsound == []
    assert sum(decided) > 100 and decided.count(False) > 100, (sum(decided), decided.count(False))
    raised = [r for r in results if r not in ("ok", "none", "crash")]
    assert len(raised) > 20, len(raised)  # the fuzz makes the walk raise: it has teeth

"""The fast decoding of a glTF document (formats.gltf_decode) against pygltflib's own
(``GLTF2.from_dict(data, infer_missing=True)``, dataclasses_json): the same objects, field for field
and type for type, on every real glTF file here and on thousands of mutated documents; where the
fast path declines (NotPlain), the reader falls back to pygltflib and reads or refuses as before."""

from __future__ import annotations

import copy
import dataclasses
import json
import struct
import warnings
from pathlib import Path

import numpy as np
import pygltflib
import pytest

from usdhands.formats.gltf_decode import NotPlain, decode_gltf

ROOT = Path(__file__).resolve().parent.parent
FILES = sorted(p for d in (ROOT / "sample_assets", ROOT.parent / "shared" / "assets") if d.is_dir()
               for p in d.rglob("*") if p.suffix.lower() in (".glb", ".gltf"))


def _json(path: Path):
    data = path.read_bytes()
    if data[:4] == b"glTF":
        (length,) = struct.unpack("<I", data[12:16])
        return json.loads(data[20:20 + length])
    return json.loads(data)


def _pygltflib(data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return pygltflib.GLTF2.from_dict(copy.deepcopy(data), infer_missing=True)


def difference(a, b, path="gltf") -> str | None:
    """Where ``a`` and ``b`` differ in type or value (None if nowhere): dataclasses, Attributes,
    dicts (their key order too) and lists walked; everything else by type and ``==``."""
    if type(a) is not type(b):
        return f"{path}: {type(a).__name__} against {type(b).__name__}"
    if dataclasses.is_dataclass(a):
        return next((d for f in dataclasses.fields(a)
                     if (d := difference(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}"))), None)
    if isinstance(a, pygltflib.Attributes):
        return difference(vars(a), vars(b), path)
    if isinstance(a, dict):
        if list(a) != list(b):
            return f"{path}: keys {list(a)} against {list(b)}"
        return next((d for k in a if (d := difference(a[k], b[k], f"{path}[{k!r}]"))), None)
    if isinstance(a, list):
        if len(a) != len(b):
            return f"{path}: {len(a)} items against {len(b)}"
        return next((d for i, (x, y) in enumerate(zip(a, b)) if (d := difference(x, y, f"{path}[{i}]"))), None)
    return None if a == b else f"{path}: {a!r} against {b!r}"


def test_difference_sees_a_type_and_a_value():
    assert difference([1.0, {"a": 2}], [1.0, {"a": 2}]) is None
    assert "float against int" in difference([1.0], [1])  # 1 == 1.0: equality alone would pass it
    assert difference({"a": 1, "b": 2}, {"b": 2, "a": 1}) is not None
    assert difference(pygltflib.Node(name="a"), pygltflib.Node(name="b")) is not None


@pytest.mark.skipif(len(FILES) < 10, reason="the glTF files of sample_assets and ../shared/assets")
@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_real_files_decode_as_pygltflib_decodes_them(path):
    data = _json(path)
    got = decode_gltf(copy.deepcopy(data))
    assert difference(_pygltflib(data), got) is None


def _mutations(data, rng, n):
    """``n`` documents, each ``data`` with one value somewhere replaced by a value of another shape or
    type (a number, a string, a bool, None, a list, an object), a key removed, or an unknown key added."""
    paths = []

    def walk(node, path):
        if isinstance(node, dict):
            for k, v in node.items():
                paths.append(path + (k,))
                walk(v, path + (k,))
        elif isinstance(node, list):
            for i, v in enumerate(node[:4]):
                paths.append(path + (i,))
                walk(v, path + (i,))

    walk(data, ())
    values = [0, 1, 2.5, -1, True, False, None, "x", "1.5", [], [1, 2], [{"a": 1}], {}, {"uri": "a"}, [None], 10**30]
    for _ in range(n):
        doc = copy.deepcopy(data)
        path = paths[rng.integers(len(paths))]
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        op = rng.integers(4)
        if op == 0 and isinstance(parent, dict):
            del parent[path[-1]]
        elif op == 1 and isinstance(parent, dict):
            parent["unknownKey"] = values[rng.integers(len(values))]
        else:
            parent[path[-1]] = copy.deepcopy(values[rng.integers(len(values))])
        yield doc


@pytest.mark.parametrize("name", ["conversation_bodyonly.glb", "interaction/cup_grasp.glb"])
def test_mutated_documents_decode_as_pygltflib_or_go_to_it(name):
    data = _json(ROOT / "sample_assets" / name)
    data = {k: v[:6] if isinstance(v, list) else v for k, v in data.items()}  # every kind of object, fewer of each
    for anim in data.get("animations", []):
        anim["channels"], anim["samplers"] = anim["channels"][:4], anim["samplers"][:4]
    rng = np.random.default_rng(11)
    decoded = declined = 0
    for doc in _mutations(data, rng, 800):
        try:
            want = _pygltflib(doc)
        except Exception:  # noqa: BLE001 - pygltflib refuses it: the fast path must not accept it
            want = None
        try:
            got = decode_gltf(copy.deepcopy(doc))
        except NotPlain:
            declined += 1
            continue
        assert want is not None, "decoded a document pygltflib refuses"
        assert difference(want, got) is None
        decoded += 1
    assert decoded > 350 and declined > 100, (decoded, declined)  # both paths seen


def test_a_document_of_another_shape_is_declined():
    for data in ([], {"nodes": {}}, {"nodes": [[]]}, {"asset": []}, {"accessors": [None]},
                 {"accessors": [{"min": 3}]}, {"extras": []}, {"accessors": [{"count": "x"}]}):
        with pytest.raises(NotPlain):
            decode_gltf(data)


def test_a_pygltflib_class_with_a_field_type_unknown_here_goes_to_pygltflib(monkeypatch):
    """A newer pygltflib with a field of a type the plans do not know: its documents are decoded by
    pygltflib's own from_dict, not refused."""
    from usdhands.formats import gltf_decode
    from usdhands.formats.gltf_container import clear_decoded_cache, load_gltf

    @dataclasses.dataclass
    class Odd:
        value: "complex" = 0j

    monkeypatch.setattr(gltf_decode, "_plans", {})
    with pytest.raises(NotPlain):
        gltf_decode._plan(Odd)
    assert gltf_decode._plans[Odd] is None
    path = ROOT / "sample_assets" / "interaction" / "cup_grasp.glb"
    clear_decoded_cache()
    want = load_gltf(path).gltf
    monkeypatch.setattr(gltf_decode, "_plans", {pygltflib.Node: None})  # as if Node had such a field
    clear_decoded_cache()
    with pytest.raises(NotPlain):
        decode_gltf(_json(path))
    got = load_gltf(path).gltf  # read all the same, through dataclasses_json
    assert difference(want, got) is None

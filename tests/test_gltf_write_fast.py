"""The glTF writer's fast paths give the bytes of the straightforward ones: its JSON text is pygltflib's
``gltf_to_json`` text (gltf_container._to_json), its rotation channels those of flipping frame by frame
and rounding (gltf_write._rotation_channels, _float32_channels)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib
import pytest

from usdhands.formats import gltf_container, gltf_write
from usdhands.formats.gltf_container import _to_json
from usdhands.formats.io import read_asset, write_asset

ROOT = Path(__file__).resolve().parent.parent


def _pygltflib_text(doc: pygltflib.GLTF2) -> str:
    return doc.gltf_to_json(separators=(",", ":"), indent=None)


def _gltf_files() -> list[Path]:
    shared = ROOT.parent / "shared" / "assets"
    found = sorted(shared.rglob("*.glb")) + sorted(shared.rglob("*.gltf")) if shared.is_dir() else []
    return found + sorted((ROOT / "sample_assets").rglob("*.glb"))


@pytest.mark.parametrize("path", _gltf_files(), ids=lambda p: p.name)
def test_loaded_documents_give_pygltflib_text(path):
    doc = pygltflib.GLTF2().load(str(path))
    assert _to_json(doc) == _pygltflib_text(doc)


def test_written_documents_give_pygltflib_text(sample_assets, tmp_path, monkeypatch):
    """Every document the writer makes (skins, meshes, materials, morph targets, extras, clips) as it is saved."""
    texts = []
    real = gltf_container._to_json

    def both(doc):
        texts.append((real(doc), _pygltflib_text(doc)))
        return texts[-1][0]

    monkeypatch.setattr(gltf_container, "_to_json", both)
    sources = [sample_assets / "humanoid.usda", sample_assets / "conversation.glb", sample_assets / "humanoid.bvh"]
    shared = ROOT.parent / "shared" / "assets"
    sources += [p for p in (shared / "robot_expressive" / "RobotExpressive.glb",
                            shared / "usd_cesiumman" / "CesiumMan.usdz") if p.exists()]
    for k, src in enumerate(sources):
        asset = read_asset(src)
        for ext in (".glb", ".gltf"):
            write_asset(asset, tmp_path / f"out{k}{ext}")
    assert len(texts) == 2 * len(sources)
    for ours, theirs in texts:
        assert ours == theirs


def test_odd_values_give_pygltflib_text():
    """Empty and None values at every depth (removed or kept as pygltflib removes or keeps them),
    extensions, custom attributes, tuples, numpy numbers, non-ASCII names."""
    doc = pygltflib.GLTF2(asset=pygltflib.Asset(generator="", version="2.0"))
    doc.extras = {"a": None, "b": [], "c": {"d": None, "e": {}}, "f": [{"g": None}, [{"h": None}], None],
                  "i": "", "j": (1, 2), "k": np.float64(0.5)}
    doc.extensions = {"X_ext": {"y": None, "z": []}, "Empty": {}}
    doc.extensionsUsed = []
    doc.nodes = [pygltflib.Node(name="Ünïcode ✓", translation=[0.0, -0.0, 1e-300], rotation=None, scale=[],
                                extras={}, children=[1]), pygltflib.Node(name=None, mesh=0)]
    attrs = pygltflib.Attributes(POSITION=0, NORMAL=None)
    attrs.TEXCOORD_2 = 5
    doc.meshes = [pygltflib.Mesh(primitives=[pygltflib.Primitive(attributes=attrs, targets=[{"POSITION": 1}])],
                                 weights=[0.25], extras={"targetNames": ["smile"]})]
    doc.accessors = [pygltflib.Accessor(bufferView=0, componentType=5126, count=3, type="VEC3", min=[0, 0, 0],
                                        max=[1.5, 2, 3]),
                     pygltflib.Accessor(componentType=5126, count=3, type="VEC3",
                                        sparse=pygltflib.Sparse(count=1, indices=pygltflib.AccessorSparseIndices(
                                            bufferView=0, componentType=5123),
                                            values=pygltflib.AccessorSparseValues(bufferView=0)))]
    assert _to_json(doc) == _pygltflib_text(doc)
    assert doc.extras["a"] is None and doc.extras["c"] == {"d": None, "e": {}}  # the document is not changed


@pytest.mark.parametrize("value, error", [(float("nan"), ValueError), (np.float32(0.5), TypeError)])
def test_refused_like_pygltflib(value, error):
    doc = pygltflib.GLTF2(nodes=[pygltflib.Node(translation=[value, 0.0, 0.0])])
    with pytest.raises(error):
        _pygltflib_text(doc)
    with pytest.raises(error):
        _to_json(doc)


def _flipped_frame_by_frame(q: np.ndarray) -> np.ndarray:
    """(J, T, 4) float32: unit quaternions (normalised where some is not within 1e-6 of unit length and none
    is NaN), rounded to float32, and multiplied by -1 where an odd number of the dot products of neighbours
    up to them (summed left to right) are below 0: a neighbour at right angles (0) keeps the sign of the
    frame before. (A NaN multiplied by -1 keeps its sign bit on x86, unlike a negation.)"""
    q = np.array(q, dtype=np.float64)
    square = np.einsum("...i,...i->...", q, q)
    if np.abs(square - 1.0).max(initial=0.0) > 1e-6:
        norms = np.linalg.norm(q, axis=-1, keepdims=True)
        if np.abs(norms - 1.0).max(initial=0.0) > 1e-6:
            q = q / norms
    out = q.astype(np.float32)
    for j in range(q.shape[1]):
        odd = False
        for t in range(1, q.shape[0]):
            a, b = q[t, j], q[t - 1, j]
            odd ^= bool(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] < 0)
            if odd:
                out[t, j] *= np.float32(-1.0)
    return np.ascontiguousarray(out.transpose(1, 0, 2))


def _rotations(T: int, J: int, seed: int) -> np.ndarray:
    """Random unit quaternions, with neighbours at right angles (dot products 0 and within 1e-16 of it)."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(T, J, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    for t in range(1, T, 5):
        a = q[t - 1, 0]
        b = np.array([-a[1], a[0], -a[3], a[2]])  # at right angles to a: the dot product is 0 or about 1e-17
        q[t, 0] = b + rng.choice([-1e-16, 0.0, 1e-16]) * a
    return q


@pytest.mark.parametrize("T, J", [(2, 1), (3, 2), (17, 3), (40, 5), (101, 7)])
@pytest.mark.parametrize("case", ["unit", "scaled", "nan", "nan_and_scaled", "huge"])
def test_rotation_channels_equal_flipping_frame_by_frame(T, J, case, monkeypatch):
    monkeypatch.setattr(gltf_write, "_BLOCK_BYTES", 32 * J * 16)  # blocks of 16 frames: several per clip
    q = _rotations(T, J, seed=T * 31 + J)
    if case in ("scaled", "nan_and_scaled"):
        q[T // 2] *= 3.0
    if case in ("nan", "nan_and_scaled"):
        q[T - 1, J - 1] = np.nan
    if case == "huge":
        q *= 1e38
    want = _flipped_frame_by_frame(q)
    got = gltf_write._rotation_channels(q)
    assert got.shape == want.shape and got.flags.c_contiguous
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    q2, flips = gltf_write._continuous_flips(q)  # the whole-array functions give the same bytes
    assert np.array_equal(gltf_write._float32_channels(q2, flips).view(np.uint32), want.view(np.uint32))
    if case == "unit" and T >= 40:  # random neighbours point apart about half the time: flips were made
        assert flips is not None and flips.any()


@pytest.mark.parametrize("C", [3, 4])
def test_float32_channels_equal_rounding_then_transposing(C):
    rng = np.random.default_rng(C)
    values = rng.normal(size=(23, 6, C)) * 10.0 ** rng.integers(-30, 30, size=(23, 6, C))  # within float32
    values[3, 2, 0] = -0.0
    flips = rng.random((23, 6)) < 0.5
    want = values.astype(np.float32)
    want[flips] *= np.float32(-1.0)
    got = gltf_write._float32_channels(values, flips)
    assert np.array_equal(got.view(np.uint32), np.ascontiguousarray(want.transpose(1, 0, 2)).view(np.uint32))
    plain = gltf_write._float32_channels(values[:, ::2])  # a strided view: rounded into a new array first
    assert np.array_equal(plain, values[:, ::2].astype(np.float32).transpose(1, 0, 2))
    assert gltf_write._float32_channels(values[:0]).shape == (6, 0, C)

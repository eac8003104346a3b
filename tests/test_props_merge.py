"""The vertex merge of every prop (formats.props._clean) against trimesh's ``merge_vertices`` to the bit:
the same vertices in the same order, the same faces, on the real props and on built meshes with
duplicates, near-duplicates either side of the rounding, unused vertices and float32 input."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from usdhands.formats.props import _clean

ROOT = Path(__file__).resolve().parent.parent
ASSETS = ROOT.parent / "shared" / "assets"


def _trimesh_clean(vertices, faces):
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    area2 = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    size = float(np.ptp(v, axis=0).max()) if len(v) else 0.0
    return v, f[area2 > 1e-12 * size * size]


def _assert_same(vertices, faces):
    got, want = _clean(vertices, faces), _trimesh_clean(vertices, faces)
    for g, w in zip(got, want):
        assert g.dtype == w.dtype and g.shape == w.shape
        assert g.tobytes() == w.tobytes()
    return got


def _split_mesh(rng, n=300, faces=500, scale=1.0):
    """A mesh whose vertices are each repeated (as a loader splits them along normals), shuffled."""
    base = rng.normal(size=(n, 3)) * scale
    copies = rng.integers(1, 4, size=n)
    v = np.repeat(base, copies, axis=0)
    owner = np.repeat(np.arange(n), copies)
    perm = rng.permutation(len(v))
    v, owner = v[perm], owner[perm]
    f = np.array([rng.choice(np.flatnonzero(owner == o)) for o in rng.integers(0, n, size=3 * faces)]).reshape(-1, 3)
    return v, f


@pytest.mark.parametrize("seed", range(6))
def test_built_meshes_merge_as_trimesh_merges_them(seed):
    rng = np.random.default_rng(seed)
    v, f = _split_mesh(rng, scale=[0.01, 1.0, 300.0, 5e4, 1e-5, 2.0][seed])
    extra = rng.normal(size=(7, 3))  # vertices no face uses, first and last
    v = np.concatenate([extra[:3], v, extra[3:]])
    f = f + 3
    got_v, got_f = _assert_same(v, f)
    assert len(got_v) < len(v) - 7  # the copies were merged (not a test that passes on a no-op)
    tri = v[f]
    kept = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) > 0
    assert np.array_equal(got_v[got_f], tri[kept])  # exact copies: every triangle where it was, in order


def test_near_duplicates_either_side_of_the_rounding_merge_as_in_trimesh():
    rng = np.random.default_rng(7)
    base = rng.normal(size=(50, 3))
    step = 1e-8
    near = base + rng.choice([0.2, 0.49, 0.51, 0.8, 1.5], size=(50, 1)) * step  # some round together, some not
    v = np.concatenate([base, near])
    f = np.concatenate([rng.integers(0, 50, size=(40, 3)), rng.integers(50, 100, size=(40, 3))])
    got_v, _ = _assert_same(v, f)
    assert 50 < len(got_v) < 100


def test_float32_and_degenerate_faces_as_in_trimesh():
    rng = np.random.default_rng(3)
    v, f = _split_mesh(rng, n=80, faces=120)
    f[:5, 2] = f[:5, 1]  # zero area: dropped
    got_v, got_f = _assert_same(v.astype(np.float32), f.astype(np.int32))
    assert len(got_f) <= len(f) - 5


@pytest.mark.parametrize("name", ["mujoco_mug/mug.obj", "sample_cup"])
def test_real_props_merge_as_trimesh_merges_them(name):
    if name == "sample_cup":
        path = ROOT / "sample_assets" / "props" / "cup_on_table.obj"
    else:
        path = ASSETS / name
        if not path.exists():
            pytest.skip(f"{path} is not here")
    loaded = trimesh.load(str(path), force="mesh", process=False)
    v, f = np.asarray(loaded.vertices), np.asarray(loaded.faces)
    got_v, _ = _assert_same(v, f)
    if "mug" in name:  # split along normals as loaded; one closed body once merged
        assert len(got_v) < len(v)


def test_reading_a_plain_obj_prop_imports_no_trimesh(tmp_path):
    import subprocess

    code = ("import sys; from usdhands.formats.props import read_props; "
            f"p = read_props({str(ROOT / 'sample_assets' / 'props' / 'cup_on_table.obj')!r}, meters_per_unit=0.01, "
            "up_axis='Y'); assert len(p[0].faces) > 0; print('trimesh' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"

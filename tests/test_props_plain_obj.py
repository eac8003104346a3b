"""The OBJ reader for files of positions and triangles only (formats.props._read_plain_obj): trimesh's
arrays bit for bit wherever it reads a file, None (trimesh reads it) for everything else."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from usdhands.formats.props import _read_plain_obj, read_props

ROOT = Path(__file__).resolve().parent.parent
MUG = ROOT.parent / "shared" / "assets" / "mujoco_mug" / "mug.obj"


def _trimesh_arrays(path: Path):
    loaded = trimesh.load(str(path), force="mesh", process=False)
    return np.asarray(loaded.vertices, dtype=np.float64), np.asarray(loaded.faces, dtype=np.int64)


def _same_as_trimesh(path: Path) -> bool:
    got = _read_plain_obj(path)
    assert got is not None
    want = _trimesh_arrays(path)
    return got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes() and \
        got[0].shape == want[0].shape and got[1].shape == want[1].shape


def _obj(rng, n=40, formats=("%.6f", "%.8f", "%.3f", "%.0f", "%.12f")) -> str:
    """Positions and triangles with comments, o/g/s lines, blank lines, unused vertices, odd spacing."""
    verts = rng.normal(size=(n, 3)) * rng.choice([0.01, 1.0, 300.0])
    lines = ["# a comment: v 1 2 3 f 1 2 3 ~!@", "o Thing"]
    for v in verts:
        fmt = formats[rng.integers(len(formats))]
        lines.append("v " + "  ".join(fmt % x for x in v) + (" " if rng.random() < 0.2 else ""))
        if rng.random() < 0.05:
            lines.append("")
    lines += ["g part", "s off"]
    used = rng.choice(n, size=n - 3, replace=False)  # three vertices no face uses
    for _ in range(60):
        a, b, c = rng.choice(used, size=3, replace=False) + 1
        lines.append(f"f {a} {b} {c}")
        if rng.random() < 0.05:
            lines.append("# between faces")
    return "\n".join(lines) + ("\n" if rng.random() < 0.5 else "")


def test_positions_and_triangles_read_as_trimesh_reads_them(tmp_path):
    rng = np.random.default_rng(0)
    paths = [ROOT / "sample_assets" / "props" / name for name in ("cup_on_table.obj", "table.obj", "cup.obj")]
    for k in range(30):
        p = tmp_path / f"gen{k}.obj"
        p.write_text(_obj(rng))
        paths.append(p)
    if MUG.exists():  # the mug as trimesh writes it (the benchmark's prop)
        (mug,) = read_props(MUG, meters_per_unit=0.01, up_axis="Y", prop_meters_per_unit=0.01)
        p = tmp_path / "mug_written.obj"
        trimesh.Trimesh(np.asarray(mug.vertices) * 0.01, np.asarray(mug.faces), process=False).export(p)
        paths.append(p)
    for p in paths:
        if p.exists():
            assert _same_as_trimesh(p), p.name


@pytest.mark.parametrize("text", [
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3 4\n",  # a quad
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n",  # relative indices
    "v 0 0 0\nv 1e-3 0 0\nv 0 1 0\nf 1 2 3\n",  # an exponent
    "v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n",  # CR LF
    "v 0\t0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",  # a tab
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n",  # normals
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\n",  # texture coordinates
    "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n",  # materials
    "v 0 0 0 1 0 0\nv 1 0 0 1 0 0\nv 0 1 0 1 0 0\nf 1 2 3\n",  # vertex colours
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",  # an index past the end
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",  # index 0
    "v 0 0\nv 1 0 0 0\nv 0 1 0\nf 1 2 3\n",  # two and four numbers
    "v 0 0 0\nv 1 v0 0\nv 0 1 0\nf 1 2 3\n",  # a letter inside a number
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nl 1 2\n",  # a line element
    "v 0 0 0\nv 1 0 0\nv 0 1 0\n  f 1 2 3\n",  # leading spaces
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\\\n",  # a continuation
    "v 0 0 0\nv 1 0 0\nv 0 1 0\n",  # no faces
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# caf\u00e9\n",  # not ASCII
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 \nv 1-2 0 0\n",  # a malformed number
])
def test_anything_else_is_left_to_trimesh(tmp_path, text):
    p = tmp_path / "odd.obj"
    p.write_bytes(text.encode("utf-8"))
    assert _read_plain_obj(p) is None


def test_mutated_files_read_as_trimesh_reads_them_or_not_at_all(tmp_path):
    """Random byte edits of a small plain OBJ: whatever the plain reader reads, trimesh reads alike."""
    rng = np.random.default_rng(1)
    base = _obj(rng, n=12).encode()
    alphabet = np.frombuffer(b"0123456789.- \nvfogs#e+/\t", dtype=np.uint8)
    read = 0
    for k in range(400):
        b = bytearray(base)
        for _ in range(rng.integers(1, 4)):
            i = int(rng.integers(len(b)))
            op = rng.integers(3)
            if op == 0:
                b[i] = int(rng.choice(alphabet))
            elif op == 1:
                del b[i]
            else:
                b.insert(i, int(rng.choice(alphabet)))
        p = tmp_path / f"m{k}.obj"
        p.write_bytes(bytes(b))
        got = _read_plain_obj(p)
        if got is None:
            continue
        read += 1
        want = _trimesh_arrays(p)
        assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes(), bytes(b)
    assert read > 50

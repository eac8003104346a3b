"""Reading props (rigid meshes the hands touch) into :class:`~usdhands.model.prop.PropMesh`.

OBJ, STL, PLY and OFF are read through trimesh; glTF mesh nodes (static or moved by an
animation) through :mod:`usdhands.formats.gltf_props`; USD ``Mesh`` prims through
:mod:`usdhands.formats.usd_props`. Every prop is converted to the units and up axis
of the clip it goes with. Formats that do not say their units (OBJ, STL, PLY, OFF) are
taken to be in the clip's units and Y up unless told otherwise; glTF is metres and Y up
by its specification; USD says both in its layer metadata.

Vertices that differ only in normals or texture coordinates are merged, so a mesh that
a loader split along its UV seams or hard edges (``mug.obj`` as loaded) is one closed
surface again and inside/outside queries work on it.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from usdhands.errors import AssetReadError
from usdhands.input_files import check_regular_file
from usdhands.model.prop import PropMesh
from usdhands.model.units import up_axis_xform

__all__ = ["MESH_SUFFIXES", "USD_SUFFIXES", "read_props", "convert_xform", "check_prop_units"]

MESH_SUFFIXES = (".obj", ".stl", ".ply", ".off", ".glb", ".gltf")
USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")


def convert_xform(meters_per_unit: float, up_axis: str, clip_meters_per_unit: float, clip_up_axis: str) -> np.ndarray:
    """The ``(4, 4)`` transform taking a prop's coordinates into the clip's units and up axis."""
    f = float(meters_per_unit) / float(clip_meters_per_unit)
    return up_axis_xform(up_axis, clip_up_axis) @ np.diag([f, f, f, 1.0])


def _clean(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge coincident vertices (whatever their normals or UVs) and drop faces of zero area.

    ``vertices`` ``(V, 3)`` and ``faces`` ``(F, 3)`` (indices into them) in; float64 and int64 out. The
    merge is trimesh's ``merge_vertices(merge_tex=True, merge_norm=True)`` to the bit, without
    importing trimesh (0.27 s of a fresh ``usdhands correct`` or ``synthesize --props``): vertices
    whose positions agree when rounded to 1e-8 of a unit are one, the first of them kept in order of
    first occurrence, the vertices no face uses dropped.
    """
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(v) and len(f):
        referenced = np.zeros(len(v), dtype=bool)
        referenced[f] = True
        used = np.flatnonzero(referenced)
        keys = (v[used] * 10**8).round().astype(np.int64)
        _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        order = first.argsort()
        renumber = np.zeros(len(v), dtype=np.int64)
        renumber[used] = order.argsort()[inverse.reshape(-1)]
        v, f = v[used[first[order]]], renumber[f]
    area2 = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    size = float(np.ptp(v, axis=0).max()) if len(v) else 0.0
    return v, f[area2 > 1e-12 * size * size]


#: Largest OBJ file :func:`_read_plain_obj` reads (bigger ones go to trimesh, which streams no better).
_PLAIN_OBJ_MAX_BYTES = 256 * 1024 * 1024


def _read_plain_obj(path: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """The vertices ``(V, 3)`` float64 and triangles ``(F, 3)`` int64 trimesh's OBJ loader gives for an OBJ
    made only of positions and triangles, or None for any other file (trimesh reads those).

    Read here: ASCII lines that are blank, comments (``#``), ``o``, ``g`` or ``s`` lines (which split
    nothing in trimesh's default load), ``v x y z`` (three plain decimal numbers: digits, ``.``, ``-``)
    and ``f a b c`` (three positive indices, no ``/``). The numbers are parsed as trimesh parses them
    (``np.fromstring`` of the same tokens) and the vertices no face uses are dropped, the faces
    renumbered, as it does; the per-line Python work of its general loader (its check that every
    face line has the same columns, 24,544 lines for the mug) is done here on the whole text at
    once. Anything else (normals, texture coordinates, materials, polygons, negative indices, tabs,
    CR line ends, line continuations, exponents, other bytes) returns None.
    """
    try:
        if path.suffix.lower() != ".obj" or path.stat().st_size > _PLAIN_OBJ_MAX_BYTES:
            return None
        data = path.read_bytes()
    except OSError:
        return None
    buf = np.frombuffer(data + b"\n", dtype=np.uint8)
    if len(buf) < 2 or buf.max() >= 128 or (buf == 9).any() or (buf == 13).any() or (buf == 92).any():
        return None
    ends = np.flatnonzero(buf == 10)
    starts = np.concatenate([[0], ends[:-1] + 1])
    length = ends - starts
    first = buf[starts]
    second = buf[np.minimum(starts + 1, len(buf) - 1)]
    spaced = (length >= 2) & (second == 32)
    is_v = (first == ord("v")) & spaced
    is_f = (first == ord("f")) & spaced
    other = (length == 0) | (first == ord("#")) | (spaced & ((first == ord("o")) | (first == ord("g")) |
                                                              (first == ord("s"))))
    nv, nf = int(is_v.sum()), int(is_f.sum())
    if not np.all(is_v | is_f | other) or nv == 0 or nf == 0:
        return None
    kind = np.repeat(np.where(is_v, 1, np.where(is_f, 2, 0)).astype(np.int8), length + 1)  # per byte
    # v and f lines hold numbers only: digits, '.' and '-' (v), digits (f), spaces, their own letter
    bad_v = np.ones(256, dtype=bool)
    bad_v[np.frombuffer(b"0123456789.- \nv", dtype=np.uint8)] = False
    bad_f = np.ones(256, dtype=bool)
    bad_f[np.frombuffer(b"0123456789 \nf", dtype=np.uint8)] = False
    if (bad_v[buf] & (kind == 1)).any() or (bad_f[buf] & (kind == 2)).any():
        return None
    if np.count_nonzero((buf == ord("v")) & (kind == 1)) != nv or np.count_nonzero((buf == ord("f")) & (kind == 2)) != nf:
        return None  # a v or f other than the line's own letter
    # three numbers after the letter on every such line: token starts are non-spaces after a space
    space = (buf == 32) | (buf == 10)
    token_start = ~space & np.concatenate([[True], space[:-1]])
    tokens = np.add.reduceat(token_start, starts, dtype=np.int32)
    if np.any(tokens[is_v] != 4) or np.any(tokens[is_f] != 4):
        return None
    # each kind's lines with their letter blanked: the same tokens trimesh hands np.fromstring
    payload = np.where(kind > 0, np.where((buf == ord("v")) | (buf == ord("f")), np.uint8(32), buf), np.uint8(32))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a token it cannot read ends the array: the counts below catch it
            v = np.fromstring(payload[kind == 1].tobytes().decode("ascii"), sep=" ", dtype=np.float64)
            f = np.fromstring(payload[kind == 2].tobytes().decode("ascii"), sep=" ", dtype=np.int64)
    except ValueError:  # numpy versions that refuse such a token outright
        return None
    if len(v) != 3 * nv or len(f) != 3 * nf or not np.isfinite(v).all():
        return None
    v = v.reshape(-1, 3)
    f = f.reshape(-1, 3)
    if f.min() < 1 or f.max() > len(v):
        return None
    f = f - 1
    used = np.zeros(len(v), dtype=bool)  # trimesh keeps the vertices the faces use, renumbered in order
    used[f] = True
    renumber = np.zeros(len(v), dtype=np.int64)
    renumber[used] = np.arange(used.sum())
    return v[used].copy(), renumber[f]


def _read_trimesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    plain = _read_plain_obj(path)
    if plain is not None:
        return plain
    import trimesh

    try:
        loaded = trimesh.load(str(path), force="mesh", process=False)
    except Exception as e:  # trimesh raises many kinds of errors for files that are not meshes
        reason = " ".join(str(e).split())[:200] or type(e).__name__
        raise AssetReadError(f"cannot read as a mesh: {reason}", path=path) from None
    faces = getattr(loaded, "faces", None)
    vertices = getattr(loaded, "vertices", None)
    if faces is None or vertices is None:
        raise AssetReadError("not a mesh (no triangles in it)", path=path)
    return np.asarray(vertices, dtype=np.float64).reshape(-1, 3), np.asarray(faces, dtype=np.int64).reshape(-1, 3)


def read_props(path: str | os.PathLike, *, meters_per_unit: float, up_axis: str,
               prop_meters_per_unit: float | None = None, prop_up_axis: str | None = None) -> list[PropMesh]:
    """Every rigid mesh of a prop file, in the clip's units and up axis.

    Parameters
    ----------
    path : path-like
        A mesh file (:data:`MESH_SUFFIXES`) or a USD file (:data:`USD_SUFFIXES`).
    meters_per_unit, up_axis : float, {"Y", "Z"}
        The clip's units and up axis: the props come back in them.
    prop_meters_per_unit, prop_up_axis : optional
        The file's units and up axis, overriding what the file says (or, for formats
        that say nothing, the clip's units and Y up).

    Returns
    -------
    list of PropMesh
        A mesh file gives one prop; a USD file one prop for its static meshes and one
        per animated mesh.

    Raises
    ------
    AssetReadError
        Missing file, not a mesh, no triangles, non-finite coordinates; one line.
    """
    path = check_regular_file(path)  # missing, a folder, a named pipe, a device: one line, nothing opened
    suffix = path.suffix.lower()
    if suffix in USD_SUFFIXES:
        from usdhands.formats.usd_props import read_usd_props

        props = read_usd_props(path, meters_per_unit=meters_per_unit, up_axis=up_axis,
                               prop_meters_per_unit=prop_meters_per_unit, prop_up_axis=prop_up_axis)
    elif suffix in (".glb", ".gltf"):
        from usdhands.formats.gltf_props import read_gltf_props

        m = convert_xform(prop_meters_per_unit or 1.0, prop_up_axis or "Y", meters_per_unit, up_axis)
        props = read_gltf_props(path, m)
        if not props:
            raise AssetReadError("not a mesh (no triangles in it)", path=path)
    elif suffix in MESH_SUFFIXES:
        vertices, faces = _read_trimesh(path)
        m = convert_xform(prop_meters_per_unit or meters_per_unit, prop_up_axis or "Y", meters_per_unit, up_axis)
        props = [PropMesh(path.stem, vertices @ m[:3, :3].T, faces, path=str(path))]
    else:
        raise AssetReadError(f"unknown prop format {suffix or '(no extension)'!r}; expected one of "
                             f"{', '.join(MESH_SUFFIXES + USD_SUFFIXES)}", path=path)
    out = []
    for p in props:
        if len(p.faces) == 0:
            raise AssetReadError(f"empty mesh: {p.name!r} has no triangles", path=path)
        if not np.isfinite(p.vertices).all():
            raise AssetReadError(f"mesh {p.name!r} has NaN or infinite coordinates", path=path)
        v, f = _clean(np.asarray(p.vertices), np.asarray(p.faces))
        if len(f) == 0:
            raise AssetReadError(f"empty mesh: {p.name!r} has only degenerate triangles", path=path)
        out.append(PropMesh(p.name, v, f, p.times, p.xforms, p.path))
    if not out:
        raise AssetReadError("empty mesh: no triangles in the file", path=path)
    return out


#: Units a prop file is usually in, metres per unit.
_COMMON_UNITS = {1.0: "metres", 0.01: "centimetres", 0.001: "millimetres", 0.0254: "inches"}


def _bbox_gap(a: np.ndarray, b: np.ndarray) -> float:
    """Distance between two axis-aligned boxes ``(2, 3)`` (0 where they overlap)."""
    d = np.maximum(0.0, np.maximum(a[0] - b[1], b[0] - a[1]))
    return float(np.linalg.norm(d))


def check_prop_units(prop: PropMesh, character_bounds: np.ndarray, meters_per_unit: float,
                     claimed_meters_per_unit: float) -> None:
    """Refuse a prop whose size and place show it is not in the units it claims.

    A prop that is nowhere near the character (more than ten character heights away or
    across) but would be within reach at a common unit slip (cm, mm or inches read as
    metres, or the other way) is in other units than it claims.

    Parameters
    ----------
    prop : PropMesh
        In the clip's units.
    character_bounds : (2, 3) float
        Bounding box of the character's joints over the clip, clip units.
    meters_per_unit : float
        The clip's units.
    claimed_meters_per_unit : float
        The units the file claims (or was taken to be in).

    Raises
    ------
    AssetReadError
    """
    verts = np.asarray(prop.vertices)
    if prop.animated:
        x = prop.xforms[0]
        verts = verts @ x[:3, :3].T + x[:3, 3]
    box = np.array([verts.min(axis=0), verts.max(axis=0)])
    height = max(float(np.max(character_bounds[1] - character_bounds[0])), 1e-9)
    size = float(np.max(box[1] - box[0]))
    gap = _bbox_gap(box, character_bounds)

    def plausible(f: float) -> bool:
        return 0.002 / meters_per_unit <= size * f <= 3 * height and _bbox_gap(box * f, character_bounds) <= height

    if (size > 10 * height or gap > 10 * height or size < 0.002 / meters_per_unit) and not plausible(1.0):
        for units, what in _COMMON_UNITS.items():
            if units != claimed_meters_per_unit and plausible(units / claimed_meters_per_unit):
                raise AssetReadError(
                    f"prop {prop.name!r} is {size * meters_per_unit:.4g} m across and {gap * meters_per_unit:.4g} m "
                    f"from the character in the units it claims ({claimed_meters_per_unit:g} m per unit); it looks "
                    f"like it is in {what}: give its units with --prop-units {units:g}", path=prop.path or None)

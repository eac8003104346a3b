"""A prop for interaction clips: a cup with a handle, as a triangle mesh.

Centimetres, +Y up, the base centred on the origin, the handle toward +X. The body is
a lathe of the cup's closed wall profile (outer wall, rim, inner wall, floor), the
handle a tube swept along a C-shaped path with capped ends; both are closed
(watertight) surfaces, so point-in-mesh queries work on them.
"""

from __future__ import annotations

import numpy as np
import trimesh

__all__ = ["CUP_HEIGHT_CM", "CUP_RADIUS_CM", "cup_mesh", "cup_usda_text", "cup_obj_text"]

CUP_HEIGHT_CM = 9.5
CUP_RADIUS_CM = 4.0
_WALL = 0.35
_FLOOR = 0.5
_SECTIONS = 32


def _lathe(profile: np.ndarray, sections: int) -> trimesh.Trimesh:
    """Revolve a closed (r, y) profile (first and last points on the axis) about +Y."""
    rings = profile[1:-1]
    n = len(rings)
    ang = 2 * np.pi * np.arange(sections) / sections
    verts = [np.array([0.0, profile[0, 1], 0.0])]
    for r, y in rings:
        verts.extend(np.stack([r * np.cos(ang), np.full(sections, y), -r * np.sin(ang)], axis=1))
    verts.append(np.array([0.0, profile[-1, 1], 0.0]))
    verts = np.vstack(verts)
    faces = []
    bottom, top = 0, len(verts) - 1
    ring = lambda i, k: 1 + i * sections + (k % sections)
    for k in range(sections):
        faces.append((bottom, ring(0, k + 1), ring(0, k)))
    for i in range(n - 1):
        for k in range(sections):
            a, b = ring(i, k), ring(i, k + 1)
            c, d = ring(i + 1, k + 1), ring(i + 1, k)
            faces.append((a, b, c))
            faces.append((a, c, d))
    for k in range(sections):
        faces.append((top, ring(n - 1, k), ring(n - 1, k + 1)))
    return trimesh.Trimesh(verts, np.array(faces), process=False)


def _handle(tube_r: float = 0.45, segments: int = 8, steps: int = 12) -> trimesh.Trimesh:
    """A tube along a C from the upper wall out to +X and back to the lower wall."""
    t = np.linspace(-0.5 * np.pi, 0.5 * np.pi, steps)
    cx, cy, a, b = CUP_RADIUS_CM - 0.25, 5.2, 2.3, 2.9
    path = np.stack([cx + a * np.cos(t), cy + b * np.sin(t), np.zeros_like(t)], axis=1)
    tang = np.gradient(path, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    z = np.array([0.0, 0.0, 1.0])
    ang = 2 * np.pi * np.arange(segments) / segments
    verts = []
    for p, tg in zip(path, tang):
        n = np.cross(tg, z)
        n /= np.linalg.norm(n)
        for s in ang:
            verts.append(p + tube_r * (np.cos(s) * n + np.sin(s) * z))
    verts.append(path[0])
    verts.append(path[-1])
    verts = np.array(verts)
    faces = []
    ring = lambda i, k: i * segments + (k % segments)
    for i in range(steps - 1):
        for k in range(segments):
            a_, b_ = ring(i, k), ring(i, k + 1)
            c_, d_ = ring(i + 1, k + 1), ring(i + 1, k)
            faces.append((a_, b_, c_))
            faces.append((a_, c_, d_))
    c0, c1 = len(verts) - 2, len(verts) - 1
    for k in range(segments):
        faces.append((c0, ring(0, k + 1), ring(0, k)))
        faces.append((c1, ring(steps - 1, k), ring(steps - 1, k + 1)))
    mesh = trimesh.Trimesh(verts, np.array(faces), process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def cup_mesh() -> trimesh.Trimesh:
    """The cup: a watertight body and a watertight handle, about 450 triangles.

    Returns
    -------
    trimesh.Trimesh
        Vertices in cm, +Y up; two closed components (body, handle).
    """
    R, H = CUP_RADIUS_CM, CUP_HEIGHT_CM
    profile = np.array([
        [0.0, 0.0], [R - 0.3, 0.0], [R, 0.3], [R, H], [R - _WALL, H], [R - _WALL, _FLOOR + 0.2],
        [R - _WALL - 0.2, _FLOOR], [0.0, _FLOOR],
    ])
    body = _lathe(profile, _SECTIONS)
    if body.volume < 0:
        body.invert()
    mesh = trimesh.util.concatenate([body, _handle()])
    mesh.metadata["name"] = "Cup"
    return mesh


def cup_obj_text(mesh: trimesh.Trimesh | None = None) -> str:
    """Wavefront OBJ text of the cup (vertices in cm, +Y up; one object, triangles)."""
    mesh = mesh if mesh is not None else cup_mesh()
    lines = ["# usdhands sample prop: cup, centimetres, +Y up", "o Cup"]
    lines += [f"v {x:.5f} {y:.5f} {z:.5f}" for x, y, z in mesh.vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces]
    return "\n".join(lines) + "\n"


def _fmt_tuples(rows: np.ndarray, fmt: str = "{:.5g}") -> str:
    return ", ".join("(" + ", ".join(fmt.format(float(v)) for v in r) + ")" for r in rows)


def cup_usda_text(mesh: trimesh.Trimesh | None = None) -> str:
    """USD text (``.usda``) of the cup: one ``UsdGeom.Mesh`` under an Xform, cm, Y up.

    Authored as text so this module needs no ``pxr``; the tests open it with ``pxr``.
    """
    mesh = mesh if mesh is not None else cup_mesh()
    lo, hi = mesh.bounds
    counts = ", ".join("3" for _ in range(len(mesh.faces)))
    indices = ", ".join(str(int(i)) for i in mesh.faces.reshape(-1))
    return f"""#usda 1.0
(
    defaultPrim = "Cup"
    doc = "usdhands sample prop: a cup, centimetres, +Y up"
    metersPerUnit = 0.01
    upAxis = "Y"
)

def Xform "Cup" (
    kind = "component"
)
{{
    def Mesh "Geom"
    {{
        float3[] extent = [{_fmt_tuples(np.array([lo, hi]))}]
        int[] faceVertexCounts = [{counts}]
        int[] faceVertexIndices = [{indices}]
        point3f[] points = [{_fmt_tuples(mesh.vertices)}]
        normal3f[] normals = [{_fmt_tuples(mesh.vertex_normals, "{:.4f}")}] (
            interpolation = "vertex"
        )
        uniform token orientation = "rightHanded"
        uniform token subdivisionScheme = "none"
        color3f[] primvars:displayColor = [(0.85, 0.83, 0.78)]
    }}
}}
"""

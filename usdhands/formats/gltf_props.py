"""Reading glTF mesh nodes as props: static ones baked, animated ones (a node or an ancestor with
translation, rotation or scale channels in the file's first animation) with their keys."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from usdhands.formats.gltf_container import load_gltf
from usdhands.formats.gltf_read import (
    _attributes, _node_parents, _node_trs, _triangles, channel_keys, sample_channel,
)
from usdhands.model.prop import PropMesh
from usdhands.model.rotations import trs_to_xform

__all__ = ["read_gltf_props"]


def _node_geometry(doc, mesh_index: int) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle primitive of a mesh: vertices ``(V, 3)`` and faces ``(F, 3)`` in the node's frame."""
    verts, faces, n = [], [], 0
    for pi, prim in enumerate(doc.gltf.meshes[mesh_index].primitives):
        attrs = _attributes(prim)
        if attrs.get("POSITION") is None:
            continue
        points = doc.accessor(attrs["POSITION"])
        idx = (doc.accessor(prim.indices, as_float=False)[:, 0].astype(np.int64) if prim.indices is not None
               else np.arange(points.shape[0]))
        tri = _triangles(4 if prim.mode is None else prim.mode, idx)
        if tri is None or tri.size == 0:
            continue
        if tri.max() >= points.shape[0]:
            raise doc.error(f"index {int(tri.max())} out of range for {points.shape[0]} vertices",
                            f"meshes[{mesh_index}].primitives[{pi}]")
        verts.append(points[:, :3])
        faces.append(tri + n)
        n += points.shape[0]
    if not verts:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    return np.concatenate(verts), np.concatenate(faces)


def read_gltf_props(path: Path, conv: np.ndarray) -> list[PropMesh]:
    """Every mesh node of a glTF file (skinned ones left out), transformed by ``conv`` (``(4, 4)``,
    the file's metres and Y up to the clip's units and up axis).

    Static nodes are baked into one prop named after the file; a node moved by the first
    animation is its own prop with keys at the union of its channels' key times.
    """
    doc = load_gltf(path)
    g = doc.gltf
    parents = _node_parents(doc)
    trs = [_node_trs(doc, i) for i in range(len(g.nodes))]
    channels: dict[int, list] = {}
    if g.animations:
        for ci, ch in enumerate(g.animations[0].channels):
            if ch.target is None or ch.target.node is None or ch.target.path not in ("translation", "rotation", "scale"):
                continue
            channels.setdefault(int(ch.target.node), []).append((ch.target.path, *channel_keys(doc, 0, ci)))
    conv_inv = np.linalg.inv(conv)

    def world(node: int, at: np.ndarray | None) -> np.ndarray:
        """World transforms ``(K, 4, 4)`` of ``node`` at times ``at`` (one rest transform when None)."""
        K = 1 if at is None else len(at)
        out = np.broadcast_to(np.eye(4), (K, 4, 4)).copy()
        chain = []
        j = node
        while j >= 0:
            chain.append(j)
            j = int(parents[j])
        for j in reversed(chain):
            t, q, s = (np.broadcast_to(x, (K, len(x))).copy() for x in trs[j])
            for path_, times, values, interp in channels.get(j, []) if at is not None else []:
                v = sample_channel(times, values, interp, at, path_ == "rotation")
                {"translation": t, "rotation": q, "scale": s}[path_][:] = v
            out = out @ trs_to_xform(t, q, s)
        return out

    static_v, static_f, n_static, props = [], [], 0, []
    for ni, node in enumerate(g.nodes):
        if node.mesh is None or node.skin is not None:
            continue
        v, f = _node_geometry(doc, int(node.mesh))
        if len(f) == 0:
            continue
        chain, j = [], ni
        while j >= 0:
            chain.append(j)
            j = int(parents[j])
        keys = sorted({float(x) for j in chain for _, times, _, _ in channels.get(j, []) for x in times})
        if len(keys) > 1:
            at = np.asarray(keys)
            xs = conv @ world(ni, at) @ conv_inv
            props.append(PropMesh(node.name or f"node{ni}", v @ conv[:3, :3].T, f, at, xs, path=str(path)))
        else:
            w = conv @ world(ni, None)[0]
            static_v.append(v @ w[:3, :3].T + w[:3, 3])
            static_f.append(f + n_static)
            n_static += len(v)
    if static_v:
        props.insert(0, PropMesh(Path(path).stem, np.concatenate(static_v), np.concatenate(static_f), path=str(path)))
    return props

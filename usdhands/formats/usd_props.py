"""Reading USD ``Mesh`` prims as props (rigid, static or with time-sampled transforms)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom

from usdhands.errors import AssetReadError
from usdhands.formats.usd_common import matrices_to_numpy, open_stage, quiet_diagnostics
from usdhands.model.prop import PropMesh

__all__ = ["read_usd_props", "stage_meters_per_unit"]

_PREDICATE = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)


def _triangles(counts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Fan-triangulate polygons: ``(sum(counts - 2), 3)`` int64 (polygons under 3 vertices dropped)."""
    counts = np.asarray(counts, dtype=np.int64)
    indices = np.asarray(indices, dtype=np.int64)
    if counts.sum() != len(indices):
        raise ValueError("faceVertexCounts do not add up to faceVertexIndices")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tri = []
    for k in range(3, int(counts.max(initial=0)) + 1):
        sel = starts[counts == k]
        for i in range(1, k - 1):
            tri.append(np.stack([indices[sel], indices[sel + i], indices[sel + i + 1]], axis=1))
    return np.concatenate(tri) if tri else np.zeros((0, 3), dtype=np.int64)


def _time_varying(prim: Usd.Prim) -> list[float]:
    """Time codes at which the local-to-world transform of ``prim`` is keyed (empty when static)."""
    times: set[float] = set()
    p = prim
    while p and not p.IsPseudoRoot():
        x = UsdGeom.Xformable(p)
        if x:
            for op in x.GetOrderedXformOps():
                times.update(op.GetAttr().GetTimeSamples())
            if x.GetResetXformStack():
                break
        p = p.GetParent()
    return sorted(times) if len(times) > 1 else []


def stage_meters_per_unit(path) -> float:
    """The ``metersPerUnit`` a USD file claims (1 cm = 0.01 when it says nothing, as USD defines)."""
    return float(UsdGeom.GetStageMetersPerUnit(open_stage(path)))


def read_usd_props(path: Path, *, meters_per_unit: float, up_axis: str,
                   prop_meters_per_unit: float | None = None, prop_up_axis: str | None = None) -> list[PropMesh]:
    """Every ``Mesh`` prim of a USD file, in the clip's units and up axis.

    Static meshes are baked (their world transform applied) into one prop named after
    the file; a mesh whose transform (or an ancestor's) has time samples is its own
    prop with those keys (seconds = time code / timeCodesPerSecond).
    """
    from usdhands.formats.props import convert_xform

    stage = open_stage(path)
    mpu = prop_meters_per_unit or UsdGeom.GetStageMetersPerUnit(stage)
    up = prop_up_axis or str(UsdGeom.GetStageUpAxis(stage))
    conv = convert_xform(mpu, up, meters_per_unit, up_axis)
    conv_inv = np.linalg.inv(conv)
    tcps = stage.GetTimeCodesPerSecond() or 24.0
    static_v, static_f, n_static = [], [], 0
    props: list[PropMesh] = []
    cache = UsdGeom.XformCache(Usd.TimeCode.EarliestTime())
    with quiet_diagnostics():
        for prim in stage.Traverse(_PREDICATE):
            if not prim.IsA(UsdGeom.Mesh):
                continue
            mesh = UsdGeom.Mesh(prim)
            if UsdGeom.Imageable(prim).ComputeVisibility() == UsdGeom.Tokens.invisible:
                continue
            pts = mesh.GetPointsAttr().Get(Usd.TimeCode.EarliestTime())
            counts = mesh.GetFaceVertexCountsAttr().Get()
            idx = mesh.GetFaceVertexIndicesAttr().Get()
            if pts is None or counts is None or idx is None or len(pts) == 0:
                continue
            v = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
            try:
                f = _triangles(np.asarray(counts), np.asarray(idx))
            except ValueError as e:
                raise AssetReadError(f"{e}", path=path, location=str(prim.GetPath())) from None
            if len(f) and (f.min() < 0 or f.max() >= len(v)):
                raise AssetReadError("face vertex index out of range", path=path, location=str(prim.GetPath()))
            keys = _time_varying(prim)
            if keys:
                xs = np.empty((len(keys), 4, 4))
                for i, t in enumerate(keys):
                    c = UsdGeom.XformCache(Usd.TimeCode(t))
                    xs[i] = conv @ matrices_to_numpy([c.GetLocalToWorldTransform(prim)])[0] @ conv_inv
                props.append(PropMesh(str(prim.GetPath()), v @ conv[:3, :3].T, f, np.asarray(keys) / tcps, xs,
                                      path=str(path)))
            else:
                world = conv @ matrices_to_numpy([cache.GetLocalToWorldTransform(prim)])[0]
                static_v.append(v @ world[:3, :3].T + world[:3, 3])
                static_f.append(f + n_static)
                n_static += len(v)
    if static_v:
        props.insert(0, PropMesh(Path(path).stem, np.concatenate(static_v), np.concatenate(static_f), path=str(path)))
    if not props:
        raise AssetReadError("empty mesh: no Mesh prim with points and faces in the file", path=path)
    return props

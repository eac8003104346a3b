"""Reading and writing clips in each format, against the bare library doing the same work.

Run: ``python benchmarks/bench_io.py [--frames 10000] [--joints 65] [--repeat 5] [--formats usd gltf bvh]
[--no-real]``

Two parts, each timing usdhands and the bare library in the same run, alternately, and
printing medians of CPU time and the ratio usdhands / bare (the goal: 1.2 or less), then
the ratio of wall-time medians (these machines are shared: wall time is noisier):

1. A generated clip of ``--frames`` x ``--joints`` (random tree, centimetres).
2. The real files: the glTF, USD and BVH assets in ``../shared/assets`` (when present)
   and the samples in ``sample_assets``, each read, and its asset written again in
   its own format.

The bare baselines, per format (``bare_read_*``, ``bare_write_*``):

- USD (pxr): ``Usd.Stage.Open``, ``Get`` of rotations and translations at every time
  sample of every SkelAnimation into ``(T, J, 4/3)`` float32 arrays (scales at every time
  sample where they have time samples, else once), and of what else the reader reads:
  every Skeleton's joints, bind and rest transforms and local-to-world transform, every
  Mesh's points, faces, normals, UVs, joint influences and bound material, which skeleton
  each mesh is bound to (``UsdSkel.Cache``, ``ComputeSkelBindings``), every shader's inputs
  and the bytes of the texture files they name (before session 11 the bare read took scales
  once even where they vary, and neither bindings nor world transforms; usdhands: float64
  arrays, the hierarchy checked, the crate's structure checked before USD opens it, the
  influences checked, skinning resolved; a generated file has no mesh); writing: one
  SkelAnimation per clip, ``Set`` of ``FromNumpy`` arrays per frame, and every Skeleton's
  joints and transforms, every mesh's points, faces, normals, UVs and influences, every
  image into a file beside, every material as a UsdPreviewSurface network bound to its
  meshes, and (since session 13) what makes the file a character UsdSkel poses: one SkelRoot
  above them, each mesh's ``skel:skeleton``, ``geomBindTransform`` and extent, each skeleton's
  ``skel:animationSource``; ``Export`` (usdhands writes its textures atomically: a temporary
  file renamed).
- glTF (pygltflib + numpy): ``GLTF2.load``, ``np.frombuffer`` of every channel's input
  and output accessor, and the outputs put into one time-major ``(T, nodes, 4 or 3)`` float32
  array per path (rotation, translation), as a reader hands over arrays of that shape, and
  every mesh's vertex attributes and indices and every skin's bind matrices; no sampling
  (usdhands: float64, the rest pose where nothing is keyed, scales, the accessors'
  bounds checked, the skeletons and meshes built); writing: one node per joint, one input
  accessor and a rotation and translation accessor per joint and clip (the float32
  per-joint arrays made from the clip inside the timing), ``save_binary`` (usdhands also
  writes the skins, meshes and materials of a real file, checks the quaternions are unit
  and keeps neighbouring ones on the same side).
- BVH (numpy): ``np.loadtxt`` of the motion block, nothing else (usdhands also reads the
  hierarchy and turns every rotation channel's Euler angles into quaternions: ``np.cos``
  and ``np.sin`` of the half angles alone take about 14% of the loadtxt time of 10,000
  frames x 65 joints); writing: ``np.savetxt`` of the same numbers with ``%.6f`` (usdhands
  also turns the quaternions into Euler angles and writes the hierarchy). Two reading
  rows: ``read``, the reader every install with the kernels compiled ahead of time runs
  (``usdhands.formats._bvh_compiled``: the motion parser and the axis products), and
  ``read.np``, NumPy alone (``np.loadtxt`` and the NumPy Euler conversion: what an install
  without a C compiler reads with until numba runs a kernel of the package or 128 MB of
  BVH motion were read; the goal is the first row's).

usdhands does more than each baseline (hierarchy, rest poses, unit and axis
conversion, quaternion normalisation, Euler conversions, checks), so the ratios are
what all of that costs on top of moving the numbers.

Both sides run in this one process and take turns, each round in the same order; the real
files get at least 15 rounds, more while a row's rounds took less than 1.5 s. Columns:
``ratio`` of the CPU medians (this process, every thread: the goal), ``wall`` of the wall
medians, ``main`` of the main thread's CPU medians. USD works with a pool of worker threads
(TBB) that spin for a while after each parallel step before they sleep; on a small file
(CesiumMan.usdz: the bare read is 1.0-1.5 ms on the main thread) that spinning adds about
1 ms of CPU to each read in some processes and almost none in others, on both sides alike,
so the CPU ratio of a small file moves between runs (1.3x and 2-3x for CesiumMan's read)
while ``main`` stays put: the work usdhands does, without the pool's spinning. The load
average is printed before and after.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
GOAL = 1.2


def make_clip(frames: int, joints: int, seed: int = 0):
    """A random ``frames`` x ``joints`` clip on a random tree, centimetres."""
    from usdhands.model.clip import Clip
    from usdhands.model.skeleton import Skeleton

    rng = np.random.default_rng(seed)
    parents = np.array([-1] + [int(rng.integers(0, j)) for j in range(1, joints)])
    names = [f"mixamorig:Joint{j}" for j in range(joints)]
    q = rng.normal(size=(frames, joints, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    rest_q = rng.normal(size=(joints, 4))
    rest_q /= np.linalg.norm(rest_q, axis=-1, keepdims=True)
    sk = Skeleton(names, parents, rng.normal(size=(joints, 3)) * 10, rest_q, meters_per_unit=0.01, name="Rig")
    return Clip(sk, 30.0, q, rng.normal(size=(frames, joints, 3)) * 10, name="Take")


def medians(repeat: int, fns: dict, budget: float = 0.0) -> dict:
    """Median CPU, wall and main-thread CPU seconds of each function over ``repeat`` rounds (more,
    while the rounds so far took less than ``budget`` seconds, up to 20 x ``repeat``), the functions
    taking turns.

    CPU time (of this process, all threads) is what the ratios use: on a shared machine
    wall time also holds the time others' processes had the cores. The main thread's CPU
    (``time.thread_time``) leaves out USD's worker threads, which spin for a while after each
    parallel step (a stage's open and close): about 1 ms of CPU per small file's open, in some
    processes and not in others (see the module docstring).
    """
    times: dict = {k: ([], [], []) for k in fns}
    start = time.perf_counter()
    rounds = 0
    while rounds < repeat or (time.perf_counter() - start < budget and rounds < 20 * repeat):
        rounds += 1
        for k, fn in fns.items():
            t0, c0, m0 = time.perf_counter(), time.process_time(), time.thread_time()
            fn()
            times[k][2].append(time.thread_time() - m0)
            times[k][0].append(time.process_time() - c0)
            times[k][1].append(time.perf_counter() - t0)
    return {k: (statistics.median(c), statistics.median(w), statistics.median(m)) for k, (c, w, m) in times.items()}


# --------------------------------------------------------------------------- USD
def bare_write_usd(asset, path: Path) -> None:
    """One SkelAnimation per clip, Set per frame from numpy; what else the writer writes: every
    Skeleton's joints and transforms, every mesh's points, faces, normals, UVs and joint
    influences, every image's bytes in a file beside, every material as a UsdPreviewSurface
    network (its factors, a texture reader per texture) bound to its meshes; what makes the file a
    character UsdSkel poses (since session 13): everything under one SkelRoot, each mesh bound to
    its skeleton (``skel:skeleton``, its ``geomBindTransform``) with its extent (UsdGeom's rule for
    a boundable prim), each skeleton bound to its first animation (``skel:animationSource``); Export."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, UsdSkel, Vt

    from usdhands.formats.usd_common import joint_tokens_for

    stage = Usd.Stage.CreateInMemory()
    stage.SetTimeCodesPerSecond(asset.clips[0].fps)
    UsdSkel.Root.Define(stage, "/Root")
    for k, sk in enumerate(asset.skeletons):
        skel = UsdSkel.Skeleton.Define(stage, f"/Root/Skel{k}")
        skel.CreateJointsAttr().Set(joint_tokens_for(sk.joint_names, sk.parents))
        skel.CreateRestTransformsAttr().Set(Vt.Matrix4dArray.FromNumpy(
            np.ascontiguousarray(sk.rest_local_xforms().transpose(0, 2, 1))))
        bind = sk.bind_xforms if sk.bind_xforms is not None else sk.rest_world_xforms()
        skel.CreateBindTransformsAttr().Set(Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(bind.transpose(0, 2, 1))))
    for k, m in enumerate(asset.meshes):
        mesh = UsdGeom.Mesh.Define(stage, f"/Root/Mesh{k}")
        points = np.ascontiguousarray(m.points, dtype=np.float32)
        mesh.CreatePointsAttr().Set(Vt.Vec3fArray.FromNumpy(points))
        if len(points):
            mesh.CreateExtentAttr().Set(Vt.Vec3fArray.FromNumpy(np.stack([points.min(axis=0), points.max(axis=0)])))
        mesh.CreateFaceVertexCountsAttr().Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(m.face_vertex_counts,
                                                                                          dtype=np.int32)))
        mesh.CreateFaceVertexIndicesAttr().Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(m.face_vertex_indices,
                                                                                           dtype=np.int32)))
        api = UsdGeom.PrimvarsAPI(mesh)
        if m.normals is not None:
            api.CreatePrimvar("normals", Sdf.ValueTypeNames.Normal3fArray, UsdGeom.Tokens.vertex).Set(
                Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(m.normals, dtype=np.float32)))
        if m.uvs is not None:
            api.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(
                Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(m.uvs, dtype=np.float32)))
        if m.joint_indices is not None:
            n = m.joint_indices.shape[1]
            binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
            binding.CreateJointIndicesPrimvar(False, n).Set(Vt.IntArray.FromNumpy(
                np.ascontiguousarray(m.joint_indices, dtype=np.int32).ravel()))
            binding.CreateJointWeightsPrimvar(False, n).Set(Vt.FloatArray.FromNumpy(
                np.ascontiguousarray(m.joint_weights, dtype=np.float32).ravel()))
            binding.CreateSkeletonRel().SetTargets([Sdf.Path(f"/Root/Skel{m.skeleton_index}")])
            binding.CreateGeomBindTransformAttr().Set(Gf.Matrix4d(m.geom_bind_xform.T.tolist()))
    image_paths = []
    for k, image in enumerate(asset.images):
        image_paths.append(path.parent / f"bare_image{k}_{image.name}")
        image_paths[-1].write_bytes(image.content())
    materials = []
    for k, mat in enumerate(asset.materials):  # a UsdPreviewSurface network per material, as the writer makes
        material = UsdShade.Material.Define(stage, f"/Materials/Material{k}")
        surface = UsdShade.Shader.Define(stage, f"/Materials/Material{k}/PreviewSurface")
        surface.CreateIdAttr("UsdPreviewSurface")
        material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
        surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*mat.base_color[:3]))
        surface.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(float(mat.metallic))
        surface.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(mat.roughness))
        reader = UsdShade.Shader.Define(stage, f"/Materials/Material{k}/uvReader_st")
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
        reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
        for slot, ref in mat.textures.items():
            tex = UsdShade.Shader.Define(stage, f"/Materials/Material{k}/{slot}_texture")
            tex.CreateIdAttr("UsdUVTexture")
            tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(f"./{image_paths[ref.image].name}"))
            tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
            tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
            surface.CreateInput(f"{slot}Texture", Sdf.ValueTypeNames.Color3f).ConnectToSource(tex.ConnectableAPI(),
                                                                                            "rgb")
        materials.append(material)
    for k, m in enumerate(asset.meshes):
        if m.material is not None:
            UsdShade.MaterialBindingAPI.Apply(stage.GetPrimAtPath(f"/Root/Mesh{k}")).Bind(materials[m.material])
    for k, clip in enumerate(asset.clips):
        sk = clip.skeleton
        anim = UsdSkel.Animation.Define(stage, f"/Root/Anim{k}")
        skel_binding = UsdSkel.BindingAPI.Apply(stage.GetPrimAtPath(f"/Root/Skel{next(i for i, s in enumerate(asset.skeletons) if s is sk)}"))
        if not skel_binding.GetAnimationSourceRel().HasAuthoredTargets():
            skel_binding.CreateAnimationSourceRel().SetTargets([anim.GetPath()])
        anim.CreateJointsAttr().Set(joint_tokens_for(sk.joint_names, sk.parents))
        rot = np.ascontiguousarray(clip.rotations, dtype=np.float32)
        tr = np.ascontiguousarray(clip.translations, dtype=np.float32)
        r, t = anim.CreateRotationsAttr(), anim.CreateTranslationsAttr()
        anim.CreateScalesAttr().Set(Vt.Vec3hArray.FromNumpy(np.ones((clip.num_joints, 3), np.float16)))
        for f in range(clip.num_frames):
            r.Set(Vt.QuatfArray.FromNumpy(rot[f]), float(f))
            t.Set(Vt.Vec3fArray.FromNumpy(tr[f]), float(f))
    stage.GetRootLayer().Export(str(path))


def bare_read_usd(path: Path) -> list:
    """Rotations and translations ``(T, J, 4/3)`` float32 of every SkelAnimation, and its scales at
    every time sample where they have time samples (once where they do not); every Skeleton's
    joints, bind and rest transforms and its local-to-world transform; every Mesh's points,
    faces, normals, UVs and joint influences as numpy arrays, and its bound material; which
    skeleton each mesh is bound to (``UsdSkel.Cache`` populated from each SkelRoot,
    ``ComputeSkelBindings``); every shader's inputs, and the bytes of every texture file they name."""
    from pxr import Ar, Sdf, Usd, UsdGeom, UsdShade, UsdSkel

    out = []
    stage = Usd.Stage.Open(str(path))
    cache = UsdSkel.Cache()
    roots = []
    for prim in stage.Traverse():
        if prim.IsA(UsdSkel.Root):
            roots.append(UsdSkel.Root(prim))
            cache.Populate(roots[-1], Usd.PrimDefaultPredicate)
        elif prim.IsA(UsdSkel.Skeleton):
            skel = UsdSkel.Skeleton(prim)
            out.append((list(skel.GetJointsAttr().Get() or []),
                        [np.asarray(a.Get()) for a in (skel.GetBindTransformsAttr(), skel.GetRestTransformsAttr())
                         if a.HasValue()],
                        np.asarray(skel.ComputeLocalToWorldTransform(Usd.TimeCode.EarliestTime()))))
        elif prim.IsA(UsdGeom.Mesh):
            mesh, api = UsdGeom.Mesh(prim), UsdGeom.PrimvarsAPI(prim)
            binding = UsdSkel.BindingAPI(prim)
            arrays = [np.asarray(a.Get()) for a in (mesh.GetPointsAttr(), mesh.GetFaceVertexCountsAttr(),
                                                    mesh.GetFaceVertexIndicesAttr()) if a.HasValue()]
            for pv in (api.GetPrimvar("normals"), api.GetPrimvar("st"), binding.GetJointIndicesPrimvar(),
                       binding.GetJointWeightsPrimvar()):
                if pv and pv.HasValue():
                    arrays.append(np.asarray(pv.ComputeFlattened()))
            arrays.append(UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0])
            out.append(arrays)
        elif prim.IsA(UsdShade.Shader):
            for inp in UsdShade.Shader(prim).GetInputs():
                value = inp.Get()
                out.append(value)
                if isinstance(value, Sdf.AssetPath) and value.resolvedPath:
                    out.append(bytes(Ar.GetResolver().OpenAsset(Ar.ResolvedPath(value.resolvedPath)).GetBuffer()))
        if not prim.IsA(UsdSkel.Animation):
            continue
        anim = UsdSkel.Animation(prim)
        r, t, s = anim.GetRotationsAttr(), anim.GetTranslationsAttr(), anim.GetScalesAttr()
        samples = r.GetTimeSamples()
        J = len(anim.GetJointsAttr().Get() or [])
        out_r = np.empty((len(samples), J, 4), np.float32)
        out_t = np.empty((len(samples), J, 3), np.float32)
        for f, code in enumerate(samples):
            out_r[f] = np.asarray(r.Get(code))
            out_t[f] = np.asarray(t.Get(code))
        if s.GetNumTimeSamples():  # scales that vary (CesiumMan's: 48 samples), as usdhands must read them
            out_s = np.empty((len(samples), J, 3), np.float32)
            for f, code in enumerate(samples):
                out_s[f] = np.asarray(s.Get(code))
        else:
            out_s = s.Get()
        out.append((out_r, out_t, out_s))
    for root in roots:  # which skeleton each skinned mesh is bound to
        for binding in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate):
            out.append((binding.GetSkeleton().GetPrim().GetPath(),
                        [target.GetPrim().GetPath() for target in binding.GetSkinningTargets()]))
    return out


# -------------------------------------------------------------------------- glTF
def bare_write_gltf(asset, path: Path) -> None:
    """Nodes, one input accessor and per-joint rotation and translation accessors per clip, save_binary."""
    import pygltflib

    g = pygltflib.GLTF2()
    blob = bytearray()

    def accessor(arr, type_):
        g.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=arr.nbytes))
        blob.extend(arr.tobytes())
        g.accessors.append(pygltflib.Accessor(bufferView=len(g.bufferViews) - 1, componentType=pygltflib.FLOAT,
                                              count=arr.shape[0], type=type_))
        return len(g.accessors) - 1

    first_node = {}
    for clip in asset.clips:
        sk = clip.skeleton
        if id(sk) not in first_node:
            first_node[id(sk)] = len(g.nodes)
            g.nodes.extend(pygltflib.Node(name=n) for n in sk.joint_names)
        base = first_node[id(sk)]
        times = (np.arange(clip.num_frames) / clip.fps).astype(np.float32)
        rot = np.ascontiguousarray(clip.rotations.transpose(1, 0, 2), dtype=np.float32)
        tr = np.ascontiguousarray(clip.translations.transpose(1, 0, 2) * sk.meters_per_unit, dtype=np.float32)
        inp = accessor(times, "SCALAR")
        g.accessors[inp].min, g.accessors[inp].max = [float(times[0])], [float(times[-1])]
        anim = pygltflib.Animation(name=clip.name)
        for j in range(clip.num_joints):
            for what, arr, type_ in (("rotation", rot[j], "VEC4"), ("translation", tr[j], "VEC3")):
                anim.samplers.append(pygltflib.AnimationSampler(input=inp, output=accessor(arr, type_)))
                anim.channels.append(pygltflib.AnimationChannel(
                    sampler=len(anim.samplers) - 1,
                    target=pygltflib.AnimationChannelTarget(node=base + j, path=what)))
        g.animations.append(anim)
    g.buffers.append(pygltflib.Buffer(byteLength=len(blob)))
    g.set_binary_blob(bytes(blob))
    g.save_binary(str(path))


def bare_read_gltf(path: Path) -> list:
    """``GLTF2.load``, then per animation its key times and, per channel path, one time-major
    ``(T, nodes, 4 or 3)`` float32 array with each channel's values in its node's column."""
    import pygltflib

    _SIZES = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}
    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob()
    out = []

    def read(index):
        acc = g.accessors[index]
        view = g.bufferViews[acc.bufferView]
        n = _SIZES[acc.type]
        dtype = {pygltflib.FLOAT: np.float32, pygltflib.UNSIGNED_SHORT: np.uint16,
                 pygltflib.SHORT: np.int16, pygltflib.UNSIGNED_BYTE: np.uint8, pygltflib.BYTE: np.int8}[acc.componentType]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        return np.frombuffer(blob, dtype, acc.count * n, start).reshape(-1, n)

    def read_any(index):
        """Any accessor, strided views and integer types included, as a ``(count, n)`` array."""
        acc = g.accessors[index]
        if acc.bufferView is None:
            return None
        view = g.bufferViews[acc.bufferView]
        dtype = np.dtype({5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}[acc.componentType])
        n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc.type]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        stride = view.byteStride or n * dtype.itemsize
        rows = np.frombuffer(blob, np.uint8, (acc.count - 1) * stride + n * dtype.itemsize if acc.count else 0, start)
        return np.lib.stride_tricks.as_strided(rows.view(np.uint8), (acc.count, n * dtype.itemsize), (stride, 1)) \
            .copy().view(dtype)

    for mesh in g.meshes:  # what else the reader reads: vertex data, indices, bind matrices
        for prim in mesh.primitives:
            attrs = prim.attributes
            for index in (attrs.POSITION, attrs.NORMAL, attrs.TEXCOORD_0, attrs.JOINTS_0, attrs.WEIGHTS_0,
                          prim.indices):
                if index is not None:
                    out.append(read_any(index))
    for skin in g.skins:
        if skin.inverseBindMatrices is not None:
            out.append(read_any(skin.inverseBindMatrices))
    for anim in g.animations:
        by_path: dict = {}  # path -> [(node, values)]
        times = {}
        for ch in anim.channels:
            s = anim.samplers[ch.sampler]
            if s.input not in times:
                times[s.input] = read(s.input)
            by_path.setdefault(ch.target.path, []).append((ch.target.node, read(s.output)))
        arrays = {}
        for what, chans in by_path.items():
            column = {node: k for k, node in enumerate(dict.fromkeys(node for node, _ in chans))}
            a = arrays[what] = np.empty((max(len(v) for _, v in chans), len(column), chans[0][1].shape[1]),
                                        np.float32)
            for node, v in chans:
                a[:len(v), column[node]] = v
        out.append((list(times.values()), arrays))
    return out


# --------------------------------------------------------------------------- BVH
def _motion_start(path: Path) -> int:
    """Lines before the first motion line (up to and including 'Frame Time:')."""
    with open(path) as f:
        for k, line in enumerate(f):
            if line.split(":")[0].strip().lower() == "frame time":
                return k + 1
    raise ValueError(f"{path}: no 'Frame Time:' line")


def bare_read_bvh(path: Path) -> np.ndarray:
    """``np.loadtxt`` of the motion block."""
    return np.loadtxt(path, skiprows=_motion_start(path), ndmin=2)


def bare_write_bvh(values: np.ndarray, path: Path) -> None:
    """``np.savetxt`` of the motion values with ``%.6f``."""
    np.savetxt(path, values, fmt="%.6f")


# ------------------------------------------------------------------------ driver
EXT = {"usd": ".usdc", "gltf": ".glb", "bvh": ".bvh"}


def format_of(path: Path) -> str | None:
    s = path.suffix.lower()
    return {".usd": "usd", ".usda": "usd", ".usdc": "usd", ".usdz": "usd", ".glb": "gltf", ".bvh": "bvh"}.get(s)


def bench_file(fmt: str, source: Path, asset, folder: Path, repeat: int, budget: float = 0.0) -> list[tuple]:
    """Rows ``(operation, usdhands s, bare s)`` for reading ``source`` and writing ``asset`` in ``fmt``."""
    from usdhands.formats.registry import handler_for

    ours_out = folder / ("ours" + EXT[fmt])
    bare_out = folder / ("bare" + (".txt" if fmt == "bvh" else EXT[fmt]))
    handler = handler_for(ours_out, "write")
    rows = []
    if asset.clips:
        handler.write(asset, ours_out)
        if fmt == "bvh":
            values = bare_read_bvh(ours_out)  # the numbers usdhands writes
            bare_write = lambda: bare_write_bvh(values, bare_out)  # noqa: E731
        else:
            bare_write = lambda: globals()[f"bare_write_{fmt}"](asset, bare_out)  # noqa: E731
        t = medians(repeat, {"ours": lambda: handler.write(asset, ours_out), "bare": bare_write}, budget)
        rows.append(("write", t["ours"], t["bare"]))
    reader = handler_for(source, "read")
    from usdhands.formats.gltf_container import clear_decoded_cache

    def ours_read():
        clear_decoded_cache()  # every read decodes its glTF JSON, as a first read does
        reader.read(source)

    if fmt != "bvh":
        t = medians(repeat, {"ours": ours_read, "bare": lambda: globals()[f"bare_read_{fmt}"](source)}, budget)
        rows.insert(0, ("read", t["ours"], t["bare"]))
        return rows
    import usdhands.formats.bvh as bvh

    def bvh_read(compiled: bool):
        def read():
            bvh.USE_COMPILED = compiled
            try:
                reader.read(source)
            finally:
                bvh.USE_COMPILED = None
        return read

    bvh_read(True)()  # the kernels loaded (compiled on a first run), not timed
    t = medians(repeat, {"compiled": bvh_read(True), "numpy": bvh_read(False), "bare": lambda: bare_read_bvh(source)},
                budget)
    rows[:0] = [("read", t["compiled"], t["bare"]), ("read.np", t["numpy"], t["bare"])]
    return rows


def real_files() -> list[Path]:
    shared = ROOT.parent / "shared" / "assets"
    found = sorted(p for p in shared.rglob("*") if format_of(p)) if shared.is_dir() else []
    samples = [ROOT / "sample_assets" / n for n in (
        "conversation.glb", "conversation_bodyonly.glb", "conversation_bodyonly.bvh", "conversation_bodyonly.usdc",
        "humanoid.glb", "humanoid.bvh", "humanoid.usda", "gestures/ok_01.glb")]
    return found + [p for p in samples if p.exists()]


def print_row(name: str, fmt: str, op: str, ours: tuple, bare: tuple) -> float:
    """One table row: CPU medians and their ratio, then the ratios of wall and of main-thread CPU medians."""
    ratio = ours[0] / bare[0]
    print(f"{name:<34}{fmt:<6}{op:<7}{ours[0] * 1e3:>11.1f}{bare[0] * 1e3:>9.1f}{ratio:>7.2f}"
          f"{ours[1] / bare[1]:>7.2f}{ours[2] / bare[2]:>7.2f}{'' if ratio <= GOAL else '  over ' + str(GOAL)}")
    return ratio


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--joints", type=int, default=65)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--formats", nargs="*", default=list(EXT), choices=list(EXT))
    ap.add_argument("--no-real", action="store_true", help="only the generated clip")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from usdhands.formats.io import read_asset
    from usdhands.model.asset import Asset

    clip = make_clip(args.frames, args.joints)
    generated = Asset("generated", (clip.skeleton,), (clip,))
    head = f"{'file':<34}{'fmt':<6}{'op':<7}{'usdhands ms':>11}{'bare ms':>9}{'ratio':>7}{'wall':>7}{'main':>7}"
    ratios: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
        print(f"generated clip: {args.frames} frames x {args.joints} joints; medians of {args.repeat}, "
              f"usdhands and bare taking turns; CPU ms, ratio of CPU times, of wall times, of main-thread CPU")
        print(head)
        for fmt in args.formats:
            src = folder / ("generated" + EXT[fmt])
            from usdhands.formats.registry import handler_for

            handler_for(src, "write").write(generated, src)
            for op, ours, bare in bench_file(fmt, src, generated, folder, args.repeat):
                print_row(f"generated {args.frames}x{args.joints}", fmt, op, ours, bare)
            back = read_asset(src).clips[0]
            order = [back.skeleton.index(n) for n in clip.skeleton.short_names]  # BVH is depth-first
            err = float(np.abs(np.abs((back.rotations[:, order] * clip.rotations).sum(-1)) - 1).max())
            print(f"{'':<34}{fmt:<6}check: read back, max |1 - |q.q'|| = {err:.1e}")
        if args.no_real:
            return 0
        repeat = max(args.repeat, 15)
        print(f"\nreal files: medians of {repeat} rounds or more (until 1.5 s per operation, at most "
              f"{20 * repeat}); each read, and its asset written again in its format")
        print(head)
        for path in real_files():
            fmt = format_of(path)
            if fmt not in args.formats:
                continue
            asset = read_asset(path)
            name = str(path.relative_to(ROOT.parent)) if path.is_relative_to(ROOT.parent) else path.name
            if len(name) > 33:
                name = "..." + name[-30:]
            for op, ours, bare in bench_file(fmt, path, asset, folder, repeat, budget=1.5):
                ratios.setdefault((fmt, op), []).append(print_row(name, fmt, op, ours, bare))
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print("\nreal files, median ratio per format and operation:")
    for (fmt, op), r in sorted(ratios.items()):
        print(f"  {fmt:<5}{op:<6}{statistics.median(r):6.2f}  (over {len(r)} files, worst {max(r):.2f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""glTF 2.0 writers: a new file from an :class:`~usdhands.model.asset.Asset`, and a
source file with one animation's channels added or replaced (everything else kept).

glTF is metres and +Y up: assets in other units or Z up are converted with
:mod:`usdhands.model.units` (translations rescaled; a -90° rotation about X folded
into the root joints' rest pose and every frame, and into bind and mesh
transforms), so no extra node appears.
"""

from __future__ import annotations

import base64
import os
from dataclasses import replace
import urllib.parse
from pathlib import Path
from typing import Sequence

import numpy as np
import pygltflib

from usdhands.errors import AssetReadError, JointMismatchError, OutputPathError
from usdhands.formats.gltf_container import (
    BinaryAppender, GltfFile, contained_file, load_gltf, read_external, save_gltf,
)
from usdhands.formats.gltf_read import (
    EXTRAS_KEY, GltfScene, SkeletonBinding, animation_channels, channel_keys, malformed_as_read_error, sample_channel,
    scan_scene, snap_time,
)
from usdhands.model.asset import Asset, RootNode, SkinnedMesh
from usdhands.model.clip import Clip
from usdhands.model.provenance import provenance_record
from usdhands.formats.gltf_materials import write_materials
from usdhands.model.rotations import quat_angle_deg, trs_to_xform, xform_to_trs
from usdhands.model.skeleton import Skeleton, short_joint_name
from usdhands.model.units import asset_to, clip_to, skeleton_to

__all__ = ["write_gltf", "write_clip_gltf", "clip_to_gltf_space", "ROTATION_TOLERANCE_DEG", "TRANSLATION_TOLERANCE_M"]

ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963
#: A joint's channel is rewritten by ``write_clip`` when the clip differs from the file
#: by more than this at some frame (geodesic angle, degrees) ...
ROTATION_TOLERANCE_DEG = 1e-3
#: ... or by more than this in translation (metres) or scale (relative).
TRANSLATION_TOLERANCE_M = 1e-6
SCALE_TOLERANCE = 1e-6



# -- units and axes ------------------------------------------------------------

def clip_to_gltf_space(clip: Clip) -> Clip:
    """``clip`` in metres and +Y up (roots re-oriented, see :mod:`usdhands.model.units`)."""
    sk = clip.skeleton
    if sk.meters_per_unit == 1.0 and sk.up_axis == "Y":
        return clip
    return clip_to(clip, skeleton_to(sk, 1.0, "Y"))


# -- animation data ----------------------------------------------------------------

def _unit(q: np.ndarray) -> np.ndarray:
    """``q`` scaled to length 1 unless it is within 1e-6 of it already."""
    n = float(np.linalg.norm(q))
    return q if abs(n - 1.0) <= 1e-6 else q / n


def _continuous(q: np.ndarray) -> np.ndarray:
    """Unit quaternions, signs flipped along time (axis 0) so neighbours have a non-negative dot product.

    glTF requires unit rotations: a USD quaternion of magnitude 1e38 was written as it was
    and failed the Khronos validator.
    """
    q, flips = _continuous_flips(q)
    if flips is None:
        return q
    return q * np.where(flips, -1.0, 1.0)[..., None]


#: Largest difference between two sums of the four products of a dot product of quaternions of
#: length at most 1 + 1e-6, in any order and with or without fused multiply-adds, is a few 1e-16:
#: dot products closer to 0 than this are summed again left to right before their sign is taken.
_DOT_SIGN_MARGIN = 1e-12


def _apart(a: np.ndarray, b: np.ndarray, out: np.ndarray, near_unit: bool) -> None:
    """``out`` (bool) = the dot products of quaternions ``a`` and ``b`` ``(..., 4)``, summed left to
    right, below 0 (NaN is not).

    With ``near_unit`` (every quaternion of length within 1e-6 of 1, or NaN) einsum sums them (in
    its own order, faster) and the sums within :data:`_DOT_SIGN_MARGIN` of 0 are summed again left
    to right: the signs are the left-to-right sums' everywhere.
    """
    if near_unit:
        d = np.einsum("...i,...i->...", a, b)
        near = np.flatnonzero(~(np.abs(d) > _DOT_SIGN_MARGIN))
        if near.size:
            at = np.unravel_index(near, d.shape)
            d[at] = _dot_left_to_right(a[at], b[at])
    else:
        d = _dot_left_to_right(a, b)
    np.less(d, 0.0, out=out)


def _dot_left_to_right(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = a[..., 0] * b[..., 0]  # summed left to right, as np.sum does (in place: no temporaries)
    for k in (1, 2, 3):
        d += a[..., k] * b[..., k]
    return d


def _continuous_flips(q: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`_continuous` as the unit quaternions and where ``(T, ...)`` bool each is to be
    multiplied by -1 (None: no flip), for a writer that applies them as it converts.

    A frame flips where an odd number of neighbours up to it point apart (the dot product
    of a quaternion and the one before it, summed left to right, below 0).
    """
    q = np.asarray(q)
    square = np.einsum("...i,...i->...", q, q)
    # |n² - 1| <= 1e-6 means |n - 1| < 1e-6: the norms themselves are needed only otherwise
    square -= 1.0
    worst = np.abs(square, out=square).max(initial=0.0)
    near_unit = bool(worst <= 1e-6)  # not with NaN: then nothing is normalised (the maximum is NaN)
    if worst > 1e-6:
        norms = np.linalg.norm(q, axis=-1, keepdims=True)
        if np.abs(norms - 1.0).max(initial=0.0) > 1e-6:  # unit ones are written as they are (same bytes as before)
            q = q / norms
        near_unit = True  # of length 1 within 1e-6 now, or NaN (zero length)
    if q.shape[0] < 2:
        return q, None
    apart = np.empty((q.shape[0] - 1,) + q.shape[1:-1], dtype=bool)
    _apart(q[1:], q[:-1], apart, near_unit)
    if not apart.any():
        return q, None
    flips = np.empty(q.shape[:-1], dtype=bool)
    flips[0] = False
    np.logical_xor.accumulate(apart, axis=0, out=flips[1:])
    return q, flips


#: Rows of +1 and -1 picked by a flip (False, True) as a bool's byte: the factors of a channel's values.
_SIGN_ROWS = np.array([[1.0] * 4, [-1.0] * 4], dtype=np.float32)


def _records(a: np.ndarray) -> np.ndarray:
    """A C-contiguous ``(..., C)`` float32 array as ``(...)`` records of C floats (moved whole, not float by float)."""
    return a.view(np.dtype((np.void, a.shape[-1] * a.itemsize))).reshape(a.shape[:-1])


def _float32_channels(values: np.ndarray, flips: np.ndarray | None = None) -> np.ndarray:
    """``values`` (T, K, C) float as ``(K, T, C)`` float32, C-contiguous (one joint's keys after
    another), each number rounded as ``astype`` rounds it and, where ``flips`` (T, K) bool is True,
    multiplied by -1 (rounding and a sign flip commute: the same bytes as flipping first).

    Rounded in place, then whole records of C floats moved: a float-by-float transposition is
    3-4 times slower.
    """
    T, K, C = values.shape
    out = np.empty((K, T, C), dtype=np.float32)
    if out.size == 0:
        return out
    rounded = np.asarray(values).astype(np.float32, order="C")
    if flips is not None:
        factors = out.reshape(T, K, C)  # out's memory as scratch until the values move in
        np.take(_SIGN_ROWS[:, :C], flips.view(np.uint8), axis=0, out=factors)
        rounded *= factors
    np.copyto(_records(out), _records(rounded).T)
    return out


#: Bytes of float64 quaternions :func:`_rotation_channels` takes at a time (its temporaries stay in cache).
_BLOCK_BYTES = 1 << 20


def _rotation_channels(q: np.ndarray) -> np.ndarray:
    """``(T, J, 4)`` rotations as the writer stores them, ``(J, T, 4)`` float32: the same bytes as
    ``_float32_channels(*_continuous_flips(q))``, made a block of frames at a time.

    Each block is checked for unit length, its neighbours' signs found, rounded, flipped and
    moved into place while it is in the processor's cache: the float64 quaternions are read
    once instead of about eight times (10,000 x 65 in a write: ~20 ms against ~27, under load). Where a
    quaternion is not of unit length the whole-array functions normalise them all.
    """
    q = np.asarray(q)
    if q.ndim != 3 or q.shape[0] < 2 or q.shape[1] == 0 or not q.flags.c_contiguous:
        return _float32_channels(*_continuous_flips(q))
    T, J = q.shape[:2]
    out = np.empty((J, T, 4), dtype=np.float32)
    placed = _records(out)
    step = max(16, _BLOCK_BYTES // (32 * J))
    flips = np.empty((step, J), dtype=bool)
    factors = np.empty((step, J, 4), dtype=np.float32)
    rounded = np.empty((step, J, 4), dtype=np.float32)
    carry = np.zeros(J, dtype=bool)
    worst, nan, unit_before = 0.0, False, True
    for t0 in range(0, T, step):
        t1 = min(t0 + step, T)
        n = t1 - t0
        block = q[t0:t1]
        square = np.einsum("...i,...i->...", block, block)
        square -= 1.0
        most = float(np.abs(square, out=square).max())
        nan |= most != most
        worst = max(worst, most)
        unit = most <= 1e-6  # False for NaN
        f = flips[:n]
        lo = max(t0, 1)  # the pairs (t - 1, t) ending in this block, the first with the last frame before it
        _apart(q[lo:t1], q[lo - 1:t1 - 1], f[1:] if t0 == 0 else f, unit and unit_before)
        unit_before = unit
        if t0 == 0:
            f[0] = False
        else:
            f[0] ^= carry
        np.logical_xor.accumulate(f, axis=0, out=f)
        carry[:] = f[-1]
        r = rounded[:n]
        np.copyto(r, block, casting="same_kind")
        np.take(_SIGN_ROWS, f.view(np.uint8), axis=0, out=factors[:n])
        r *= factors[:n]
        np.copyto(placed[:, t0:t1], _records(r).T)
    if worst > 1e-6 and not nan:  # _continuous_flips normalises them all (not where some are NaN)
        return _float32_channels(*_continuous_flips(q))
    return out


def _key_times(clip: Clip) -> np.ndarray:
    """Frame times as float32, shifted to start at 0 when the clip starts before 0."""
    t = clip.times
    if t.size and t[0] < 0:
        t = t - t[0]
    t32 = t.astype(np.float32)
    if t32.size > 1 and not np.all(np.diff(t32) > 0):
        raise ValueError(f"clip {clip.name!r}: frame times do not increase in float32 "
                         f"({clip.num_frames} frames at {clip.fps} fps from {clip.start_time} s)")
    return t32


def _cubic_values(values: np.ndarray, times: np.ndarray) -> np.ndarray:
    """CUBICSPLINE sampler output ``(3T, ...)``: (in-tangent, value, out-tangent) per key, the tangents
    the finite-difference slopes of the values (per second), so the spline passes through every frame."""
    if len(times) < 2:
        slope = np.zeros_like(values)
    else:
        slope = np.gradient(values, times.astype(np.float64), axis=0)
    out = np.empty((3 * values.shape[0],) + values.shape[1:], dtype=values.dtype)
    out[0::3], out[1::3], out[2::3] = slope, values, slope
    return out


class _AnimationWriter:
    """Adds samplers and channels for per-joint arrays of one clip to an animation."""

    def __init__(self, app: BinaryAppender, animation: pygltflib.Animation, times: np.ndarray,
                 interpolation: str = "LINEAR"):
        self.app = app
        self.anim = animation
        self.times = times
        self.interpolation = interpolation if interpolation in ("STEP", "CUBICSPLINE") else "LINEAR"
        self.input = app.add_accessor(times.reshape(-1, 1), "SCALAR", min_max=True)

    def _sampler(self, output: int) -> int:
        self.anim.samplers.append(pygltflib.AnimationSampler(input=self.input, output=output,
                                                             interpolation=self.interpolation))
        return len(self.anim.samplers) - 1

    def add_weights(self, node: int, values: np.ndarray) -> None:
        """A ``weights`` channel on a morphed mesh node: ``values`` (T, B)."""
        data = np.asarray(values, dtype=np.float32)
        if self.interpolation == "CUBICSPLINE":
            data = _cubic_values(data, self.times)
        acc = self.app.add_accessor(data.reshape(-1, 1), "SCALAR")
        self.anim.channels.append(pygltflib.AnimationChannel(
            sampler=self._sampler(acc), target=pygltflib.AnimationChannelTarget(node=node, path="weights")))

    def add(self, path: str, joints: list[int], nodes: list[int], values: np.ndarray,
            replace: dict[tuple[int, str], int] | None = None, flips: np.ndarray | None = None) -> None:
        """Channels for ``joints`` (indices into ``values`` axis 1) targeting ``nodes``.

        Parameters
        ----------
        values : (T, J, C) float
        replace : dict (node, path) -> channel index
            Existing channels to point at the new samplers instead of appending.
        flips : (T, J) bool, optional
            Where a value is multiplied by -1 (:func:`_continuous_flips`), applied to the
            float32 values (no float64 copy of the flipped values).
        """
        if not joints:
            return
        every = len(joints) == values.shape[1] and joints == list(range(values.shape[1]))
        chosen = values if every else values[:, joints]
        self.add_packed(path, nodes, _float32_channels(chosen, None if flips is None else flips if every
                                                       else flips[:, joints]), replace)

    def add_packed(self, path: str, nodes: list[int], data: np.ndarray,
                   replace: dict[tuple[int, str], int] | None = None) -> None:
        """Channels targeting ``nodes`` of the values ``data`` (K, T, C) float32 (:func:`_float32_channels`)."""
        if self.interpolation == "CUBICSPLINE":
            data = np.ascontiguousarray(_cubic_values(data.transpose(1, 0, 2), self.times).transpose(1, 0, 2))
        T, C = data.shape[1], data.shape[2]
        view = self.app.add_view(memoryview(data).cast("B"))  # the array's bytes, not a copy of them
        type_ = {3: "VEC3", 4: "VEC4"}[C]
        for k, node in enumerate(nodes):
            acc = self.app.add_accessor(data[k], type_, view=view, byte_offset=k * T * C * 4)
            s = self._sampler(acc)
            existing = None if replace is None else replace.get((node, path))
            if existing is not None:
                self.anim.channels[existing].sampler = s
            else:
                self.anim.channels.append(pygltflib.AnimationChannel(
                    sampler=s, target=pygltflib.AnimationChannelTarget(node=node, path=path)))


def _record(anim: pygltflib.Animation, key: str, value) -> None:
    """Set ``anim.extras["usdhands"][key]`` (other extras kept)."""
    extras = anim.extras if isinstance(anim.extras, dict) else {}
    ours = extras.get(EXTRAS_KEY) if isinstance(extras.get(EXTRAS_KEY), dict) else {}
    anim.extras = {**extras, EXTRAS_KEY: {**ours, key: value}}


def _record_fps(anim: pygltflib.Animation, fps: float) -> None:
    """Record the clip's exact frame rate in ``extras.usdhands.fps``."""
    _record(anim, "fps", float(fps))


def _record_provenance(anim: pygltflib.Animation, record: dict | None) -> None:
    """Record how the finger motion was made in ``extras.usdhands.provenance`` (nothing for None)."""
    if record is not None:
        _record(anim, "provenance", provenance_record(record))


def _differs_from_rest(values: np.ndarray, rest: np.ndarray, tol: float) -> np.ndarray:
    """Per joint: whether ``values (T, J, 3)`` leave ``rest (J, 3)`` anywhere (relative tolerance)."""
    if values.shape[0] == 0:
        return np.zeros(values.shape[1], dtype=bool)
    limit = tol * np.maximum(1.0, np.abs(rest))
    # |v - rest| > limit at some frame  <=>  max(v) - rest > limit or rest - min(v) > limit (rounding is
    # monotonic); fmax/fmin skip NaN as the comparison does
    over = np.fmax.reduce(values, axis=0) - rest > limit
    under = rest - np.fmin.reduce(values, axis=0) > limit
    return np.any(over | under, axis=-1)


# -- new files ---------------------------------------------------------------------

def write_gltf(asset: Asset, path: str | os.PathLike, *, provenance: dict | None = None, **options) -> None:
    """Write ``asset`` as a new ``.gltf`` (buffers embedded as data URIs) or ``.glb``.

    Every skeleton becomes a node tree with a skin (inverse bind matrices), every
    skinned mesh a triangle mesh, every clip an animation with LINEAR samplers keyed
    at its frames (animation names are the clip names' last path element, unless two
    clips share it). Translation and scale channels that never leave the node's rest
    value are left out (a reader falls back to the node, so the motion is the same);
    rotation channels are written for every joint.

    Parameters
    ----------
    asset : Asset
    path : path-like
        ``.glb`` for binary, anything else for JSON.
    provenance : dict, optional
        How the finger motion of every clip was made, recorded in each animation's
        ``extras.usdhands.provenance``; by default the asset's record of each clip.
    """
    options.pop("final_path", None)  # images are embedded: where the file ends up does not matter
    if options:
        raise TypeError(f"unexpected options for glTF write: {sorted(options)}")
    path = Path(path)
    if any(sk.meters_per_unit != 1.0 or sk.up_axis != "Y" for sk in asset.skeletons):
        asset = asset_to(asset, 1.0, "Y")
    asset, chains = _unfold_root_nodes(asset)
    gltf = pygltflib.GLTF2(asset=pygltflib.Asset(generator="usdhands", version="2.0"))
    gltf.buffers = [pygltflib.Buffer(byteLength=0)]
    app = BinaryAppender(gltf, 0)
    scene_nodes: list[int] = []
    skel_nodes: list[list[int]] = []
    skel_skins: list[int] = []
    skin_slot: list[np.ndarray] = []
    chain_nodes: list[tuple[int, int, RootNode]] = []  # skeleton index, node index, the node above it
    index_of = {id(s): i for i, s in enumerate(asset.skeletons)}
    for k, sk in enumerate(asset.skeletons):
        base = len(gltf.nodes)
        nodes = list(range(base, base + sk.num_joints))
        for j in range(sk.num_joints):
            gltf.nodes.append(pygltflib.Node(
                name=short_joint_name(sk.joint_names[j]),
                translation=[float(v) for v in sk.rest_translations[j]],
                rotation=[float(v) for v in _unit(sk.rest_rotations[j])],
                scale=[float(v) for v in sk.rest_scales[j]]))
        above = None
        for node in chains.get(k, ()):
            t, q, sc = xform_to_trs(node.local if node.rest is None else node.rest)
            gltf.nodes.append(pygltflib.Node(name=node.name, translation=[float(v) for v in t],
                                             rotation=[float(v) for v in _unit(q)], scale=[float(v) for v in sc]))
            chain_nodes.append((k, len(gltf.nodes) - 1, node))
            if above is None:
                scene_nodes.append(len(gltf.nodes) - 1)
            else:
                gltf.nodes[above].children.append(len(gltf.nodes) - 1)
            above = len(gltf.nodes) - 1
        for j, p in enumerate(sk.parents):
            if p < 0 and above is None:
                scene_nodes.append(nodes[j])
            elif p < 0:
                gltf.nodes[above].children.append(nodes[j])
            else:
                gltf.nodes[nodes[p]].children.append(nodes[j])
        in_skin = _skin_joints(sk, asset.non_skin_joints.get(k, ()), [m for m in asset.meshes
                                                                      if m.skeleton_index == k])
        slot = np.full(sk.num_joints, -1, dtype=np.int64)
        slot[in_skin] = np.arange(len(in_skin))
        skin_slot.append(slot)
        bind = sk.bind_xforms if sk.bind_xforms is not None else sk.rest_world_xforms()
        ibm = np.linalg.inv(bind[in_skin]).transpose(0, 2, 1).reshape(-1, 16).astype(np.float32)
        acc = app.add_accessor(ibm, "MAT4")
        roots = [nodes[j] for j in range(sk.num_joints) if sk.parents[j] < 0]
        gltf.skins.append(pygltflib.Skin(name=sk.name.rsplit("/", 1)[-1] or None, joints=[nodes[j] for j in in_skin],
                                         inverseBindMatrices=acc, skeleton=roots[0] if len(roots) == 1 else None))
        skel_nodes.append(nodes)
        skel_skins.append(len(gltf.skins) - 1)

    material_index = write_materials(gltf, app, asset.materials, asset.images)
    morph_nodes = _write_meshes(gltf, app, asset, skel_nodes, skel_skins, scene_nodes, material_index, skin_slot)

    # the name recorded where the source could not hold it, else a USD prim path's last element
    shorts = [asset.source_names.get(c.name) or c.name.rsplit("/", 1)[-1] for c in asset.clips]
    for clip, short in zip(asset.clips, shorts):
        si = index_of.get(id(clip.skeleton))
        if si is None:
            si = next((i for i, s in enumerate(asset.skeletons) if s.joint_names == clip.skeleton.joint_names), None)
        if si is None:
            raise ValueError(f"clip {clip.name!r} is on a skeleton that is not in the asset")
        sk = asset.skeletons[si]
        c = clip_to_gltf_space(clip)
        anim = pygltflib.Animation(name=short if shorts.count(short) == 1 else clip.name)
        _record_fps(anim, c.fps)
        _record_provenance(anim, provenance if provenance is not None else asset.provenance.get(clip.name))
        kind = asset.interpolation.get(clip.name, "LINEAR")
        sel = _key_frames(c, asset.key_times.get(clip.name))
        w = _AnimationWriter(app, anim, _key_times(c)[sel], kind)
        J = sk.num_joints
        nodes = skel_nodes[si]
        if isinstance(sel, slice):  # every frame (the usual case): made a block of frames at a time
            w.add_packed("rotation", nodes, _rotation_channels(c.rotations))
        else:
            q, flips = _continuous_flips(c.rotations)
            w.add("rotation", list(range(J)), nodes, q[sel], flips=None if flips is None else flips[sel])
        for path_, values, rest, tol in (("translation", c.translations, sk.rest_translations, TRANSLATION_TOLERANCE_M),
                                         ("scale", c.scales, sk.rest_scales, SCALE_TOLERANCE)):
            moving = [j for j in np.nonzero(_differs_from_rest(values, rest, tol))[0]]
            w.add(path_, moving, [nodes[j] for j in moving], values[sel])
        _add_node_motion(w, [(n, node) for k, n, node in chain_nodes if k == si], clip, sel)
        shapes = asset.blend_shape_weights.get(clip.name)
        for node, (k, names, defaults) in morph_nodes.items():
            if k != si or shapes is None or not set(names) & set(shapes.names):
                continue
            col = {n: i for i, n in enumerate(shapes.names)}
            values = np.stack([shapes.weights[:, col[n]] if n in col else np.full(c.num_frames, d)
                               for n, d in zip(names, defaults)], axis=1)
            w.add_weights(node, values[sel])
        gltf.animations.append(anim)

    gltf.scenes = [pygltflib.Scene(nodes=scene_nodes)]
    gltf.scene = 0
    buffers: list[bytes] = []
    data = app.finish(buffers)
    if not data:
        gltf.buffers = []
        buffers = []
    save_gltf(gltf, buffers, path, glb=path.suffix.lower() == ".glb")


def _add_node_motion(w: _AnimationWriter, nodes: Sequence[tuple[int, RootNode]], clip: Clip,
                     sel: slice | np.ndarray) -> None:
    """Translation, rotation and scale channels for each node above the skeleton that moves in
    ``clip`` (the components that leave the node's rest), at the frames ``sel``."""
    for index, node in nodes:
        m = _node_motion(node, clip)
        if m is None:
            continue
        rest = xform_to_trs(node.local if node.rest is None else node.rest)
        t, q, sc = xform_to_trs(m)
        q = _continuous(q[:, None])[:, 0]
        if quat_angle_deg(q, rest[1]).max(initial=0.0) > 1e-4:
            w.add("rotation", [0], [index], q[sel][:, None])
        for path_, values, r, tol in (("translation", t, rest[0], TRANSLATION_TOLERANCE_M),
                                      ("scale", sc, rest[2], SCALE_TOLERANCE)):
            if _differs_from_rest(values[:, None], r[None], tol)[0]:
                w.add(path_, [0], [index], values[sel][:, None])


def _triangulate(counts: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Fan triangulation of polygons, ``(F', 3)`` vertex indices."""
    counts = np.asarray(counts, dtype=np.int64)
    indices = np.asarray(indices, dtype=np.int64)
    if np.all(counts == 3):
        return indices.reshape(-1, 3)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    ntri = np.maximum(counts - 2, 0)
    face = np.repeat(np.arange(counts.size), ntri)
    k = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri) + 1
    s = starts[face]
    return np.stack([indices[s], indices[s + k], indices[s + k + 1]], axis=1)


def _clean_influences(ji: np.ndarray, jw: np.ndarray, num_joints: int) -> tuple[np.ndarray, np.ndarray]:
    """Influences as glTF wants them: unique joints per vertex, zero weights on joint 0,
    heaviest first, rows normalised in float32 (the validator sums in float32), width a
    multiple of 4."""
    ji = np.asarray(ji, dtype=np.int64)
    jw = np.clip(np.asarray(jw, dtype=np.float64), 0.0, None)
    V, K = ji.shape
    if np.any((ji < 0) | (ji >= num_joints)):
        raise ValueError(f"joint indices must be in 0..{num_joints - 1}, got {int(ji.min())}..{int(ji.max())}")
    # merge repeated joints of a vertex: sort by joint, sum runs
    order = np.argsort(ji, axis=1, kind="stable")
    ji = np.take_along_axis(ji, order, 1)
    jw = np.take_along_axis(jw, order, 1)
    for k in range(1, K):
        same = ji[:, k] == ji[:, k - 1]
        jw[same, k] += jw[same, k - 1]
        jw[same, k - 1] = 0.0
    total = jw.sum(axis=1)
    empty = total <= 0
    jw[empty, 0] = 1.0  # an unweighted vertex follows the first joint
    ji[empty, 0] = 0
    jw /= jw.sum(axis=1, keepdims=True)
    order = np.argsort(-jw, axis=1, kind="stable")
    ji = np.take_along_axis(ji, order, 1)
    jw = np.take_along_axis(jw, order, 1)
    used = max(1, int((jw > 0).sum(axis=1).max()))
    width = (used + 3) // 4 * 4
    ji = ji[:, :width] if K >= width else np.pad(ji, ((0, 0), (0, width - K)))
    jw = jw[:, :width] if K >= width else np.pad(jw, ((0, 0), (0, width - K)))
    jw /= jw.sum(axis=1, keepdims=True)
    ji = np.where(jw > 0, ji, 0)
    w32 = jw.astype(np.float32)
    for _ in range(4):  # nudge the heaviest weight until the float32 running sum is 1
        acc = np.cumsum(w32, axis=1, dtype=np.float32)[:, -1].astype(np.float64)
        n = (w32 > 0).sum(axis=1)
        bad = np.abs(acc - 1.0) > 2e-7 * n * 0.5
        if not bad.any():
            break
        w32[bad, 0] = (w32[bad, 0].astype(np.float64) - (acc[bad] - 1.0)).astype(np.float32)
    ji = np.where(w32 > 0, ji, 0)  # weights too small for float32 became 0: their joint must be 0 too
    return ji, w32


def _key_frames(clip: Clip, key_times: np.ndarray | None) -> slice | np.ndarray:
    """The frames to key: those at the source's key times (``Asset.key_times``) when every one of
    them is a frame of the clip (within a thousandth of a frame), else every frame."""
    if key_times is None or not len(key_times):
        return slice(None)
    x = (np.asarray(key_times, dtype=np.float64) - clip.start_time) * clip.fps
    k = np.round(x)
    if np.any(np.abs(x - k) > 1e-3) or k.min() < 0 or k.max() >= clip.num_frames:
        return slice(None)
    frames = np.unique(k.astype(np.int64))
    return slice(None) if len(frames) == clip.num_frames else frames


def _unfold_root_nodes(asset: Asset) -> tuple[Asset, dict]:
    """``asset`` with the transforms of ``asset.root_nodes`` taken back out of the root joints (rest,
    and every frame: a moving node's transform at that frame), and those nodes per skeleton index,
    for the writer to put above the roots."""
    if not asset.root_nodes:
        return asset, {}
    new_sk, chains = {}, {}
    skeletons = list(asset.skeletons)
    for k, chain in asset.root_nodes.items():
        if not 0 <= k < len(skeletons) or not chain:
            continue
        sk = skeletons[k]
        world = np.eye(4)
        for node in chain:
            world = world @ np.asarray(node.local, dtype=np.float64)
        inv = np.linalg.inv(world)
        roots = np.flatnonzero(sk.parents < 0)
        t, q, sc = (np.array(sk.rest_translations), np.array(sk.rest_rotations), np.array(sk.rest_scales))
        t[roots], q[roots], sc[roots] = xform_to_trs(inv @ trs_to_xform(t[roots], q[roots], sc[roots]))
        skeletons[k] = Skeleton(sk.joint_names, sk.parents, t, q, sc, sk.bind_xforms, sk.meters_per_unit,
                                sk.up_axis, sk.name)
        new_sk[id(sk)] = (skeletons[k], inv, roots, chain)
        chains[k] = chain
    clips = []
    for c in asset.clips:
        if id(c.skeleton) not in new_sk:
            clips.append(c)
            continue
        sk, inv, roots, chain = new_sk[id(c.skeleton)]
        inv = _chain_inverse_per_frame(chain, c, inv)
        t, q, sc = np.array(c.translations), np.array(c.rotations), np.array(c.scales)
        t[:, roots], q[:, roots], sc[:, roots] = xform_to_trs(inv @ trs_to_xform(t[:, roots], q[:, roots],
                                                                                  sc[:, roots]))
        clips.append(c.replace(skeleton=sk, translations=t, rotations=q, scales=sc))
    return replace(asset, skeletons=tuple(skeletons), clips=tuple(clips)), chains


def _node_motion(node: RootNode, clip: Clip) -> np.ndarray | None:
    """(F, 4, 4) ``node``'s local transform at each frame of ``clip``, None where it does not move in it."""
    m = None if node.motion is None else node.motion.get(clip.name)
    return m if m is not None and len(m) == clip.num_frames else None


def _chain_inverse_per_frame(chain: Sequence[RootNode], clip: Clip, inv: np.ndarray) -> np.ndarray:
    """The inverse of the chain's world transform: ``inv`` (4, 4) when no node moves in ``clip``,
    else (F, 1, 4, 4), one per frame, to take out of the root joints."""
    if all(_node_motion(n, clip) is None for n in chain):
        return inv
    world = np.broadcast_to(np.eye(4), (clip.num_frames, 4, 4))
    for n in chain:
        m = _node_motion(n, clip)
        world = world @ (np.asarray(n.local, dtype=np.float64) if m is None else m)
    return np.linalg.inv(world)[:, None]


def _skin_joints(sk: Skeleton, non_skin: Sequence[str], meshes: Sequence[SkinnedMesh]) -> list[int]:
    """The joints a skin lists: all but the ones the source had as plain nodes (``non_skin``) that
    no mesh point is weighted to (Blender's importer makes every skin joint a bone, and a bone
    cannot hold the scale of RobotExpressive's ``RobotArmature``)."""
    weighted = set()
    for m in meshes:
        if m.joint_indices is not None and m.joint_weights is not None:
            idx = np.asarray(m.joint_indices)
            weighted.update(np.unique(idx[np.asarray(m.joint_weights).reshape(idx.shape) != 0]).tolist())
    names = set(non_skin)
    keep = [j for j in range(sk.num_joints) if sk.joint_names[j] not in names or j in weighted]
    return keep or list(range(sk.num_joints))


def _write_meshes(gltf: pygltflib.GLTF2, app: BinaryAppender, asset: Asset, skel_nodes: list[list[int]],
                  skel_skins: list[int], scene_nodes: list[int], material_index: list[int],
                  skin_slot: list[np.ndarray]) -> dict:
    """Every mesh of ``asset`` as glTF meshes: the parts of one ``group`` (a source mesh's primitives)
    become one mesh with several primitives; a mesh following one joint rigidly becomes a mesh node
    below that joint's node, the others skinned nodes at the scene root.

    Returns
    -------
    dict node -> (skeleton index, blend shape names, default weights)
        The morphed mesh nodes, for the animations' ``weights`` channels.
    """
    groups: dict[tuple, list[SkinnedMesh]] = {}
    for mesh in asset.meshes:
        si = mesh.skeleton_index
        if not -1 <= si < len(asset.skeletons):
            raise ValueError(f"mesh {mesh.name!r} has skeleton_index {si}, the asset has {len(asset.skeletons)}")
        key = (si, mesh.group, mesh.node) if mesh.group is not None else (si, id(mesh), None)
        groups.setdefault(key, []).append(mesh)
    morph_nodes = {}
    for (si, _, node_name), parts in groups.items():
        joints = {m.rigid_joint() for m in parts}
        rigid = joints.pop() if len(joints) == 1 else None  # parts on different joints: a skinned mesh
        static = si < 0  # on no skeleton: a mesh node placed by its own transform
        sk = asset.skeletons[max(si, 0)]
        first = parts[0]
        short = asset.source_names.get(first.name) or first.name.rsplit("/", 1)[-1]
        mesh_name = first.group or short
        names = list(dict.fromkeys(b.name for m in parts for b in m.blend_shapes))
        defaults = []
        for n in names:
            defaults.append(next(b.default_weight for m in parts for b in m.blend_shapes if b.name == n))
        local = None
        if static:  # the parts of one source node share its transform
            local = np.asarray(first.geom_bind_xform, dtype=np.float64)
        elif rigid is not None:
            bind = sk.bind_xforms if sk.bind_xforms is not None else sk.rest_world_xforms()
            local = np.linalg.inv(bind[rigid]) @ np.asarray(first.geom_bind_xform, dtype=np.float64)
            if not all(np.allclose(np.linalg.inv(bind[rigid]) @ m.geom_bind_xform, local, atol=1e-9) for m in parts):
                local = None
                rigid = None
        prims = []
        for m in parts:
            xf = np.eye(4) if rigid is not None or static else np.asarray(m.geom_bind_xform, dtype=np.float64)
            mat = material_index[m.material] if m.material is not None and m.material < len(material_index) else None
            prims.append(_add_primitive(app, m, skin_slot[max(si, 0)], xf, rigid is None and not static, names, mat))
        extras = {}
        if names:
            extras["targetNames"] = [next((b.source_name or b.name) for m in parts for b in m.blend_shapes
                                          if b.name == n) for n in names]
        gltf.meshes.append(pygltflib.Mesh(name=mesh_name, primitives=prims, extras=extras,
                                          weights=[float(d) for d in defaults] if names else None))
        node = pygltflib.Node(name=node_name or mesh_name, mesh=len(gltf.meshes) - 1)
        if rigid is None and not static:
            node.skin = skel_skins[si]
            gltf.nodes.append(node)
            scene_nodes.append(len(gltf.nodes) - 1)
        else:
            t, q, sc = xform_to_trs(local)
            if not np.allclose(trs_to_xform(t, q, sc), local, atol=1e-6 * max(1.0, np.abs(local).max())):
                node.matrix = [float(v) for v in local.T.reshape(-1)]  # shear: the matrix as it is
            else:
                node.translation = [float(v) for v in t]
                node.rotation = [float(v) for v in _unit(q)]
                node.scale = [float(v) for v in sc]
            gltf.nodes.append(node)
            if static:
                scene_nodes.append(len(gltf.nodes) - 1)
            else:
                gltf.nodes[skel_nodes[si][rigid]].children.append(len(gltf.nodes) - 1)
        if names and not static:
            morph_nodes[len(gltf.nodes) - 1] = (si, names, defaults)
    return morph_nodes


def _add_primitive(app: BinaryAppender, mesh: SkinnedMesh, skin_slot: np.ndarray, xf: np.ndarray, skinned: bool,
                   target_names: list[str], material: int | None) -> pygltflib.Primitive:
    """One triangle primitive of ``mesh``, points moved by ``xf`` (4, 4); joints (``skin_slot``: each
    skeleton joint's place in the skin) and weights when ``skinned``; one morph target per name of
    ``target_names`` (zero where the mesh lacks it)."""
    pts = np.asarray(mesh.points, dtype=np.float64)
    pts = pts @ xf[:3, :3].T + xf[:3, 3]
    attrs = {"POSITION": app.add_accessor(pts.astype(np.float32), "VEC3", target=ARRAY_BUFFER, min_max=True)}
    lin = np.linalg.inv(xf[:3, :3]).T
    if mesh.normals is not None:
        n = np.asarray(mesh.normals, dtype=np.float64) @ lin.T
        length = np.linalg.norm(n, axis=1, keepdims=True)
        ok = (length[:, 0] > 1e-12) & np.isfinite(length[:, 0])
        n = np.where(ok[:, None], n / np.where(ok[:, None], length, 1.0), [0.0, 1.0, 0.0])
        attrs["NORMAL"] = app.add_accessor(n.astype(np.float32), "VEC3", target=ARRAY_BUFFER)
    if mesh.uvs is not None:
        uv = np.asarray(mesh.uvs, dtype=np.float64)
        uv = np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)
        attrs["TEXCOORD_0"] = app.add_accessor(uv.astype(np.float32), "VEC2", target=ARRAY_BUFFER)
    if skinned and mesh.joint_indices is not None and mesh.joint_weights is not None:
        num_joints = int(skin_slot.max()) + 1
        w = np.asarray(mesh.joint_weights)
        idx = skin_slot[np.asarray(mesh.joint_indices)]
        ji, jw = _clean_influences(np.where(idx >= 0, idx, 0), np.where(idx >= 0, w, 0.0), num_joints)
        jdtype = np.uint8 if num_joints <= 256 else np.uint16
        for s in range(ji.shape[1] // 4):
            attrs[f"JOINTS_{s}"] = app.add_accessor(ji[:, 4 * s:4 * s + 4].astype(jdtype), "VEC4",
                                                    target=ARRAY_BUFFER)
            attrs[f"WEIGHTS_{s}"] = app.add_accessor(jw[:, 4 * s:4 * s + 4], "VEC4", target=ARRAY_BUFFER)
    targets = []
    by_name = {b.name: b for b in mesh.blend_shapes}
    for name in target_names:
        b = by_name.get(name)
        off = np.zeros_like(pts) if b is None else np.asarray(b.offsets, dtype=np.float64) @ xf[:3, :3].T
        target = pygltflib.Attributes(POSITION=app.add_accessor(off.astype(np.float32), "VEC3", target=ARRAY_BUFFER,
                                                                min_max=True))
        if mesh.normals is not None and b is not None and b.normal_offsets is not None:
            dn = np.asarray(b.normal_offsets, dtype=np.float64) @ lin.T
            target.NORMAL = app.add_accessor(dn.astype(np.float32), "VEC3", target=ARRAY_BUFFER)
        targets.append(target)
    tri = _triangulate(mesh.face_vertex_counts, mesh.face_vertex_indices)
    idtype = np.uint16 if pts.shape[0] <= 65535 else np.uint32
    indices = app.add_accessor(tri.reshape(-1, 1).astype(idtype), "SCALAR", target=ELEMENT_ARRAY_BUFFER)
    return pygltflib.Primitive(attributes=pygltflib.Attributes(**attrs), indices=indices, mode=4,
                               targets=targets or None, material=material)


# -- a source file with one animation changed ------------------------------------------

def _find_binding(scene: GltfScene, clip: Clip, source: Path) -> SkeletonBinding:
    names = clip.skeleton.joint_names
    best, best_missing = None, None
    for b in scene.bindings:
        missing = [n for n in names if not b.skeleton.has_joint(n)]
        if not missing:
            return b
        if best_missing is None or len(missing) < len(best_missing):
            best, best_missing = b, missing
    if best is None:
        raise JointMismatchError("file has no skinned skeleton to write the animation to", path=source)
    shown = ", ".join(repr(n) for n in best_missing[:5]) + (" ..." if len(best_missing) > 5 else "")
    raise JointMismatchError(f"{len(best_missing)} joints of clip {clip.name!r} are not in the file's skeleton "
                             f"{best.skeleton.name!r}: {shown}", path=source)


def _find_animation(doc: GltfFile, clip: Clip, animation: str | int | None) -> tuple[int | None, str]:
    """Index of the animation to change (None for a new one) and the name of a new one."""
    anims = doc.gltf.animations
    names = [a.name or f"animation{i}" for i, a in enumerate(anims)]
    if isinstance(animation, int) or (isinstance(animation, str) and animation.isdigit() and animation not in names):
        i = int(animation)
        if not 0 <= i < len(anims):
            raise AssetReadError(f"animation index {i} out of range 0..{len(anims) - 1}", path=doc.path)
        return i, names[i]
    wanted = animation if animation is not None else clip.name
    if wanted in names:
        return names.index(wanted), wanted
    if animation is None and ":" in wanted and wanted.rsplit(":", 1)[0] in names:  # "Name:skeleton" of a reader
        return names.index(wanted.rsplit(":", 1)[0]), wanted
    return None, wanted


#: media type of an embedded image by file extension (glTF 2.0 core: PNG and JPEG; common extensions)
IMAGE_TYPES = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp",
               ".ktx2": "image/ktx2"}


def _carry_uri(uri: str | None, source: Path, out_dir: Path, what: str, location: str,
               content=None, media_type: str | None = None) -> str | None:
    """An external URI of ``source`` as the output in ``out_dir`` must spell it.

    Unchanged in the same folder; re-expressed from ``out_dir`` when the file lies
    inside it; otherwise embedded as a data URI of ``content()`` (a reference out of
    the output's folder would be refused on reading it back). Data URIs and None are
    unchanged.

    Raises
    ------
    AssetReadError
        The URI does not name a file inside ``source``'s folder
        (:func:`~usdhands.formats.gltf_container.contained_file`), or the file to
        embed cannot be read.
    """
    if uri is None or (isinstance(uri, str) and uri.startswith("data:")):
        return uri
    target = contained_file(source, uri, what, location)
    out_dir = out_dir.resolve()
    if source.parent.resolve() == out_dir:
        return uri
    if target.is_relative_to(out_dir):
        rel = target.relative_to(out_dir).as_posix()
        return urllib.parse.quote(rel)
    data = content() if content is not None else read_external(source, uri, what, location)
    kind = media_type or IMAGE_TYPES.get(target.suffix.lower(), "application/octet-stream")
    return f"data:{kind};base64," + base64.b64encode(data).decode("ascii")


def write_clip_gltf(source: str | os.PathLike, clip: Clip, path: str | os.PathLike, *,
                    final_path: str | os.PathLike | None = None, animation: str | int | None = None,
                    provenance: dict | None = None, **options) -> None:
    """Copy ``source`` to ``path`` with ``clip`` written into one of its animations.

    The animation is ``animation`` (name or index) or, when None, the one named like
    the clip; when there is none, a new animation of that name is added. In it, every
    joint channel whose values differ from the clip at some frame (beyond
    :data:`ROTATION_TOLERANCE_DEG` / :data:`TRANSLATION_TOLERANCE_M`) is replaced by
    a LINEAR channel keyed at the clip's frames, and joints the animation does not
    key yet (finger joints, typically) get channels where the clip leaves their rest
    value. Nothing else changes: meshes, materials, morph targets, skins, images,
    extensions, extras, other animations and unchanged channels keep their JSON and
    their bytes. New data is appended to the GLB binary chunk (``.glb``) or to a new
    data-URI buffer (``.gltf``); replaced channels' old accessors stay in the file,
    unused.

    Parameters
    ----------
    source : path-like
        A ``.gltf`` or ``.glb`` file.
    clip : Clip
        On the file's skeleton (joint names as :func:`read_gltf` gives them).
    path : path-like
        Where to write (may be a temporary file; see ``final_path``).
    final_path : path-like, optional
        The file's final location, used to re-express relative URIs of external
        buffers and images when it is in another folder than ``source``.
    animation : str or int, optional
    provenance : dict, optional
        How the finger motion was made, recorded in the animation's
        ``extras.usdhands.provenance`` (even when no channel changed).
    as_layer : bool, optional
        Only False is accepted (override layers are a USD feature).

    Raises
    ------
    JointMismatchError
        The clip names joints the file's skeletons do not have.
    OutputPathError
        ``as_layer=True``.
    """
    if options.pop("as_layer", False):
        raise OutputPathError("an override layer (--as-layer, as_layer) needs a USD output (.usd, .usda, .usdc); "
                              "glTF files are written whole", path=final_path or path)
    if options:
        raise TypeError(f"unexpected options for glTF write_clip: {sorted(options)}")
    source = Path(source)
    path = Path(path)
    final = Path(final_path) if final_path is not None else path
    doc = load_gltf(source)
    with malformed_as_read_error(source):
        scene = scan_scene(doc)
    binding = _find_binding(scene, clip, source)
    g = doc.gltf
    for i, b in enumerate(g.buffers):
        b.uri = _carry_uri(b.uri, source, final.parent, "buffer", f"buffers[{i}]", content=lambda i=i: doc.buffers[i],
                           media_type="application/octet-stream")
    for i, im in enumerate(g.images):
        im.uri = _carry_uri(im.uri, source, final.parent, "image", f"images[{i}]", media_type=im.mimeType)
    sk = binding.skeleton
    clip = clip_to_gltf_space(clip)
    ai, new_name = _find_animation(doc, clip, animation)

    times = _key_times(clip)
    at = times.astype(np.float64)
    cj = [sk.index(n) for n in clip.skeleton.joint_names]          # file joint of each clip joint
    nodes = [binding.nodes[j] for j in cj]
    existing: dict[tuple[int, str], int] = {}
    if ai is not None:
        for c, j, p in animation_channels(doc, ai, binding):
            existing[(binding.nodes[j], p)] = c

    def file_values(path_: str, k: int) -> np.ndarray:
        node = nodes[k]
        c = existing.get((node, path_))
        if c is None:
            rest = {"rotation": sk.rest_rotations, "translation": sk.rest_translations, "scale": sk.rest_scales}
            return np.broadcast_to(rest[path_][cj[k]], (at.size, 4 if path_ == "rotation" else 3))
        kt, kv, interp = channel_keys(doc, ai, c)
        return sample_channel(kt, kv, interp, at, path_ == "rotation", snap_time(clip.fps))

    def other_span(path_: str, k: int) -> bool:
        """The file's channel is keyed over another time range than the clip (a trimmed or longer clip)."""
        c = existing.get((nodes[k], path_))
        if c is None:
            return False
        kt = np.asarray(channel_keys(doc, ai, c)[0], dtype=np.float64)
        half = 0.5 / clip.fps
        return len(kt) > 0 and (abs(kt[0] - at[0]) > half or abs(kt[-1] - at[-1]) > half)

    changed: dict[str, list[int]] = {"rotation": [], "translation": [], "scale": []}
    for k in range(len(cj)):
        differs = {
            "rotation": lambda: np.any(quat_angle_deg(file_values("rotation", k), clip.rotations[:, k])
                                       > ROTATION_TOLERANCE_DEG),
            "translation": lambda: _differs(file_values("translation", k), clip.translations[:, k],
                                            TRANSLATION_TOLERANCE_M),
            "scale": lambda: _differs(file_values("scale", k), clip.scales[:, k], SCALE_TOLERANCE),
        }
        for path_, test in differs.items():
            if other_span(path_, k) or test():
                changed[path_].append(k)

    out_glb = final.suffix.lower() == ".glb"
    buffers = list(doc.buffers)
    for i, b in enumerate(g.buffers):  # a GLB chunk may carry up to 3 padding bytes past byteLength
        if b.uri is None:
            buffers[i] = buffers[i][: b.byteLength]

    if provenance is not None:
        provenance = provenance_record(provenance)  # checked before anything is written
        if ai is None and not any(changed.values()):
            changed["rotation"] = list(range(len(cj)))  # a new animation to hold the record
    if any(changed.values()):
        target = _data_buffer(g, buffers, out_glb)
        app = BinaryAppender(g, target, buffers[target])
        if ai is None:
            g.animations.append(pygltflib.Animation(name=new_name))
            ai = len(g.animations) - 1
        anim = g.animations[ai]
        _record_fps(anim, clip.fps)
        w = _AnimationWriter(app, anim, times)
        arrays = {"rotation": _continuous(clip.rotations), "translation": clip.translations, "scale": clip.scales}
        for path_, ks in changed.items():
            w.add(path_, ks, [nodes[k] for k in ks], arrays[path_], replace=existing)
        _drop_unused_samplers(anim)
        app.finish(buffers)
    if provenance is not None:
        _record_provenance(g.animations[ai], provenance)
    save_gltf(g, buffers, path, glb=out_glb)


def _differs(file: np.ndarray, clip: np.ndarray, tolerance: float) -> bool:
    """Whether (T, 3) values differ beyond ``tolerance`` (relative above magnitude 1)."""
    return bool(np.any(np.abs(file - clip) > tolerance * np.maximum(1.0, np.abs(file))))


def _data_buffer(g: pygltflib.GLTF2, buffers: list[bytes], glb: bool) -> int:
    """Index of the buffer new data goes to: the GLB chunk (buffer 0, created if needed) or a new one."""
    if g.buffers and g.buffers[0].uri is None:
        return 0
    if glb:  # the binary chunk must be buffer 0: shift the others
        g.buffers.insert(0, pygltflib.Buffer(byteLength=0))
        buffers.insert(0, b"")
        for v in g.bufferViews:
            v.buffer += 1
        return 0
    g.buffers.append(pygltflib.Buffer(byteLength=0))
    buffers.append(b"")
    return len(g.buffers) - 1


def _drop_unused_samplers(anim: pygltflib.Animation) -> None:
    used = sorted({ch.sampler for ch in anim.channels})
    if len(used) == len(anim.samplers):
        return
    remap = {old: new for new, old in enumerate(used)}
    anim.samplers = [anim.samplers[i] for i in used]
    for ch in anim.channels:
        ch.sampler = remap[ch.sampler]

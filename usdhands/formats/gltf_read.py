"""glTF 2.0 reader: skins → skeletons, animations → clips, skinned primitives → meshes.

Decisions (see docs/format-gltf.md):

- Skins that share a joint node are one skeleton (RobotExpressive has two skins over
  the same 43 joints). Its joints are the union of the skins' joints, plus the
  non-joint ancestors needed for correct world transforms: an ancestor is kept when
  it, or a node above it, has a non-identity transform or is animated. Identity
  nodes above everything are dropped (their transform changes nothing). The kept
  ancestors are listed in ``Asset.non_skin_joints`` (the USD writer makes the static
  ones above the skin's joints ``Xform`` prims).
- Joints keep the skin's order (ancestors first) when parents already come before
  children there; otherwise they are in depth-first order of the node tree.
- Joint names are node names; an empty name becomes ``"node<i>"``; repeated names
  get Blender-style suffixes ``".001"``, ``".002"``.
- ``bind_xforms`` are the inverses of the inverse bind matrices (identity where a
  skin has none); kept ancestors, which no skin lists, bind at their rest world
  transform.
- Animations are sampled at ``fps`` or, when None, at a rate found from the key
  times (see :func:`detect_fps`).
"""

from __future__ import annotations

import contextlib
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from usdhands.errors import AssetReadError
from usdhands.formats.gltf_container import GltfFile, load_gltf
from usdhands.formats.gltf_materials import read_materials
from usdhands.model.asset import Asset, BlendShape, BlendShapeWeights, SkinnedMesh
from usdhands.model.clip import Clip, clip_size_problem
from usdhands.model.provenance import provenance_record
from usdhands.model.rotations import quat_slerp, trs_to_xform, xform_to_trs
from usdhands.model.skeleton import Skeleton

__all__ = ["GltfScene", "SkeletonBinding", "read_gltf", "scan_scene", "detect_fps", "sample_channel",
           "COMMON_FPS", "KNOWN_FPS", "DEFAULT_FPS", "EXTRAS_KEY", "recorded_fps", "snap_time"]

#: Rates tried, in this order, when key times sit on a regular grid.
COMMON_FPS = (30.0, 24.0, 25.0, 60.0, 50.0, 48.0, 120.0, 100.0, 90.0)
#: Rates a regular key grid snaps to (within 0.01%): the common ones and NTSC's.
KNOWN_FPS = COMMON_FPS + (24000 / 1001, 30000 / 1001, 60000 / 1001, 48000 / 1001, 120000 / 1001)
#: Keys on a regular grid at this rate or more are read at their own rate.
MIN_SAMPLED_FPS = 12.0
#: Rate used when key times fit no grid.
DEFAULT_FPS = 30.0
_TRS_PATHS = ("translation", "rotation", "scale")
_log = logging.getLogger(__name__)


@dataclass
class SkeletonBinding:
    """A skeleton of the file and the nodes behind it.

    Attributes
    ----------
    skeleton : Skeleton
    nodes : list of int
        Node index of every joint, in joint order.
    skins : list of int
        The skins whose joints it holds.
    node_to_joint : dict int -> int
    """

    skeleton: Skeleton
    nodes: list[int]
    skins: list[int]
    node_to_joint: dict[int, int] = field(default_factory=dict)


@dataclass
class GltfScene:
    """A loaded file with its node hierarchy and skeletons worked out."""

    doc: GltfFile
    parents: np.ndarray                   # (N,) parent node of each node, -1 for roots
    local_trs: list[tuple]                # per node: (t (3,), q (4,), s (3,))
    bindings: list[SkeletonBinding]
    skin_binding: dict[int, int]          # skin index -> binding index

    def binding_of_node(self, node: int) -> int | None:
        """Index of the binding holding ``node`` as a joint, or None."""
        for b, binding in enumerate(self.bindings):
            if node in binding.node_to_joint:
                return b
        return None


def _node_trs(doc: GltfFile, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = doc.gltf.nodes[i]
    if n.matrix is not None and len(n.matrix) == 16:
        m = np.asarray(n.matrix, dtype=np.float64).reshape(4, 4).T  # column-major in the file
        if not np.isfinite(m).all() or np.abs(m).max() > 1e30:
            raise doc.error("node matrix is not finite (or absurdly large)", f"nodes[{i}]")
        scale = np.linalg.norm(m[:3, :3], axis=0)
        if (scale < 1e-12).any() or abs(np.linalg.det(m[:3, :3] / scale)) < 1e-6:
            raise doc.error("node matrix is singular (a zero scale or collapsed axes)", f"nodes[{i}]")
        t, q, s = xform_to_trs(m)
        return t, q, s
    t = np.asarray(n.translation if n.translation is not None else (0.0, 0.0, 0.0), dtype=np.float64)
    q = np.asarray(n.rotation if n.rotation is not None else (0.0, 0.0, 0.0, 1.0), dtype=np.float64)
    s = np.asarray(n.scale if n.scale is not None else (1.0, 1.0, 1.0), dtype=np.float64)
    if t.shape != (3,) or q.shape != (4,) or s.shape != (3,):
        raise doc.error("node TRS has the wrong number of components", f"nodes[{i}]")
    trs = np.concatenate([t, q, s])
    if not np.isfinite(trs).all() or np.abs(trs).max() > 1e30:  # 1e308 overflowed the norm below
        raise doc.error("node translation, rotation or scale is not finite (or absurdly large)", f"nodes[{i}]")
    if np.linalg.norm(q) < 1e-12:
        raise doc.error(f"node rotation {q.tolist()} is not a quaternion", f"nodes[{i}]")
    return t, q / np.linalg.norm(q), s


def _node_parents(doc: GltfFile) -> np.ndarray:
    nodes = doc.gltf.nodes
    parents = np.full(len(nodes), -1, dtype=np.int64)
    for i, n in enumerate(nodes):
        for c in n.children or []:
            if not 0 <= c < len(nodes):
                raise doc.error(f"child {c} out of range (there are {len(nodes)} nodes)", f"nodes[{i}]")
            if parents[c] >= 0:
                raise doc.error(f"node {c} has two parents ({parents[c]} and {i})", f"nodes[{i}]")
            parents[c] = i
    # cycle check, linear: each node is walked over once (a chain of 100,000 nodes took hours
    # when every node walked up to its root)
    up = parents.tolist()
    state = [0] * len(nodes)  # 0 unseen, 1 on the current walk, 2 known to reach a root
    for i in range(len(nodes)):
        walk, j = [], i
        while j >= 0 and state[j] == 0:
            state[j] = 1
            walk.append(j)
            j = up[j]
        if j >= 0 and state[j] == 1:
            raise doc.error("node hierarchy has a cycle", f"nodes[{i}]")
        for k in walk:
            state[k] = 2
    return parents


def _unique_names(names: list[str]) -> list[str]:
    used = set(names)
    seen: set[str] = set()
    out = []
    for n in names:
        if n in seen:
            k = 1
            while f"{n}.{k:03d}" in used:
                k += 1
            n = f"{n}.{k:03d}"
            used.add(n)
        seen.add(n)
        out.append(n)
    return out


def _is_identity(trs: tuple) -> bool:
    t, q, s = trs
    return (np.allclose(t, 0.0, atol=1e-12) and np.allclose(s, 1.0, atol=1e-12)
            and (abs(abs(q[3]) - 1.0) < 1e-12))


def scan_scene(doc: GltfFile) -> GltfScene:
    """Work out the node hierarchy and one skeleton per group of skins sharing joints."""
    g = doc.gltf
    parents = _node_parents(doc)
    trs = [_node_trs(doc, i) for i in range(len(g.nodes))]
    animated = {ch.target.node for a in g.animations for ch in a.channels
                if ch.target is not None and ch.target.node is not None and ch.target.path in _TRS_PATHS}

    # group skins that share joints (union-find)
    nskin = len(g.skins)
    root = list(range(nskin))

    def find(a: int) -> int:
        while root[a] != a:
            root[a] = root[root[a]]
            a = root[a]
        return a

    owner: dict[int, int] = {}
    for si, skin in enumerate(g.skins):
        for j in skin.joints or []:
            if not 0 <= j < len(g.nodes):
                raise doc.error(f"joint node {j} out of range (there are {len(g.nodes)} nodes)", f"skins[{si}]")
            if j in owner:
                root[find(si)] = find(owner[j])
            else:
                owner[j] = si
    groups: dict[int, list[int]] = {}
    for si in range(nskin):
        groups.setdefault(find(si), []).append(si)

    bindings: list[SkeletonBinding] = []
    skin_binding: dict[int, int] = {}
    for skins in groups.values():
        if not any(g.skins[s].joints for s in skins):
            continue
        binding = _build_binding(doc, skins, parents, trs, animated)
        for s in skins:
            skin_binding[s] = len(bindings)
        bindings.append(binding)
    return GltfScene(doc, parents, trs, bindings, skin_binding)


def _build_binding(doc: GltfFile, skins: list[int], parents: np.ndarray, trs: list[tuple],
                   animated: set[int]) -> SkeletonBinding:
    g = doc.gltf
    skin_nodes: list[int] = list(dict.fromkeys(j for s in skins for j in g.skins[s].joints or []))
    in_skin = set(skin_nodes)
    up = parents.tolist()

    # non-joint ancestors, each kept when it or a non-joint node above it is needed;
    # every walk up stops at a node already answered, so the work is linear in the nodes
    def needed(n: int) -> bool:
        return n in animated or not _is_identity(trs[n])

    ancestors: set[int] = set()
    walked: set[int] = set()
    for j in skin_nodes:
        p = up[j]
        while p >= 0 and p not in walked:
            walked.add(p)
            if p not in in_skin:
                ancestors.add(p)
            p = up[p]
    needed_above: dict[int, bool] = {-1: False}  # a needed non-joint node at or above n

    def has_needed_above(n: int) -> bool:
        walk = []
        while n not in needed_above:
            walk.append(n)
            n = up[n]
        answer = needed_above[n]
        for m in reversed(walk):
            answer = answer or (m not in in_skin and needed(m))
            needed_above[m] = answer
        return needed_above[walk[0]] if walk else answer

    kept = {a for a in ancestors if has_needed_above(a)}
    included = in_skin | kept
    nearest: dict[int, int] = {-1: -1}  # nearest included node at or above n (-1: none)

    def nearest_included(n: int) -> int:
        walk, p = [], up[n]
        while p not in nearest:
            if p in included:
                nearest[p] = p
                break
            walk.append(p)
            p = up[p]
        for m in walk:
            nearest[m] = nearest[p]
        return nearest[p]

    anc_order = _dfs_order(g, parents, kept)
    order = anc_order + skin_nodes
    pos = {n: i for i, n in enumerate(order)}
    above = {n: nearest_included(n) for n in order}
    if any(above[n] >= 0 and pos[above[n]] > pos[n] for n in order):
        order = _dfs_order(g, parents, included)
        pos = {n: i for i, n in enumerate(order)}
    jparents = np.array([pos[above[n]] if above[n] >= 0 else -1 for n in order], dtype=np.int64)

    # rest local transforms relative to the nearest kept ancestor: dropped nodes in
    # between are identity by construction (a dropped node has no needed node above it)
    rest_t = np.array([trs[n][0] for n in order]).reshape(-1, 3)
    rest_q = np.array([trs[n][1] for n in order]).reshape(-1, 4)
    rest_s = np.array([trs[n][2] for n in order]).reshape(-1, 3)

    names = _unique_names([g.nodes[n].name or f"node{n}" for n in order])
    world = _world_of(order, jparents, rest_t, rest_q, rest_s)
    bind = world.copy()
    done: set[int] = set()
    for s in skins:
        skin = g.skins[s]
        ibm = _inverse_binds(doc, s)
        for k, n in enumerate(skin.joints or []):
            if n in done:
                continue
            done.add(n)
            bind[pos[n]] = np.linalg.inv(ibm[k]) if ibm is not None else np.eye(4)
    first = g.skins[skins[0]]
    name = first.name or f"skin{skins[0]}"
    skel = Skeleton(names, jparents, rest_t, rest_q, rest_s, bind, meters_per_unit=1.0, up_axis="Y", name=name)
    return SkeletonBinding(skel, list(order), list(skins), {n: i for i, n in enumerate(order)})


def _dfs_order(g, parents: np.ndarray, keep: set[int]) -> list[int]:
    """Nodes of ``keep`` in depth-first pre-order of the node forest (scene roots in node order)."""
    children: dict[int, list[int]] = {}
    roots = []
    for i, p in enumerate(parents):
        if p < 0:
            roots.append(i)
        else:
            children.setdefault(int(p), []).append(i)
    out: list[int] = []
    stack = list(reversed(roots))
    while stack:
        n = stack.pop()
        if n in keep:
            out.append(n)
        stack.extend(reversed(children.get(n, [])))
    return out


def _world_of(order, parents, t, q, s) -> np.ndarray:
    local = trs_to_xform(t, q, s)
    world = np.empty_like(local)
    for j, p in enumerate(parents):
        world[j] = local[j] if p < 0 else world[p] @ local[j]
    return world


def _inverse_binds(doc: GltfFile, skin_index: int) -> np.ndarray | None:
    """Inverse bind matrices ``(len(joints), 4, 4)`` of a skin, None when it has none."""
    skin = doc.gltf.skins[skin_index]
    if skin.inverseBindMatrices is None:
        return None
    m = doc.accessor(skin.inverseBindMatrices)
    if m.shape != (len(skin.joints), 16):
        raise doc.error(f"inverseBindMatrices has {m.shape[0]} matrices for {len(skin.joints)} joints",
                        f"skins[{skin_index}]")
    return m.reshape(-1, 4, 4).transpose(0, 2, 1)


# -- animation ----------------------------------------------------------------

def detect_fps(times) -> float:
    """A frame rate whose frames land on every key time, from the key times as a whole.

    1. Keys on a regular grid: the step is first estimated from the median key
       interval of the densest key array, refined over the whole span (steps counted
       from first to last key) and then fitted by least squares over every key
       (``t = t0 + k h``); float32 rounding of single keys averages out, so 29.97 fps
       over thousands of frames stays 29.97. With ``1/h >= 12`` the rate is ``1/h``,
       snapped to a rate of :data:`KNOWN_FPS` (NTSC ``24000/1001`` ...) within
       0.01%, else to an integer within 1e-5, else to the inverse of a frame time of
       at most 6 decimals within 1e-6 (BVH ``Frame Time: 0.027000``), else to 7
       significant digits.
    2. Otherwise (sparse or irregular keys) the first rate of :data:`COMMON_FPS`
       (30 first) whose frames fall on every key.
    3. Otherwise :data:`DEFAULT_FPS`.

    Key times are measured from the first key; a key counts as on a frame within 1%
    of a frame. No sort of all keys is needed: arrays already in order (as glTF
    sampler inputs are) are used as they are.

    Parameters
    ----------
    times : (K,) float, or a sequence of such arrays
        Key times in seconds (one array per distinct sampler input, or all keys
        concatenated), any order, repeats allowed.
    """
    arrays = _key_arrays(times)
    if not arrays:
        return DEFAULT_FPS
    t0 = min(float(a[0]) for a in arrays)
    t1 = max(float(a[-1]) for a in arrays)
    if not t1 > t0:
        return DEFAULT_FPS
    rel = np.concatenate(arrays) - t0
    step = _typical_step(arrays)
    if step > 0 and 1.0 / step >= MIN_SAMPLED_FPS:
        h = (t1 - t0) / max(1.0, np.round((t1 - t0) / step))  # steps over the whole span
        k = np.round(rel / h)
        h = _fit_step(k, rel)
        if h > 0 and np.all(np.abs(rel / h - k) < 0.01):
            return _snap_rate(1.0 / h)
    for f in COMMON_FPS:
        x = rel * f
        if np.all(np.abs(x - np.round(x)) < 0.01):
            return f
    return DEFAULT_FPS


def _key_arrays(times) -> list[np.ndarray]:
    """Non-empty 1-D float64 arrays in increasing order (sorted only when they are not)."""
    if isinstance(times, np.ndarray) or (len(times) and np.isscalar(times[0])):
        times = [times]
    out = []
    for a in times:
        a = np.asarray(a, dtype=np.float64).reshape(-1)
        if a.size == 0:
            continue
        if a.size > 1 and np.any(a[1:] < a[:-1]):
            a = np.unique(a)  # all keys of all channels concatenated: repeats dropped too
        out.append(a)
    return out


def _typical_step(arrays: list[np.ndarray]) -> float:
    """Median positive key interval of the array with the smallest one (the densest keys)."""
    best = 0.0
    for a in arrays:
        d = np.diff(a)
        d = d[d > 0]
        if d.size:
            m = float(np.median(d))
            best = m if best == 0.0 else min(best, m)
    return best


def _fit_step(k: np.ndarray, rel: np.ndarray) -> float:
    """Least-squares slope ``h`` of ``rel = c + k h`` (seconds per frame)."""
    km = k - k.mean()
    den = float(km @ km)
    return float(km @ (rel - rel.mean()) / den) if den > 0 else 0.0


def _snap_rate(rate: float) -> float:
    for f in KNOWN_FPS:
        if abs(rate - f) < 1e-4 * f:
            return f
    if abs(rate - round(rate)) < 1e-5 * rate:
        return float(round(rate))
    # a frame time with at most 6 decimals (BVH "Frame Time: 0.027000"): its exact inverse
    frame_time = round(1.0 / rate, 6)
    if frame_time > 0 and abs(frame_time * rate - 1.0) < 1e-6:
        return 1.0 / frame_time
    return float(f"{rate:.7g}")


def sample_channel(times: np.ndarray, values: np.ndarray, interpolation: str, at: np.ndarray,
                   rotation: bool, snap: float = 0.0) -> np.ndarray:
    """Evaluate a glTF sampler at given times.

    Parameters
    ----------
    times : (K,) float
        Key times, seconds, increasing.
    values : (K, C) or (3K, C) float
        Key values; CUBICSPLINE holds (in-tangent, value, out-tangent) per key.
    interpolation : {"LINEAR", "STEP", "CUBICSPLINE"}
    at : (T,) float
        Times to evaluate, seconds; before the first key gives the first value, after
        the last the last value.
    rotation : bool
        Quaternions xyzw: slerp for LINEAR, normalised results.
    snap : float
        Seconds: a time this close to a key takes the key's value exactly (key times
        are float32 in files, frame times are not; without it a STEP sampler would
        give the previous key at a frame that is a hair before its key).

    Returns
    -------
    (T, C) float
    """
    K = times.shape[0]
    if interpolation == "CUBICSPLINE":
        tangents_in, vals, tangents_out = values[0::3], values[1::3], values[2::3]
    else:
        vals = values
    if K == 1:
        out = np.broadcast_to(vals[0], (at.shape[0], vals.shape[1])).copy()
        return _norm(out) if rotation else out
    if _keys_are_frames(times, at, snap):  # keys on the frames: the values themselves
        out = np.array(vals, dtype=np.float64)
        return _norm(out) if rotation else out
    if interpolation == "STEP":
        i = np.clip(np.searchsorted(times, at + snap, side="right") - 1, 0, K - 1)
        out = vals[i].copy()
        return _norm(out) if rotation else out
    i = np.clip(np.searchsorted(times, at, side="right") - 1, 0, K - 2)
    dt = times[i + 1] - times[i]
    u = np.clip((at - times[i]) / np.where(dt > 0, dt, 1.0), 0.0, 1.0)
    if snap > 0:
        u = np.where(at - times[i] <= snap, 0.0, np.where(times[i + 1] - at <= snap, 1.0, u))
    if interpolation == "CUBICSPLINE":
        u2, u3 = u * u, u * u * u
        h00 = 2 * u3 - 3 * u2 + 1
        h10 = u3 - 2 * u2 + u
        h01 = -2 * u3 + 3 * u2
        h11 = u3 - u2
        out = (h00[:, None] * vals[i] + (h10 * dt)[:, None] * tangents_out[i]
               + h01[:, None] * vals[i + 1] + (h11 * dt)[:, None] * tangents_in[i + 1])
        return _norm(out) if rotation else out
    if rotation:
        return quat_slerp(vals[i], vals[i + 1], u)
    return vals[i] * (1.0 - u)[:, None] + vals[i + 1] * u[:, None]


def snap_time(fps: float) -> float:
    """Seconds within which a frame time takes a key's value: a thousandth of a frame."""
    return 1e-3 / fps


def _keys_are_frames(times: np.ndarray, at: np.ndarray, snap: float) -> bool:
    """Whether key times ``(K,)`` are the frame times ``at (T,)``, each within ``snap`` seconds."""
    return times.shape[0] == at.shape[0] and bool(np.all(np.abs(times - at) <= snap))


def _norm(q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Quaternions ``(..., 4)`` over their length; zero ones stay zero (Clip.validate reports them).

    The squares are added left to right, as ``np.linalg.norm`` adds four components (the
    same bits), without its reduction along a four-long axis (half the time).
    """
    sq = q * q
    n = np.sqrt(sq[..., 0] + sq[..., 1] + sq[..., 2] + sq[..., 3])
    return np.divide(q, np.where(n > 0, n, 1.0)[..., None], out=out)


def channel_keys(doc: GltfFile, anim_index: int, channel_index: int,
                 targets: int | None = None, *, stored: bool = False) -> tuple[np.ndarray, np.ndarray, str]:
    """Key times ``(K,)``, values ``(K or 3K, C)`` and interpolation of one channel.

    A ``weights`` channel needs ``targets``, the morph target count of its node (its C).
    Values are float64, or with ``stored`` the float32 numbers of a FLOAT accessor as
    they are in the buffer (the caller converts them where it puts them; normalized
    integers are always mapped to float64).
    """
    a = doc.gltf.animations[anim_index]
    ch = a.channels[channel_index]
    where = f"animations[{anim_index}].channels[{channel_index}]"
    if ch.sampler is None or not 0 <= ch.sampler < len(a.samplers):
        raise doc.error(f"sampler {ch.sampler} out of range", where)
    smp = a.samplers[ch.sampler]
    interp = smp.interpolation or "LINEAR"
    if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
        raise doc.error(f"unknown interpolation {interp!r}", where)
    _check_component_types(doc, smp.input, smp.output, ch.target.path, where)
    times = doc.accessor(smp.input)[:, 0]
    values = doc.accessor(smp.output, as_float=not (stored and doc.gltf.accessors[smp.output].componentType == FLOAT))
    need = times.shape[0] * (3 if interp == "CUBICSPLINE" else 1)
    if ch.target.path == "weights":
        if targets is None or values.size != need * targets:
            raise doc.error(f"weights sampler has {values.size} output values for {times.shape[0]} keys of "
                            f"{targets} morph targets", where)
        values = values.reshape(need, targets)
    if values.shape[0] != need:
        raise doc.error(f"{interp} sampler has {values.shape[0]} output values for {times.shape[0]} keys "
                        f"(expected {need})", where)
    width = {"rotation": 4, "translation": 3, "scale": 3, "weights": targets}[ch.target.path]
    if values.shape[1] != width:
        raise doc.error(f"{ch.target.path} output has {values.shape[1]} components, expected {width}", where)
    checked = ("increasing times", smp.input)  # channels usually share one input: checked once
    if checked not in doc._cache:
        if not np.isfinite(times).all():
            raise doc.error("sampler input times are not finite", where)
        if times.size and np.any(np.diff(times) < 0):
            raise doc.error("sampler input times decrease", where)
        doc._cache[checked] = True
    return times, values, interp


#: componentType codes: FLOAT, and the integer types glTF allows (normalized) for rotations
FLOAT = 5126
ROTATION_INTEGER_TYPES = (5120, 5121, 5122, 5123)


def _check_component_types(doc: GltfFile, input_index, output_index, path: str, where: str) -> None:
    """Key times must be FLOAT; translations and scales FLOAT; rotations FLOAT or normalized
    (UNSIGNED_)BYTE/SHORT (glTF 2.0, 3.11). An UNSIGNED_INT rotation was read as integers."""
    accessors = doc.gltf.accessors
    for index in (input_index, output_index):
        if not isinstance(index, int) or not 0 <= index < len(accessors):
            raise doc.error(f"accessor index {index} out of range (there are {len(accessors)})", where)
    times, values = accessors[input_index], accessors[output_index]
    if times.componentType != FLOAT:
        raise doc.error(f"key times (accessors[{input_index}]) have componentType {times.componentType}; "
                        "glTF requires FLOAT (5126)", where)
    ok = values.componentType == FLOAT or (path in ("rotation", "weights")
                                          and values.componentType in ROTATION_INTEGER_TYPES and values.normalized)
    if not ok:
        allowed = "FLOAT or normalized BYTE/SHORT types" if path in ("rotation", "weights") else "FLOAT"
        raise doc.error(f"{path} values (accessors[{output_index}]) have componentType {values.componentType}"
                        f"{'' if values.normalized else ' not normalized'}; glTF allows {allowed}", where)


#: Highest frame rate key times may give, and most frames an animation is sampled at.
MAX_FPS = 1e4
MAX_FRAMES = 1e7


def animation_channels(doc: GltfFile, anim_index: int, binding: SkeletonBinding) -> list[tuple[int, int, str]]:
    """``(channel index, joint index, path)`` of the TRS channels of an animation on a skeleton."""
    out = []
    for c, ch in enumerate(doc.gltf.animations[anim_index].channels):
        t = ch.target
        if t is None or t.node is None or t.path not in _TRS_PATHS:
            continue
        j = binding.node_to_joint.get(t.node)
        if j is not None:
            out.append((c, j, t.path))
    return out


#: Key of the animation ``extras`` object usdhands writes (``{"fps": ..., "provenance": ...}``).
EXTRAS_KEY = "usdhands"


def recorded_fps(doc: GltfFile, anim_index: int) -> float | None:
    """The frame rate usdhands recorded in the animation's ``extras`` (None when absent or unusable)."""
    extras = doc.gltf.animations[anim_index].extras
    ours = extras.get(EXTRAS_KEY) if isinstance(extras, dict) else None
    fps = ours.get("fps") if isinstance(ours, dict) else None
    if fps is None:
        return None
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not 0 < fps <= MAX_FPS:
        _log.warning("%s: animations[%d]: ignoring extras.%s.fps %r (not a rate in 0..%g); rate from key times",
                     doc.path, anim_index, EXTRAS_KEY, fps, MAX_FPS)
        return None
    return float(fps)


def _keys_on_frames(inputs: list[np.ndarray], fps: float) -> bool:
    """Every key within 1% of a frame at ``fps`` and no two distinct keys on one frame."""
    t0 = min(float(a[0]) for a in inputs)
    for a in inputs:
        x = (a - t0) * fps
        k = np.round(x)
        if np.any(np.abs(x - k) >= 0.01) or np.any((np.diff(a) > 0) & (np.diff(k) <= 0)):
            return False
    return True


def sample_animation(doc: GltfFile, anim_index: int, binding: SkeletonBinding, fps: float | None,
                     name: str) -> Clip | None:
    """One clip of ``binding``'s skeleton from an animation, None if it animates none of its joints."""
    chans = animation_channels(doc, anim_index, binding)
    if not chans:
        return None
    keys = {c: channel_keys(doc, anim_index, c, stored=True) for c, _, _ in chans}
    anim = doc.gltf.animations[anim_index]
    accessor_of = {c: anim.samplers[anim.channels[c].sampler].input for c in keys}  # key times accessor per channel
    # each input accessor once (channels usually share one; each channel_keys call gives a new view)
    inputs = list({accessor_of[c]: k[0] for c, k in keys.items() if k[0].size}.values())
    if not inputs:
        raise doc.error("animation has no key times", f"animations[{anim_index}]")
    rate = float(fps) if fps else None
    if rate is None:
        rate = recorded_fps(doc, anim_index)
        if rate is not None and not _keys_on_frames(inputs, rate):
            _log.info("%s: animations[%d]: key times are not on the frames of the recorded %g fps; "
                         "rate from key times", doc.path, anim_index, rate)
            rate = None
        rate = rate or detect_fps(inputs)
    if not rate <= MAX_FPS:
        raise doc.error(f"key times {1.0 / rate:g} s apart give {rate:g} frames per "
                        f"second (at most {MAX_FPS:g})", f"animations[{anim_index}]")
    t0, t1 = min(float(a[0]) for a in inputs), max(float(a[-1]) for a in inputs)
    if (t1 - t0) * rate >= MAX_FRAMES:  # 1e30 s: numpy's 'Maximum allowed size exceeded'
        raise doc.error(f"key times span {t1 - t0:g} s: over {MAX_FRAMES:g} frames at {rate:g} fps",
                        f"animations[{anim_index}]")
    n = int(np.floor((t1 - t0) * rate + 1e-3)) + 1
    sk = binding.skeleton
    J = sk.num_joints

    def held() -> int:  # per animated joint, the key times of its channel with the most
        most: dict[int, int] = {}
        for c, j, _ in chans:
            most[j] = max(most.get(j, 0), len(keys[c][0]))
        return sum(most.values())

    too_big = clip_size_problem(n, J, held)
    if too_big:  # before any array is allocated
        raise doc.error(too_big, f"animations[{anim_index}]")
    at = t0 + np.arange(n) / rate
    # time-major arrays, as the clip keeps them (handed over read-only: the clip does not copy
    # them). Where every joint has a channel of a kind, the channels fill a joint-major block
    # (each a contiguous stretch) that is then copied into time order once; otherwise the
    # array starts as the rest pose and channels write their joints' columns. FLOAT accessors
    # are read as their float32 numbers and converted where they are put.
    target, staged = {}, {}
    for path, rest in (("rotation", sk.rest_rotations), ("translation", sk.rest_translations),
                       ("scale", sk.rest_scales)):
        if len({j for _, j, p in chans if p == path}) == J:
            staged[path] = np.empty((J, n, rest.shape[-1]))
        else:
            target[path] = np.empty((n, J, rest.shape[-1]))
            target[path][:] = rest
    snap = snap_time(rate)
    on_frames: dict[int, bool] = {}  # input accessor -> its keys are the frames
    with np.errstate(invalid="ignore"):  # a signalling NaN warns in the conversion; Clip.validate refuses NaN
        for c, j, path in chans:
            times, values, interp = keys[c]
            if accessor_of[c] not in on_frames:
                on_frames[accessor_of[c]] = _keys_are_frames(times, at, snap)
            if on_frames[accessor_of[c]]:  # baked keys: the values themselves, as sample_channel gives them
                vals = values[1::3] if interp == "CUBICSPLINE" else values
            else:
                vals = sample_channel(times, values.astype(np.float64, copy=False), interp, at, path == "rotation",
                                      snap)
            if path in staged:
                staged[path][j] = vals
                dst = staged[path][j]
            else:
                dst = target[path][:, j]
                dst[:] = vals
            if path == "rotation" and on_frames[accessor_of[c]]:
                _norm(dst, out=dst)
    for path, block in staged.items():
        target[path] = _time_major(block)
    rot, tra, sca = (target[p] for p in ("rotation", "translation", "scale"))
    for a in (rot, tra, sca):
        a.setflags(write=False)
    return Clip(sk, rate, rot, tra, sca, name=name, start_time=t0)


def _time_major(block: np.ndarray) -> np.ndarray:
    """``(J, T, C)`` float64 joint-major values as a C-contiguous ``(T, J, C)`` array.

    Each joint's C numbers at a frame move as one record of 8C bytes: numpy's transposing
    copy of records is about twice as fast as of single floats.
    """
    J, T, C = block.shape
    record = np.dtype((np.void, 8 * C))
    out = np.empty((T, J, C))
    out.view(record).reshape(T, J)[:] = np.ascontiguousarray(block).view(record).reshape(J, T).T
    return out


def sample_morph_weights(doc: GltfFile, anim_index: int, clip: Clip, tokens: dict[int, list[tuple[str, str]]],
                         defaults: dict[int, list[float]]) -> BlendShapeWeights | None:
    """The ``weights`` channels of an animation on the morphed nodes of ``tokens``, sampled at ``clip``'s
    frames: one column per target of every node the animation keys (None when it keys none)."""
    anim = doc.gltf.animations[anim_index]
    keyed = [(c, ch) for c, ch in enumerate(anim.channels)
             if ch.target is not None and ch.target.path == "weights" and ch.target.node in tokens]
    if not keyed:
        return None
    names: list[str] = []
    columns: dict[int, list[int]] = {}
    for _, ch in keyed:
        node = ch.target.node
        if node not in columns:
            columns[node] = []
            for t, _ in tokens[node]:
                if t not in names:
                    names.append(t)
                columns[node].append(names.index(t))
    at = clip.times
    out = np.zeros((clip.num_frames, len(names)))
    for node, cols in columns.items():
        d = defaults.get(node, [])
        for k, col in enumerate(cols):
            out[:, col] = d[k] if k < len(d) else 0.0
    snap = snap_time(clip.fps)
    for c, ch in keyed:
        node = ch.target.node
        times, values, interp = channel_keys(doc, anim_index, c, targets=len(tokens[node]))
        if not times.size:
            raise doc.error("weights sampler has no keys", f"animations[{anim_index}].channels[{c}]")
        out[:, columns[node]] = sample_channel(times, values, interp, at, False, snap)
    return BlendShapeWeights(tuple(names), out)


def sparse_key_times(doc: GltfFile, anim_index: int, nodes: set[int], clip: Clip) -> np.ndarray | None:
    """The key times (seconds, on the clip's frames) of the animation's channels on ``nodes`` when
    they are fewer than the clip's frames and every one is a frame; else None."""
    anim = doc.gltf.animations[anim_index]
    inputs = {anim.samplers[ch.sampler].input for ch in anim.channels
              if ch.target is not None and ch.target.node in nodes and ch.sampler is not None
              and 0 <= ch.sampler < len(anim.samplers)}
    if not inputs:
        return None
    times = np.unique(np.concatenate([doc.accessor(i)[:, 0] for i in inputs]).astype(np.float64))
    x = (times - clip.start_time) * clip.fps
    k = np.round(x)
    if len(times) >= clip.num_frames or np.any(np.abs(x - k) > 1e-3):
        return None
    return clip.start_time + np.unique(k) / clip.fps


def clip_interpolation(doc: GltfFile, anim_index: int, nodes: set[int]) -> str | None:
    """``"STEP"`` or ``"CUBICSPLINE"`` when every sampler of the animation's channels on ``nodes``
    has that interpolation; None for LINEAR or a mix."""
    anim = doc.gltf.animations[anim_index]
    kinds = set()
    for ch in anim.channels:
        if ch.target is not None and ch.target.node in nodes and ch.sampler is not None \
                and 0 <= ch.sampler < len(anim.samplers):
            kinds.add(anim.samplers[ch.sampler].interpolation or "LINEAR")
    return kinds.pop() if len(kinds) == 1 and kinds & {"STEP", "CUBICSPLINE"} else None


# -- meshes --------------------------------------------------------------------

def _triangles(mode: int, idx: np.ndarray) -> np.ndarray | None:
    if mode == 4:
        return idx[: idx.size // 3 * 3].reshape(-1, 3)
    if mode == 5 and idx.size >= 3:  # strip
        k = np.arange(idx.size - 2)
        tri = np.stack([idx[k], idx[k + 1], idx[k + 2]], axis=1)
        odd = k % 2 == 1
        tri[odd] = tri[odd][:, [1, 0, 2]]
        return tri
    if mode == 6 and idx.size >= 3:  # fan
        k = np.arange(1, idx.size - 1)
        return np.stack([np.full(k.size, idx[0]), idx[k], idx[k + 1]], axis=1)
    return None


def _rigid_parent(scene: GltfScene, node: int) -> tuple[int, int, np.ndarray] | None:
    """The nearest joint above a mesh node: ``(binding, joint, local)`` with ``local`` (4, 4) the
    node's transform relative to that joint (the nodes in between at rest), or None."""
    up = scene.parents
    chain = [node]
    p = int(up[node])
    while p >= 0:
        b = scene.binding_of_node(p)
        if b is not None:
            local = np.eye(4)
            for n in reversed(chain):
                t, q, s = scene.local_trs[n]
                local = local @ trs_to_xform(t, q, s)
            return b, scene.bindings[b].node_to_joint[p], local
        chain.append(p)
        p = int(up[p])
    return None


def _node_world(scene: GltfScene, node: int) -> np.ndarray:
    """The rest world transform (4, 4) of a node: its TRS and its ancestors'."""
    world = np.eye(4)
    n = node
    while n >= 0:
        t, q, sc = scene.local_trs[n]
        world = trs_to_xform(t, q, sc) @ world
        n = int(scene.parents[n])
    return world


def mesh_node_binding(scene: GltfScene, node: int) -> int | None:
    """The skeleton (binding index) a mesh node's meshes are read onto: its skin's, or the one of
    the nearest joint above it; None when it is on none."""
    n = scene.doc.gltf.nodes[node]
    if n.skin is not None and n.skin in scene.skin_binding:
        return scene.skin_binding[n.skin]
    parent = _rigid_parent(scene, node)
    return None if parent is None else parent[0]


def blend_shape_tokens(scene: GltfScene) -> dict[int, list[tuple[str, str]]]:
    """Mesh node -> ``(weight channel name, target name)`` of each of its morph targets.

    The target's name (``mesh.extras.targetNames``, else ``target<i>``) where no other
    morphed node has a target of that name, else ``<node name>_<target name>``.
    """
    g = scene.doc.gltf
    names: dict[int, list[str]] = {}
    for ni, node in enumerate(g.nodes):
        if node.mesh is None or not 0 <= node.mesh < len(g.meshes):
            continue
        mesh = g.meshes[node.mesh]
        count = max((len(p.targets or []) for p in mesh.primitives), default=0)
        if not count:
            continue
        extras = mesh.extras if isinstance(mesh.extras, dict) else {}
        given = extras.get("targetNames")
        given = [str(x) for x in given] if isinstance(given, list) and len(given) == count else []
        names[ni] = [given[i] if given and given[i] else f"target{i}" for i in range(count)]
    seen: dict[str, int] = {}
    for ni, ts in names.items():
        for t in set(ts):
            seen[t] = seen.get(t, 0) + 1
    out = {}
    for ni, ts in names.items():
        node_name = g.nodes[ni].name or f"node{ni}"
        out[ni] = [(t if seen[t] == 1 else f"{node_name}_{t}", t) for t in ts]
    return out


def read_meshes(scene: GltfScene) -> list[SkinnedMesh]:
    """Every triangle primitive of a mesh node on a skeleton, as one :class:`SkinnedMesh` each.

    Skinned nodes keep their skin's influences; a mesh node below a joint (a rigid part:
    RobotExpressive's head, arms and legs) follows that joint with full weight, its
    ``geom_bind_xform`` placing it where the node tree does at bind time. Morph targets
    become ``blend_shapes``; the primitive's material its ``material``.
    """
    doc = scene.doc
    g = doc.gltf
    out: list[SkinnedMesh] = []
    used_names: set[str] = set()
    tokens = blend_shape_tokens(scene)
    for ni, node in enumerate(g.nodes):
        if node.mesh is None:
            continue
        if node.skin is not None and node.skin in scene.skin_binding:
            b = scene.skin_binding[node.skin]
            binding = scene.bindings[b]
            skin = g.skins[node.skin]
            skin_to_joint = np.array([binding.node_to_joint[n] for n in skin.joints], dtype=np.int64)
            geom_bind = _geom_bind(scene, node.skin, binding)
            rigid = None
        else:
            parent = _rigid_parent(scene, ni)
            skin_to_joint = None
            if parent is None:
                if not scene.bindings:
                    continue  # no character: meshes alone are not read
                b, rigid, geom_bind = -1, None, _node_world(scene, ni)  # on no skeleton: a static mesh
            else:
                b, rigid, local = parent
                binding = scene.bindings[b]
                bind = binding.skeleton.bind_xforms
                geom_bind = (bind[rigid] if bind is not None else binding.skeleton.rest_world_xforms()[rigid]) @ local
        if not 0 <= node.mesh < len(g.meshes):
            raise doc.error(f"mesh {node.mesh} out of range (there are {len(g.meshes)})", f"nodes[{ni}]")
        mesh = g.meshes[node.mesh]
        base = mesh.name or node.name or f"mesh{node.mesh}"
        defaults = list(mesh.weights or [])
        for pi, prim in enumerate(mesh.primitives):
            mode = 4 if prim.mode is None else prim.mode
            attrs = _attributes(prim)
            if attrs.get("POSITION") is None:
                continue
            where = f"meshes[{node.mesh}].primitives[{pi}]"
            points = doc.accessor(attrs["POSITION"])
            idx = (doc.accessor(prim.indices, as_float=False)[:, 0].astype(np.int64) if prim.indices is not None
                   else np.arange(points.shape[0]))
            tri = _triangles(mode, idx)
            if tri is None:
                continue  # points and lines carry no surface
            if tri.size and (tri.max() >= points.shape[0]):
                raise doc.error(f"index {int(tri.max())} out of range for {points.shape[0]} vertices", where)
            normals = doc.accessor(attrs["NORMAL"]) if attrs.get("NORMAL") is not None else None
            uvs = None
            if attrs.get("TEXCOORD_0") is not None:
                uv = doc.accessor(attrs["TEXCOORD_0"])
                uvs = np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)
            if b < 0:
                ji = jw = None
            elif rigid is None:
                ji, jw = _influences(doc, attrs, skin_to_joint, points.shape[0], where)
            else:
                ji = np.full((points.shape[0], 1), rigid, dtype=np.int64)
                jw = np.ones((points.shape[0], 1))
            name = base if len(mesh.primitives) == 1 else f"{base}_{pi}"
            name = _unique_names(sorted(used_names) + [name])[-1] if name in used_names else name
            used_names.add(name)
            shapes = _blend_shapes(doc, prim, tokens.get(ni, []), defaults, points.shape[0], where)
            material = prim.material if isinstance(prim.material, int) and 0 <= prim.material < len(g.materials) \
                else None
            out.append(SkinnedMesh(
                name=name, points=points, face_vertex_counts=np.full(tri.shape[0], 3, dtype=np.int64),
                face_vertex_indices=tri.reshape(-1), normals=normals, uvs=uvs, joint_indices=ji,
                joint_weights=jw, geom_bind_xform=geom_bind, skeleton_index=b,
                group=mesh.name or None, node=node.name or None, material=material, blend_shapes=shapes))
    return out


def _blend_shapes(doc: GltfFile, prim, names: list[tuple[str, str]], defaults: list, nverts: int,
                  where: str) -> tuple:
    """The primitive's morph targets as :class:`BlendShape` (dense offsets)."""
    shapes = []
    for ti, target in enumerate(prim.targets or []):
        target = dict(target) if isinstance(target, dict) else dict(vars(target))
        pos = target.get("POSITION")
        offsets = doc.accessor(pos) if pos is not None else np.zeros((nverts, 3))
        nrm = target.get("NORMAL")
        normal_offsets = doc.accessor(nrm) if nrm is not None else None
        for label, arr in (("POSITION", offsets), ("NORMAL", normal_offsets)):
            if arr is not None and arr.shape != (nverts, 3):
                raise doc.error(f"morph target {ti} {label} has {arr.shape[0]} values for {nverts} vertices", where)
        name, original = names[ti] if ti < len(names) else (f"target{ti}", f"target{ti}")
        w = defaults[ti] if ti < len(defaults) and isinstance(defaults[ti], (int, float)) else 0.0
        shapes.append(BlendShape(name=name, offsets=offsets, normal_offsets=normal_offsets, default_weight=float(w),
                                 source_name=original if original != name else None))
    return tuple(shapes)


def _attributes(prim) -> dict:
    a = prim.attributes
    return dict(a) if isinstance(a, dict) else dict(vars(a))


def _influences(doc: GltfFile, attrs: dict, skin_to_joint: np.ndarray, nverts: int, where: str):
    sets = sorted(int(k.split("_")[1]) for k in attrs if k.startswith("JOINTS_") and attrs[k] is not None
                  and k.split("_")[1].isdigit())
    if not sets:
        return None, None
    js, ws = [], []
    for s in sets:
        if attrs.get(f"WEIGHTS_{s}") is None:
            raise doc.error(f"JOINTS_{s} without WEIGHTS_{s}", where)
        j = doc.accessor(attrs[f"JOINTS_{s}"], as_float=False).astype(np.int64)
        w = doc.accessor(attrs[f"WEIGHTS_{s}"])
        if j.shape != (nverts, 4) or w.shape != (nverts, 4):
            raise doc.error(f"JOINTS_{s}/WEIGHTS_{s} do not have 4 values per vertex", where)
        js.append(j)
        ws.append(w)
    j = np.concatenate(js, axis=1)
    w = np.concatenate(ws, axis=1)
    bad = (j >= skin_to_joint.size) & (w != 0)
    if bad.any():
        raise doc.error(f"joint index {int(j[bad].max())} out of range for a skin of {skin_to_joint.size} joints",
                        where)
    j = np.where(j < skin_to_joint.size, j, 0)
    ji = skin_to_joint[j]
    total = w.sum(axis=1, keepdims=True)
    w = np.where(total > 0, w / np.where(total > 0, total, 1.0), w)
    return ji, w


def _geom_bind(scene: GltfScene, skin_index: int, binding: SkeletonBinding) -> np.ndarray:
    """Mesh-to-skeleton transform ``bind_j @ IBM_j``, the same for every joint of a consistent skin.

    The skinned node's own transform is ignored, as the glTF specification says.
    Where the skeleton's binds came from this skin it is the identity.
    """
    ibm = _inverse_binds(scene.doc, skin_index)
    skin = scene.doc.gltf.skins[skin_index]
    bind = binding.skeleton.bind_xforms
    if ibm is None:
        ibm = np.broadcast_to(np.eye(4), (len(skin.joints), 4, 4))
    g = np.array([bind[binding.node_to_joint[n]] @ ibm[k] for k, n in enumerate(skin.joints)])
    return g[0] if g.size else np.eye(4)


# -- entry point -----------------------------------------------------------------

def read_gltf(path: str | Path, *, fps: float | None = None, scene: GltfScene | None = None) -> Asset:
    """Read skeletons, clips and skinned meshes of a ``.gltf``/``.glb`` file.

    Parameters
    ----------
    path : path-like
    fps : float, optional
        Sample every animation at this rate; by default a rate from its key times.

    Raises
    ------
    AssetReadError
        Unreadable, truncated or inconsistent file (one line, with the path).
    """
    with malformed_as_read_error(path):
        if scene is None:
            scene = scan_scene(load_gltf(path))
        doc = scene.doc
        clips: list[Clip] = []
        provenance: dict[str, dict] = {}
        meshes = read_meshes(scene)
        tokens = blend_shape_tokens(scene)
        morph_nodes: dict[int, dict[int, list]] = {}  # binding -> morphed node -> tokens
        for ni, ts in tokens.items():
            b = mesh_node_binding(scene, ni)
            if b is not None:
                morph_nodes.setdefault(b, {})[ni] = ts
        defaults = {ni: [float(w) for w in (doc.gltf.meshes[doc.gltf.nodes[ni].mesh].weights or [])] for ni in tokens}
        weights: dict[str, BlendShapeWeights] = {}
        interpolation: dict[str, str] = {}
        key_times: dict[str, np.ndarray] = {}
        for ai, anim in enumerate(doc.gltf.animations):
            name = anim.name or f"animation{ai}"
            record = recorded_provenance(doc, ai)
            k = 0
            for b, binding in enumerate(scene.bindings):
                clip = sample_animation(doc, ai, binding, fps, name if k == 0 else f"{name}:{binding.skeleton.name}")
                if clip is not None:
                    clips.append(clip)
                    if record is not None:
                        provenance[clip.name] = record
                    w = sample_morph_weights(doc, ai, clip, morph_nodes.get(b, {}), defaults)
                    if w is not None:
                        weights[clip.name] = w
                    used = set(binding.node_to_joint) | set(morph_nodes.get(b, {}))
                    kind = clip_interpolation(doc, ai, used)
                    if kind is not None:
                        interpolation[clip.name] = kind
                    keys = sparse_key_times(doc, ai, used, clip)
                    if keys is not None:
                        key_times[clip.name] = keys
                    k += 1
        materials, images, not_kept = read_materials(doc)
        left_out = left_out_of(scene, meshes) + not_kept
    for thing in left_out:
        _log.info("%s: not read: %s", path, thing)
    non_skin = {}
    for b, binding in enumerate(scene.bindings):
        in_skin = {n for s in binding.skins for n in doc.gltf.skins[s].joints or []}
        names = tuple(binding.skeleton.joint_names[j] for j, n in enumerate(binding.nodes) if n not in in_skin)
        if names:
            non_skin[b] = names
    return Asset(str(path), tuple(b.skeleton for b in scene.bindings), tuple(clips), tuple(meshes),
                 provenance=provenance, left_out=left_out, non_skin_joints=non_skin, blend_shape_weights=weights,
                 interpolation=interpolation, materials=materials, images=images, key_times=key_times)


def left_out_of(scene: GltfScene, meshes: list[SkinnedMesh]) -> tuple[str, ...]:
    """What the file holds that the model does not (materials, morph targets, meshes not
    skinned, cameras, ...), one short phrase each; samplers resampled to frames are named too."""
    g = scene.doc.gltf
    out = []

    def n(count: int, what: str) -> None:
        if count:
            out.append(f"{count} {what}")

    morphed = {i for i in blend_shape_tokens(scene) if mesh_node_binding(scene, i) is not None}
    n(len(g.cameras), "camera(s)")
    weights = sum(1 for a in g.animations for ch in a.channels if ch.target is not None and ch.target.path == "weights"
                  and ch.target.node not in morphed)
    n(weights, "morph weight channel(s) on nodes off the skeletons")
    joints = set()
    for b in scene.bindings:
        joints.update(b.node_to_joint)
    other = sum(1 for a in g.animations for ch in a.channels if ch.target is not None and ch.target.path in _TRS_PATHS
                and ch.target.node not in joints)
    n(sum(1 for a in g.animations if not any(ch.target is not None and ch.target.node in joints and ch.target.path
                                              in _TRS_PATHS for ch in a.channels)), "animation(s) moving no joint")
    n(other, "channel(s) on nodes outside the skeletons")
    mixed = sum(1 for a in g.animations if len({s.interpolation or "LINEAR" for s in a.samplers}) > 1)
    n(mixed, "animation(s) mixing LINEAR, STEP and CUBICSPLINE samplers (sampled per frame, kept as LINEAR)")
    if g.extensionsUsed:
        out.append(f"extension(s) {', '.join(g.extensionsUsed)}")
    return tuple(out)


def recorded_provenance(doc: GltfFile, anim_index: int) -> dict | None:
    """The finger-motion record of the animation's ``extras.usdhands.provenance`` (None when absent;
    a malformed one is named in a warning and left out)."""
    extras = doc.gltf.animations[anim_index].extras
    ours = extras.get(EXTRAS_KEY) if isinstance(extras, dict) else None
    record = ours.get("provenance") if isinstance(ours, dict) else None
    if record is None:
        return None
    try:
        return provenance_record(record if isinstance(record, dict) else {"method": record})
    except (ValueError, TypeError) as e:
        _log.warning("%s: animations[%d]: ignoring extras.%s.provenance (%s)", doc.path, anim_index, EXTRAS_KEY, e)
        return None


@contextlib.contextmanager
def malformed_as_read_error(path):
    """Turn the type and index errors that JSON of the wrong shape causes into one-line
    :class:`AssetReadError` (``"malformed glTF (TypeError: ...)"``)."""
    try:
        yield
    except (TypeError, KeyError, IndexError, AttributeError, ValueError) as e:
        first = str(e).splitlines()[0] if str(e) else ""
        raise AssetReadError(f"malformed glTF ({type(e).__name__}: {first})", path=path) from e

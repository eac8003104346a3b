"""Helpers shared by the USD reader and writers: opening stages, diagnostics, names, matrices.

Conventions at this boundary: ``Gf`` matrices are row-vector (``p' = p M``), the
model's are column-vector, so every matrix array is transposed here; ``Vt.QuatfArray``
holds xyzw in memory, which is the model's order, so quaternion arrays move as they are.
"""

from __future__ import annotations

import contextlib
import errno
import itertools
import math
import os
import stat
import sys
import threading
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np
from pxr import Sdf, Tf, Usd, UsdGeom, UsdSkel, UsdUtils, Vt

from usdhands.errors import AssetReadError
from usdhands.formats.usdc_crate import check_crate_file
from usdhands.model.rotations import matrix_to_quat, quat_canonical, quat_multiply, trs_to_xform, xform_to_trs

__all__ = [
    "SOURCE_JOINT_NAMES_KEY", "SOURCE_SKELETON_KEY", "SOURCE_NAME_KEY", "SOURCE_MESH_KEY", "SOURCE_NODE_KEY",
    "DEFAULT_WEIGHT_KEY", "INTERPOLATION_KEY", "NODE_KEY", "NODE_SCALE_KEY", "KEY_TIMES_KEY", "quiet_diagnostics", "open_stage",
    "open_stage_quietly", "tf_error_reason", "matrices_to_numpy", "numpy_to_matrices", "valid_identifier",
    "unique_name", "joint_tokens_for", "skeleton_tokens_and_names", "bound_animation_path",
    "skeleton_world_xforms", "fold_into_roots", "fold_similarity_into_roots", "world_might_vary", "all_close",
]

#: customData key on a Skeleton prim: the original joint names when the tokens had to be sanitised
SOURCE_JOINT_NAMES_KEY = "usdhands:sourceJointNames"
#: customData key on a SkelAnimation prim: the Skeleton prim it animates (for animations not bound)
SOURCE_SKELETON_KEY = "usdhands:skeleton"
#: customData of a SkelAnimation: the animation's name in the file it was converted from, when
#: the prim name had to differ (``dance-01`` -> prim ``dance_01``); readers restore it.
SOURCE_NAME_KEY = "usdhands:sourceName"
#: customData of a Mesh: the source mesh it is a part of (a glTF mesh with several primitives)
SOURCE_MESH_KEY = "usdhands:sourceMesh"
#: customData of a Mesh: the name of the node that carried it in the source (glTF node)
SOURCE_NODE_KEY = "usdhands:sourceNode"
#: customData of a BlendShape: its weight where no animation drives it (glTF ``mesh.weights``)
DEFAULT_WEIGHT_KEY = "usdhands:defaultWeight"
#: customData of a SkelAnimation: the seconds the source keyed (``Asset.key_times``)
KEY_TIMES_KEY = "usdhands:keyTimes"
#: customData of an Xform usdhands wrote for a source node above the skeleton (glTF ``RobotArmature``)
NODE_KEY = "usdhands:node"
#: customData of such an Xform: the uniform scale moved from it into the root joints (the source
#: node's scale is the authored one times this), so that the bind transforms have scale 1
NODE_SCALE_KEY = "usdhands:nodeScale"
#: customData of a SkelAnimation: the source's sampler interpolation (``STEP``, ``CUBICSPLINE``)
INTERPOLATION_KEY = "usdhands:interpolation"


@contextlib.contextmanager
def quiet_diagnostics() -> Iterator[object]:
    """Collect USD warnings and status messages instead of letting USD print them.

    The library never prints; while a delegate is installed, Tf hands diagnostics to it
    rather than to stderr. Yields the delegate (``TakeUncoalescedDiagnostics()``).

    USD's Python bindings also print, through ``sys.excepthook``, a value they cannot hand
    to Python (a corrupt crate's time sample of an unknown type: ``TypeError: No to_python
    (by-value) converter found for C++ type: ...VtBackgroundType``) before they raise the
    ``Tf.ErrorException`` the caller turns into its one line. That print is dropped on this
    thread while the block runs (:class:`_BindingPrints`); other threads' go on as before.
    """
    delegate = UsdUtils.CoalescingDiagnosticDelegate()
    _BINDING_PRINTS.enter()
    try:
        yield delegate
    finally:
        _BINDING_PRINTS.leave()
        del delegate


class _BindingPrints:
    """``sys.excepthook`` dropping what USD's bindings print on threads inside :func:`quiet_diagnostics`.

    Installed while any thread is inside one (a count under a lock), and only if nobody has
    replaced the hook meanwhile is the previous hook put back; every other call goes to the
    hook that was there before, so an application's own hook keeps working.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._inside = threading.local()
        self._count = 0
        self._previous = None

    def enter(self) -> None:
        self._inside.depth = getattr(self._inside, "depth", 0) + 1
        with self._lock:
            if self._count == 0:
                self._previous = sys.excepthook
                sys.excepthook = self._hook
            self._count += 1

    def leave(self) -> None:
        self._inside.depth -= 1
        with self._lock:
            self._count -= 1
            if self._count == 0:
                if sys.excepthook == self._hook:
                    sys.excepthook = self._previous
                self._previous = None

    def _hook(self, kind, value, tb) -> None:
        if getattr(self._inside, "depth", 0) > 0:
            return  # the bindings' own print: the Tf error that follows is the caller's one line
        (self._previous or sys.__excepthook__)(kind, value, tb)


_BINDING_PRINTS = _BindingPrints()


#: Longest USD error reason quoted in a one-line message.
MAX_REASON_CHARS = 200


def tf_error_reason(err: BaseException, path: str | os.PathLike | None = None) -> str:
    """The first commentary of a ``Tf.ErrorException``, on one line, without the file path."""
    try:
        text = str(err)
    except UnicodeDecodeError:  # USD quotes the offending bytes of a non-UTF-8 text file
        return "not valid UTF-8 text (corrupt or not a USD file)"
    first = text.split("\n\tError in ")[1] if "\n\tError in " in text else text
    if " : '" in first:
        first = first.split(" : '", 1)[1]
        first = first.rsplit("'", 1)[0]
    first = " ".join(first.split())
    if path is not None:
        for p in sorted({str(path), str(Path(path).resolve())}, key=len, reverse=True):  # the longer first
            first = first.replace(f"Corrupt asset @{p}@", "corrupt crate file (USD's reader refused its contents)")
            first = first.replace(f"@{p}@", "the file").replace(f"{p}:", "line ").replace(p, "the file")
    first = first.strip()
    if len(first) > MAX_REASON_CHARS:  # the text parser quotes the whole offending line (a whole array)
        first = first[:MAX_REASON_CHARS - 5].rstrip() + " ..."
    return first or "unknown error"


#: Most layers (the file, its sublayers, references and payloads) checked before a stage opens.
MAX_LAYERS = 10_000


def _children(spec, key: str, path: Path) -> list[str]:
    """The names a spec's children field (``primChildren``, ``properties``...) lists.

    Raises
    ------
    AssetReadError
        The field holds something else than a list of names: in a corrupt crate it held a
        float, a Variability, layer offsets or tokens that are not UTF-8 (usdc fuzz, 3,485
        findings in 5 minutes: TypeError and UnicodeDecodeError tracebacks).
    """
    try:
        if not spec.HasInfo(key):
            return []
        names = list(spec.GetInfo(key))
    except Tf.ErrorException:  # not a field of this kind of spec
        return []
    except UnicodeDecodeError:
        raise AssetReadError(f"cannot read as USD: {key} of <{spec.path}> holds names that are not UTF-8",
                             path=path) from None
    except TypeError:  # not iterable, or a value Python cannot hold
        raise AssetReadError(f"cannot read as USD: {key} of <{spec.path}> holds no list of names", path=path) from None
    if not all(map(isinstance, names, itertools.repeat(str, len(names)))):
        raise AssetReadError(f"cannot read as USD: {key} of <{spec.path}> holds no list of names", path=path)
    return names


def check_children(layer: Sdf.Layer, path: Path, listed: bool = False) -> None:
    """Every child a crate layer's specs list (prims, variant sets, variants, properties) has a spec.

    A crate file stores the lists apart from the specs: a child listed without one aborted
    the interpreter while USD composed the stage ('Dereferenced an invalid SdfPrimSpec',
    usdc fuzz). Text layers list what they define and are not walked.

    ``listed``: the crate's bytes showed it already (``check_crate_file``'s ``children_listed``, the
    compiled decision, which says so only where it is simple: plain names, no variant sets, every
    index in its table); nothing is walked then. Otherwise the layer is walked through Sdf
    (:func:`_walk_children`: ~75 us on CesiumMan.usdz, the decision ~2), the reference, which gives
    the errors.

    Raises
    ------
    AssetReadError
        Naming the first listed child that has no spec.
    """
    if not listed:
        _walk_children(layer, path)


def _walk_children(layer: Sdf.Layer, path: Path) -> None:
    """:func:`check_children`'s walk of the layer through Sdf (the reference of the compiled decision)."""
    def missing(where, key: str, child) -> AssetReadError:
        return AssetReadError(f"cannot read as USD: {key} of <{where}> lists <{child}>, which has no spec", path=path)

    spec_at = layer.GetObjectAtPath
    root = spec_at(Sdf.Path.absoluteRootPath)
    if root is None:  # a crate without its pseudo-root's spec (usdc fuzz): USD aborted reading the stage's metadata
        raise AssetReadError("cannot read as USD: the layer has no spec for its pseudo-root", path=path)
    todo = [(Sdf.Path.absoluteRootPath, root)]  # each prim with its spec, looked up once
    while todo:
        here, spec = todo.pop()
        for name in _children(spec, "primChildren", path):
            child = here.AppendChild(name)
            child_spec = None if child.isEmpty else spec_at(child)
            if child_spec is None:
                raise missing(here, "primChildren", child if not child.isEmpty else name)
            todo.append((child, child_spec))
        for name in _children(spec, "variantSetChildren", path):
            variant_set = here.AppendVariantSelection(name, "")
            vs_spec = None if variant_set.isEmpty else spec_at(variant_set)
            if vs_spec is None:
                raise missing(here, "variantSetChildren", variant_set if not variant_set.isEmpty else name)
            for variant in _children(vs_spec, "variantChildren", path):
                child = here.AppendVariantSelection(name, variant)
                child_spec = None if child.isEmpty else spec_at(child)
                if child_spec is None:
                    raise missing(variant_set, "variantChildren", child if not child.isEmpty else variant)
                todo.append((child, child_spec))
        for name in _children(spec, "properties", path):
            child = here.AppendProperty(name)
            if child.isEmpty or spec_at(child) is None:
                raise missing(here, "properties", child if not child.isEmpty else name)


def checked_layers(path: Path) -> list[Sdf.Layer]:
    """Open ``path`` and every local layer it composes, each crate file checked first.

    USD opens sublayers, references and payloads while it composes a stage: a text layer
    naming a crafted .usdc would hand it to USD's crate reader unchecked (a segfault with
    a token index past the table). Each layer is checked (:func:`check_crate_file`) before
    ``Sdf.Layer.FindOrOpen`` reads its structure, then its composition dependencies are
    followed. Returns the opened layers (keep them alive until the stage is open): the first is
    ``path``'s own (none when it did not open: nothing else is followed then).

    Raises
    ------
    AssetReadError
        A crate file (the input or one it composes) whose claims its bytes cannot hold.
    """
    held, seen, todo = [], set(), [Path(path)]
    first = True
    while todo and len(seen) < MAX_LAYERS:
        here = todo.pop()
        if first:  # the caller's file: its real path (a walk of its folders) only if another layer comes
            first, key = False, None
            if not os.path.isfile(here):
                continue  # not a regular file (a pipe, a device): USD says what it makes of it
        else:
            try:
                key = os.path.realpath(here)
            except ValueError:  # a NUL in a path a layer composes (usdz fuzz): no file; USD reports the layer missing
                continue
            if None in seen:  # the first layer's real path, now that another is compared with it
                seen.discard(None)
                seen.add(os.path.realpath(path))
            if key in seen or not os.path.isfile(key):
                continue  # a missing layer: USD reports it (a warning) when it composes
        seen.add(key)
        try:
            crate, listed = check_crate_file(here)
            layer = Sdf.Layer.FindOrOpen(str(here))
            if crate and layer is not None:
                check_children(layer, here, listed)
        except OSError as e:
            raise AssetReadError(f"cannot read ({e.strerror or e})", path=here) from None
        except AssetReadError as e:
            if here == Path(path):
                raise
            raise AssetReadError(f"composes {here}: {e.message}", path=path) from None
        if layer is None:
            continue
        held.append(layer)
        for asset in layer.GetCompositionAssetDependencies():
            if "://" in asset or asset.startswith("anon:"):
                continue
            todo.append(Path(layer.ComputeAbsolutePath(asset).split("[", 1)[0]))  # a package member: the package
    return held


def open_stage(path: str | os.PathLike) -> Usd.Stage:
    """Open a USD file, all payloads loaded.

    Raises
    ------
    AssetReadError
        Missing, truncated or corrupt files, one line with the path.
    """
    with quiet_diagnostics():
        return open_stage_quietly(path)


#: The errors of a stat that Path.exists answers False for: no such file
_NOT_THERE = (errno.ENOENT, errno.ENOTDIR, errno.EBADF, errno.ELOOP)


def open_stage_quietly(path: str | os.PathLike) -> Usd.Stage:
    """:func:`open_stage` inside the caller's :func:`quiet_diagnostics` block (a reader that reads the
    stage in the same block enters it once: 15-30 us a block)."""
    path = Path(path)
    try:  # one stat: Path.exists then Path.is_dir took two
        mode = os.stat(path).st_mode
    except OSError as e:
        if e.errno not in _NOT_THERE:
            raise  # (a permission refused...: as Path.exists raised it)
        raise AssetReadError("no such file", path=path) from None
    except ValueError:  # a NUL in the path
        raise AssetReadError("no such file", path=path) from None
    if stat.S_ISDIR(mode):
        raise AssetReadError("is a folder, not a file", path=path)
    try:
        layers = checked_layers(path)  # held open: Stage.Open finds them in USD's layer registry
        # the checked root layer itself when it opened (first held): USD does not look the path up and
        # resolve it again (0.08 -> 0.04 ms on CesiumMan.usdz); the same stage and resolver context
        root = layers[0] if layers else str(path)
        stage = Usd.Stage.Open(root, Usd.Stage.LoadAll)
    except Tf.ErrorException as e:
        raise AssetReadError(f"cannot read as USD: {tf_error_reason(e, path)}", path=path) from None
    del layers
    if stage is None:
        raise AssetReadError("cannot read as USD", path=path)
    return stage


def matrices_to_numpy(value) -> np.ndarray:
    """``Vt.Matrix4dArray`` (row vectors) → ``(N, 4, 4)`` float64 for column vectors."""
    a = np.asarray(value, dtype=np.float64).reshape(-1, 4, 4)
    return np.ascontiguousarray(np.swapaxes(a, -1, -2))


def numpy_to_matrices(m: np.ndarray) -> Vt.Matrix4dArray:
    """``(N, 4, 4)`` column-vector transforms → ``Vt.Matrix4dArray`` (row vectors)."""
    m = np.asarray(m, dtype=np.float64).reshape(-1, 4, 4)
    return Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(np.swapaxes(m, -1, -2)))


def valid_identifier(name: str) -> str:
    """A USD prim/joint identifier made from any string (``"Palm1.L"`` → ``"Palm1_L"``)."""
    return Tf.MakeValidIdentifier(str(name)) or "_"


def unique_name(name: str, used: set[str]) -> str:
    """``name``, or ``name_2``, ``name_3``... whichever is not in ``used``; adds it to ``used``."""
    out, k = name, 1
    while out in used:
        k += 1
        out = f"{name}_{k}"
    used.add(out)
    return out


def joint_tokens_for(names: Sequence[str], parents: Sequence[int]) -> list[str]:
    """UsdSkel joint tokens (paths of valid identifiers) for a skeleton's joint names.

    A name that already is its parent's token plus one valid identifier is kept as it
    is, so names read from USD come back unchanged; any other name (glTF
    ``"mixamorig:Hips"``, ``"Palm1.L"``) becomes a valid identifier under its parent's
    token, made unique among its siblings.

    Parameters
    ----------
    names : sequence of str, length J
    parents : (J,) int
        Parent index per joint, -1 for roots, parents first.
    """
    tokens: list[str] = []
    used: dict[int, set[str]] = {}
    for j, (name, p) in enumerate(zip(names, parents)):
        p = int(p)
        name = str(name)
        if p < 0:
            leaf = name
        else:
            prefix = str(names[p]) + "/"
            leaf = name[len(prefix):] if name.startswith(prefix) else name
        ident = valid_identifier(leaf) if "/" not in leaf else valid_identifier(leaf.replace("/", "_"))
        ident = unique_name(ident, used.setdefault(p, set()))
        tokens.append(ident if p < 0 else f"{tokens[p]}/{ident}")
    return tokens


def skeleton_tokens_and_names(skel: UsdSkel.Skeleton, path=None) -> tuple[list[str], list[str]]:
    """The joint tokens of a Skeleton prim and the names the model uses for them.

    The names are the tokens, unless the prim's customData ``usdhands:sourceJointNames``
    (written by :mod:`usdhands.formats.usd_write`) holds one original name per joint, or
    else UsdSkel's own ``jointNames`` attribute holds one name per joint that differs from
    the tokens' last elements (``mixamorig:Hips`` for the token ``mixamorig_Hips``): then
    the names are the tokens' paths with each element replaced by its joint's name.
    """
    joints = skel.GetJointsAttr().Get()
    if joints is not None and not isinstance(joints, (Vt.TokenArray, Vt.StringArray, list, tuple)):
        # a corrupt crate's joints held a Variability (usdc fuzz: 'not iterable' TypeError)
        raise AssetReadError(f"joints holds a {type(joints).__name__}, not token[]", path=path,
                             location=str(skel.GetPath()))
    tokens = [str(t) for t in (joints or [])]
    names = list(tokens)
    stored = skel.GetPrim().GetCustomDataByKey(SOURCE_JOINT_NAMES_KEY)
    if stored is not None and len(stored) == len(tokens) and len(set(map(str, stored))) == len(tokens):
        return tokens, [str(n) for n in stored]
    attr = skel.GetJointNamesAttr()
    short = [str(n) for n in (attr.Get() or [])] if attr and attr.HasAuthoredValue() else []
    if len(short) == len(tokens) and short != [t.rsplit("/", 1)[-1] for t in tokens] and all(short):
        by_token = dict(zip(tokens, short))
        full = []
        for t in tokens:
            parts = t.split("/")
            full.append("/".join(by_token.get("/".join(parts[:k + 1]), parts[k]) for k in range(len(parts))))
        if len(set(full)) == len(full):
            names = full
    return tokens, names


def bound_animation_path(skel_prim: Usd.Prim) -> Sdf.Path | None:
    """The SkelAnimation bound to a Skeleton prim through ``skel:animationSource``, if any."""
    binding = UsdSkel.BindingAPI(skel_prim)
    rel = binding.GetAnimationSourceRel()
    if rel:
        targets = rel.GetForwardedTargets()
        if targets:
            return targets[0]
    return None


_EYE4 = np.eye(4)


def all_close(a, b, rtol: float = 1e-5, atol: float = 1e-8) -> bool:
    """``np.allclose(a, b, rtol, atol)``, without its ``isclose`` machinery where every ``b`` is finite
    (a few microseconds instead of ~15-25: the readers call it for each skeleton and clip).

    ``|a - b| <= atol + rtol |b|`` everywhere is numpy's own answer where every ``b`` is finite and
    the tolerances are not negative (its ``| (a == b)`` adds nothing there: an equal ``a`` passes the
    test, an infinite or NaN ``a`` fails both); any other case is numpy's answer.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if np.isfinite(b).all() and atol >= 0 and rtol >= 0:
        with np.errstate(invalid="ignore", over="ignore"):
            return bool((np.abs(a - b) <= atol + rtol * np.abs(b)).all())
    return bool(np.allclose(a, b, rtol=rtol, atol=atol))


def world_might_vary(prim: Usd.Prim) -> bool:
    """Whether the local-to-world transform of ``prim`` may change over time."""
    p = prim
    while p and not p.IsPseudoRoot():
        x = UsdGeom.Xformable(p)
        if x:
            if x.TransformMightBeTimeVarying():
                return True
            if x.GetResetXformStack():
                break
        p = p.GetParent()
    return False


def skeleton_world_xforms(prim: Usd.Prim, time_codes: Sequence[float] | None = None,
                          earliest: np.ndarray | None = None) -> np.ndarray | None:
    """The local-to-world transform of a Skeleton prim (its own xformOps and its ancestors').

    Parameters
    ----------
    prim : Usd.Prim
    time_codes : (T,) float, optional
        Times to evaluate at; the earliest time when omitted.
    earliest : (4, 4) float, optional
        What this function gave for ``prim`` without ``time_codes`` (not None: a transform that
        is not the identity), so that a transform that does not vary is not computed again.

    Returns
    -------
    (T, 4, 4) float64 or None
        Column-vector transforms, one per time code (``(1, 4, 4)`` without
        ``time_codes``); None when the transform is the identity at every time.
        A transform that does not vary over time is computed once and repeated.
    """
    if time_codes is None or not world_might_vary(prim):
        n = 1 if time_codes is None else len(time_codes)
        if earliest is not None:
            return np.repeat(np.asarray(earliest, dtype=np.float64)[None], n, axis=0)
        m = matrices_to_numpy([UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.EarliestTime())])
        if all_close(m[0], _EYE4, rtol=0, atol=1e-12):
            return None
        return np.repeat(m, n, axis=0)
    cache = UsdGeom.XformCache()
    out = np.empty((len(time_codes), 4, 4))
    for i, t in enumerate(time_codes):
        cache.SetTime(Usd.TimeCode(float(t)))
        out[i] = np.asarray(cache.GetLocalToWorldTransform(prim), dtype=np.float64).T
    if all_close(out, _EYE4, rtol=0, atol=1e-12):
        return None
    return out


def fold_into_roots(parents: np.ndarray, world: np.ndarray, translations: np.ndarray, rotations: np.ndarray,
                    scales: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pre-multiply the root joints' local transforms by ``world`` at each frame.

    Parameters
    ----------
    parents : (J,) int
        -1 marks a root.
    world : (T, 4, 4) float
        Column-vector transform per frame (the inverse of a prim's local-to-world
        unfolds instead).
    translations : (T, J, 3) float
    rotations : (T, J, 4) float, xyzw
    scales : (T, J, 3) float

    Returns
    -------
    translations, rotations, scales
        float64 copies with the roots changed; rotations keep the hemisphere of
        ``q_world * q`` (``q_world`` with w >= 0), so curves stay continuous and folding
        with a transform then unfolding with its inverse gives the same signs back. A world transform with shear
        relative to a root (non-uniform scale under rotation) cannot be held by T, R, S
        and is approximated by :func:`~usdhands.model.rotations.xform_to_trs`.
    """
    t = np.array(translations, dtype=np.float64)
    q = np.array(rotations, dtype=np.float64)
    s = np.array(scales, dtype=np.float64)
    roots = np.flatnonzero(np.asarray(parents) < 0)
    if not len(roots) or not len(t):
        return t, q, s
    world = np.asarray(world, dtype=np.float64)
    m = world[:, None] @ trs_to_xform(t[:, roots], q[:, roots], s[:, roots])
    # w >= 0: the inverse transform gives the conjugate. A transform that does not move (a Z-up
    # skeleton's) is split once: the same numbers as split at every frame. The world transforms are
    # split in the same call as the roots' (every step works matrix by matrix: the same numbers,
    # ~45 NumPy calls fewer)
    one = len(world) > 1 and bool((world == world[:1]).all())
    own = world[:1] if one else world
    nt, nq, ns = xform_to_trs(np.concatenate([m.reshape(-1, 4, 4), own]))
    n = m.shape[0] * m.shape[1]
    qw = quat_canonical(nq[n:])
    shape = m.shape[:2]
    nt, nq, ns = nt[:n].reshape(shape + (3,)), nq[:n].reshape(shape + (4,)), ns[:n].reshape(shape + (3,))
    ref = quat_multiply(np.broadcast_to(qw[:, None], q[:, roots].shape), q[:, roots])
    nq = np.where((np.sum(nq * ref, axis=-1) < 0)[..., None], -nq, nq)
    t[:, roots], q[:, roots], s[:, roots] = nt, nq, ns
    return t, q, s


#: How far from a rotation times one scale (relative to the scale squared) a world transform's
#: columns may be for :func:`fold_similarity_into_roots` (``matrix_to_quat`` takes matrices this
#: close to orthogonal as they are).
SIMILARITY_TOL = 1e-12


def fold_similarity_into_roots(parents: np.ndarray, world: np.ndarray, translations: np.ndarray,
                               rotations: np.ndarray, scales: np.ndarray
                               ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """:func:`fold_into_roots` of one world transform at every frame that is a rotation times a
    uniform scale ``c > 0`` plus a translation (a Z-up stage's, a unit scale), with positive finite
    root scales and finite non-zero root rotations: the products taken apart as quaternions and
    vectors (``q_world * q / |q|``, ``c R t + w``, ``c s``) instead of as matrices at every frame.
    The same numbers within ~1e-15 relative (both are exact for such transforms; they round
    differently), the same hemisphere; None where this does not apply (the caller folds with
    :func:`fold_into_roots`, which also raises what it raises there).

    Parameters
    ----------
    world : (4, 4) float
        Column-vector transform, the same at every frame.
    translations, rotations, scales
        As :func:`fold_into_roots` (``(T, J, 3)``, ``(T, J, 4)`` xyzw, ``(T, J, 3)``).
    """
    world = np.asarray(world, dtype=np.float64)
    if world.shape != (4, 4) or not (np.isfinite(world).all() and (world[3] == (0.0, 0.0, 0.0, 1.0)).all()):
        return None
    a = world[:3, :3]
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = a.tolist()
    gram = a.T @ a
    c2 = float(gram.trace()) / 3.0
    det = a00 * (a11 * a22 - a12 * a21) - a01 * (a10 * a22 - a12 * a20) + a02 * (a10 * a21 - a11 * a20)
    if not (1e-150 < c2 < 1e150 and det > 0 and float(np.abs(gram - c2 * _EYE4[:3, :3]).max()) <= SIMILARITY_TOL * c2):
        return None
    roots = np.flatnonzero(np.asarray(parents) < 0)
    t = np.array(translations, dtype=np.float64)
    q = np.array(rotations, dtype=np.float64)
    s = np.array(scales, dtype=np.float64)
    if not len(roots) or not len(t):
        return t, q, s
    qr, sr = q[:, roots], s[:, roots]
    with np.errstate(all="ignore"):
        norm = np.sqrt(np.einsum("...i,...i->...", qr, qr))[..., None]
        if not (np.isfinite(qr).all() and (norm > 0).all() and (sr > 0).all() and np.isfinite(sr).all()):
            return None
    c = c2 ** 0.5
    t[:, roots] = t[:, roots] @ a.T + world[:3, 3]
    ax, ay, az, aw = _rotation_quat(a / c)  # w >= 0: the hemisphere this fold gave
    b = qr / norm
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    out = np.empty_like(b)  # quat_multiply's products and sums, in its order, with one of them four numbers
    out[..., 0] = aw * bx + ax * bw + ay * bz - az * by
    out[..., 1] = aw * by - ax * bz + ay * bw + az * bx
    out[..., 2] = aw * bz + ax * by - ay * bx + az * bw
    out[..., 3] = aw * bw - ax * bx - ay * by - az * bz
    q[:, roots] = out
    s[:, roots] = c * sr
    return t, q, s


def _rotation_quat(r: np.ndarray) -> tuple[float, float, float, float]:
    """``quat_canonical(matrix_to_quat(r))`` of one ``(3, 3)`` float64 rotation, as four floats: the same
    numbers (Markley's method in the same operations, on Python floats: ~3 us instead of ~30 for
    NumPy's calls on one matrix); a matrix ``matrix_to_quat`` would first make orthogonal (its SVD
    branch) goes to it."""
    f0, f1, f2, f3, f4, f5, f6, f7, f8 = r.ravel().tolist()
    # matrix_to_quat's test of r r^T against the identity (1e-12 + 1e-5 on the diagonal, 1e-12 off it)
    diagonal_ok = all(abs(a * a + b * b + c * c - 1.0) <= 1e-12 + 1e-5
                      for a, b, c in ((f0, f1, f2), (f3, f4, f5), (f6, f7, f8)))
    if not (diagonal_ok and abs(f0 * f3 + f1 * f4 + f2 * f5) <= 1e-12 and abs(f0 * f6 + f1 * f7 + f2 * f8) <= 1e-12
            and abs(f3 * f6 + f4 * f7 + f5 * f8) <= 1e-12):
        x, y, z, w = quat_canonical(matrix_to_quat(r)).tolist()
        return x, y, z, w
    trace = f0 + f4 + f8
    s01, s02, s12 = f3 + f1, f6 + f2, f7 + f5
    x, y, z = f7 - f5, f2 - f6, f3 - f1
    rest = 1 - trace
    diagonal = (f0, f4, f8, trace)
    choice = diagonal.index(max(diagonal))  # the first of equal ones, as argmax
    q = ((rest + 2 * f0, s01, s02, x), (s01, rest + 2 * f4, s12, y), (s02, s12, rest + 2 * f8, z),
         (x, y, z, 1 + trace))[choice]
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    x, y, z, w = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    return (-x, -y, -z, -w) if w < 0 else (x, y, z, w)

"""A finger-motion database: wrist features, finger curves, segments, labels and origins.

Content. Each clip contributes one **track** per hand that has fingers: per frame, the
wrist features of eq. 1 (position relative to the root in cm, scaled to the
database's reference body size, and the wrap-free rotation features; see
:mod:`usdhands.algorithms.synthesis.wrist_features`) and the canonical finger DOF curves
(degrees; see :mod:`usdhands.algorithms.synthesis.finger_transfer`), all resampled to one
frame rate. Tracks are cut into segments by wrist speed (§3.1). With mirroring,
every track gets a left↔right mirrored twin on the other side.

On disk (format ``usdhands-finger-database``, version 2) a database is a folder::

    DB/manifest.json   metadata, validated by schemas/database.schema.json
    DB/features.npy    (F, 12) float32  wrist position (cm) and rotation matrix entries ("deg")
    DB/fingers.npy     (F, M) float32   finger DOF curves (deg), the M DOFs of dof_index
    DB/tracks.npy      (R, 5) int64     start, stop (frames), clip, side (0 left, 1 right), mirrored
    DB/segments.npy    (N, 3) int64     start, stop (frames), track
    DB/arm_features.npy (F, C) float32  optional: other arm feature columns (elbow, shoulder, velocities,
                                        the other hand), listed in the manifest's arm_features

Frames of all tracks are concatenated in ``features`` and ``fingers``. The manifest
lists the clips (name, source file, animation, label), the labels, the frame rate,
the reference reach, the DOFs stored (``dof_index`` into the canonical layout of 60
DOFs, names in ``dofs``), the segmentation parameters, and for every array its file,
shape and dtype. Arrays are loaded memory-mapped, so a large database costs no
memory until read. Version 1 stored rotation vectors (which wrap) as features;
loading one is refused with a message to rebuild it.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from usdhands import __version__
from usdhands.algorithms.synthesis.finger_transfer import (
    NUM_DOFS, dof_names, hand_rig, canonical_curves, mirror_curves,
)
from usdhands.algorithms.synthesis.segmentation import segment_by_speed, wrist_speed
from usdhands.algorithms.synthesis.config import SegmentationConfig
from usdhands.algorithms.synthesis.wrist_features import (
    NUM_WRIST_FEATURES, WRIST_FEATURE_NAMES, mirror_features, reach_cm, world_xforms_for, wrist_features,
)
from usdhands.deferred_signals import signals_deferred
from usdhands.errors import ConfigError
from usdhands.input_files import check_regular_file, read_json
from usdhands.json_schemas import first_schema_error, load_schema
from usdhands.model.clip import Clip
from usdhands.model.handmap import SIDES, HandMap

__all__ = ["FORMAT", "VERSION", "same_rate", "DatabaseClip", "FingerDatabase", "build_database", "load_database",
           "save_database", "segment_track", "database_schema"]

FORMAT = "usdhands-finger-database"
VERSION = 2
ARRAYS = ("features", "fingers", "tracks", "segments")
OPTIONAL_ARRAY = "arm_features"


@dataclass(frozen=True)
class DatabaseClip:
    """One input of :func:`build_database`: a clip with fingers, its hands, label and origin."""

    clip: Clip
    handmap: HandMap
    label: str | None = None
    source: str = ""


@dataclass(frozen=True, eq=False)
class FingerDatabase:
    """A loaded (or freshly built) database; see the module notes for the layout.

    Attributes
    ----------
    fps : float
    reach_cm : float
        Reference body size the features are scaled to.
    features : (F, 12) float
        Wrist features (:data:`~usdhands.algorithms.synthesis.wrist_features.WRIST_FEATURE_NAMES`).
    fingers : (F, M) float
    dof_index : (M,) int
        Canonical DOF (0..59) of each column of ``fingers``.
    tracks : (R, 5) int
    segments : (N, 3) int
    clips : list of dict
        ``{"name", "source", "animation", "label"}``.
    segmentation : dict
        The segmentation parameters used.
    hands : dict
        Per side, the rest geometry of a hand of the database
        (:func:`usdhands.algorithms.synthesis.hand_graft.hand_template`), for grafting.
    path : Path or None
    arm_features : (F, C) float or None
        Columns of other feature keys (:mod:`~usdhands.algorithms.synthesis.feature_sets`),
        laid out as ``arm_feature_names``.
    arm_feature_names : tuple of str
        Feature keys in ``arm_features``, in order (``"elbow_pos"``, ``"other_wrist_vel"``...).
    """

    fps: float
    reach_cm: float
    features: np.ndarray
    fingers: np.ndarray
    dof_index: np.ndarray
    tracks: np.ndarray
    segments: np.ndarray
    clips: list
    segmentation: dict = field(default_factory=dict)
    hands: dict = field(default_factory=dict)
    path: Path | None = None
    arm_features: np.ndarray | None = None
    arm_feature_names: tuple = ()

    @property
    def labels(self) -> list[str]:
        """Distinct clip labels, sorted."""
        return sorted({c["label"] for c in self.clips if c.get("label") is not None})

    @property
    def num_frames(self) -> int:
        return int(self.features.shape[0])

    def dof_mask(self) -> np.ndarray:
        """``(NUM_DOFS,)`` bool: canonical DOFs the database holds."""
        m = np.zeros(NUM_DOFS, dtype=bool)
        m[self.dof_index] = True
        return m

    def moving_dofs(self, frames: np.ndarray | None = None) -> np.ndarray:
        """``(M,)`` bool: columns of ``fingers`` that move anywhere (range over 1e-3°).

        The transition cost and the seam thresholds average over these only. ``frames``
        ``(F,)`` bool limits the frames looked at (k-fold: those outside the held-out
        windows, so nothing of them reaches synthesis).
        """
        def compute(sel):
            f = np.asarray(self.fingers)[sel]
            return (f.max(axis=0) - f.min(axis=0)) > 1e-3 if len(f) else np.zeros(f.shape[1], bool)

        return self._cached("moving", frames, compute)

    def step_limits(self, percentile: float, frames: np.ndarray | None = None) -> np.ndarray:
        """``(M,)`` float: per column of ``fingers``, the ``percentile`` of its frame steps
        inside tracks, degrees (:func:`~usdhands.algorithms.synthesis.output_warp.step_limits`);
        ``frames`` as in :meth:`moving_dofs`."""
        from usdhands.algorithms.synthesis.output_warp import step_limits

        return self._cached(("steps", float(percentile)), frames,
                            lambda sel: step_limits(self.fingers, self.tracks, percentile,
                                                    None if isinstance(sel, slice) else sel))

    def _cached(self, key, frames, compute):
        """``compute(frames or slice(None))``, remembered per key and frame selection."""
        cache = self.__dict__.setdefault("_cache", {})
        if frames is None:
            full = (key, None)
            if full not in cache:
                cache[full] = compute(slice(None))
            return cache[full]
        frames = np.asarray(frames, dtype=bool)
        if frames.shape != (self.num_frames,):
            raise ValueError(f"Expected frames ({self.num_frames},) bool, got {frames.shape}")
        sel_key = (key, np.packbits(frames).tobytes())
        if sel_key not in cache:
            if len(cache) > 64:  # k-fold asks for one selection per fold; keep the cache bounded
                cache.clear()
            cache[sel_key] = compute(frames)
        return cache[sel_key]

    def segment_frames(self, segments: np.ndarray) -> np.ndarray:
        """``(F,)`` bool: frames inside the segments selected by ``segments`` ``(N,)`` bool."""
        sel = np.asarray(segments, dtype=bool)
        if sel.shape != (len(self.segments),):
            raise ValueError(f"Expected segments ({len(self.segments)},) bool, got {sel.shape}")
        edges = np.zeros(self.num_frames + 1, dtype=np.int64)
        np.add.at(edges, self.segments[sel, 0], 1)
        np.add.at(edges, self.segments[sel, 1], -1)
        return np.cumsum(edges[:-1]) > 0

    def segment_side(self) -> np.ndarray:
        """``(N,)`` int: 0 left, 1 right."""
        return self.tracks[self.segments[:, 2], 3]

    def segment_clip(self) -> np.ndarray:
        """``(N,)`` int: clip index of each segment."""
        return self.tracks[self.segments[:, 2], 2]

    def segment_labels(self) -> list:
        """Label of each segment's clip (None where unlabelled)."""
        return [self.clips[c].get("label") for c in self.segment_clip()]

    def full_curves(self, rows: np.ndarray | slice) -> np.ndarray:
        """Finger rows expanded to the canonical layout, ``(n, NUM_DOFS)`` float64 (zeros elsewhere)."""
        f = np.asarray(self.fingers[rows], dtype=np.float64)
        out = np.zeros((len(f), NUM_DOFS))
        out[:, self.dof_index] = f
        return out

    def manifest(self) -> dict:
        """The manifest dict written beside the arrays."""
        extra = {} if self.arm_features is None else {"arm_features": list(self.arm_feature_names)}
        return {
            "format": FORMAT,
            "version": VERSION,
            "created_by": f"usdhands {__version__}",
            "fps": float(self.fps),
            "reach_cm": float(self.reach_cm),
            "feature_names": list(WRIST_FEATURE_NAMES),
            "dofs": [dof_names()[i] for i in self.dof_index],
            "dof_index": [int(i) for i in self.dof_index],
            "clips": [dict(c) for c in self.clips],
            "labels": self.labels,
            "segmentation": dict(self.segmentation),
            "hands": dict(self.hands),
            "counts": {"frames": self.num_frames, "tracks": int(len(self.tracks)),
                       "segments": int(len(self.segments)), "clips": len(self.clips)},
            **extra,
            "arrays": {name: {"file": f"{name}.npy", "shape": list(getattr(self, name).shape),
                              "dtype": str(getattr(self, name).dtype)} for name in self._array_names()},
        }

    def _array_names(self) -> tuple:
        return ARRAYS if self.arm_features is None else ARRAYS + (OPTIONAL_ARRAY,)


def same_rate(a: float, b: float) -> bool:
    """Whether two frame rates are the same up to the rounding of file formats.

    BVH stores the frame time with six decimals (30 fps reads back as 30.0003), so
    rates within 1e-4 (relative) are taken as equal and not resampled.
    """
    return abs(a - b) <= 1e-4 * max(a, b)


def segment_track(features: np.ndarray, fps: float, config: SegmentationConfig) -> np.ndarray:
    """Segment boundaries ``(N+1,)`` of one track from its wrist features ``(T, D)`` (positions first, cm)."""
    speed = wrist_speed(features[:, :3], fps, config.speed_smoothing_s)
    return segment_by_speed(speed, fps, config.speed_threshold_cm_s, config.min_segment_s, config.max_segment_s)


def build_database(items: list[DatabaseClip], fps: float = 30.0, mirror: bool = False,
                   segmentation: SegmentationConfig | None = None, progress=None,
                   arm_features=()) -> FingerDatabase:
    """Build a database in memory.

    Parameters
    ----------
    items : list of DatabaseClip
    fps : float
        Frame rate every clip is resampled to.
    mirror : bool
        Add a left↔right mirrored twin of every track.
    segmentation : SegmentationConfig, optional
    progress : callable, optional
        ``progress(done, total, label)``.
    arm_features : sequence of str
        Feature keys besides the wrist's to store (``arm_features.npy``), e.g. the
        :func:`~usdhands.algorithms.synthesis.feature_sets.extra_keys` of a configuration.

    Raises
    ------
    ValueError
        No clip has a hand with fingers, or a feature key names a joint some hand map
        lacks.
    """
    seg_cfg = segmentation or SegmentationConfig()
    from usdhands.algorithms.synthesis.hand_graft import hand_template, mirror_template

    prepared = []  # (clip index, side, features unscaled (T,12) pos in cm, curves, reach, rig mask)
    clips_meta = []
    hands: dict = {}
    for ci, item in enumerate(items):
        clip = item.clip if same_rate(item.clip.fps, fps) else item.clip.resample(fps)
        clips_meta.append({"name": clip.name, "source": str(item.source), "animation": clip.name,
                           "label": item.label})
        world = clip.world_xforms()
        for hand in item.handmap.sides:
            if not hand.finger_joints:
                continue
            rig = hand_rig(clip.skeleton, hand)
            feats = wrist_features(clip, hand, 1.0, world)
            curves = canonical_curves(clip, rig)
            prepared.append((ci, SIDES.index(hand.side), feats, curves, reach_cm(clip.skeleton, hand), rig.present,
                             (clip, item.handmap)))
            if hand.side not in hands:
                hands[hand.side] = hand_template(clip.skeleton, hand)
        if progress:
            progress(ci + 1, len(items), clip.name)
    if not prepared:
        raise ValueError("No clip has a hand with finger joints; nothing to put in the database")
    if mirror:
        for side, other in (("left", "right"), ("right", "left")):
            if side not in hands and other in hands:
                hands[side] = mirror_template(hands[other])
    keys = list(dict.fromkeys(arm_features))
    ref_reach = float(np.median([p[4] for p in prepared]))
    present = np.logical_and.reduce([p[5] for p in prepared])
    dof_index = np.nonzero(np.repeat(present, 3))[0]
    feats_all, fing_all, arm_all, tracks, segments = [], [], [], [], []
    start = 0
    variants = [False, True] if mirror else [False]
    for ci, side, feats, curves, reach, _, (clip, handmap) in prepared:
        arm = None
        if keys:
            from usdhands.algorithms.synthesis.feature_sets import hand_columns, mirror_columns

            arm = hand_columns(clip, handmap, SIDES[side], keys, ref_reach,
                               world_xforms_for(clip, [h for h in handmap.sides]))
        scaled = feats.copy()
        scaled[:, :3] *= ref_reach / reach
        bounds = segment_track(scaled, fps, seg_cfg)
        for mirrored in variants:
            f = mirror_features(scaled) if mirrored else scaled
            c = mirror_curves(curves) if mirrored else curves
            s = 1 - side if mirrored else side
            T = len(f)
            ti = len(tracks)
            tracks.append((start, start + T, ci, s, int(mirrored)))
            for a, b in zip(bounds[:-1], bounds[1:]):
                segments.append((start + a, start + b, ti))
            feats_all.append(f)
            fing_all.append(c[:, dof_index])
            if arm is not None:
                arm_all.append(np.concatenate([mirror_columns(key, arm[key]) if mirrored else arm[key]
                                               for key in keys], axis=1))
            start += T
    return FingerDatabase(
        fps=float(fps), reach_cm=ref_reach,
        features=np.concatenate(feats_all).astype(np.float32),
        fingers=np.concatenate(fing_all).astype(np.float32),
        dof_index=dof_index.astype(np.int64),
        tracks=np.array(tracks, dtype=np.int64).reshape(-1, 5),
        segments=np.array(segments, dtype=np.int64).reshape(-1, 3),
        clips=clips_meta,
        segmentation={k: float(v) for k, v in vars(seg_cfg).items()},
        hands=hands,
        arm_features=np.concatenate(arm_all).astype(np.float32) if keys else None,
        arm_feature_names=tuple(keys),
    )


def database_schema() -> dict:
    """The JSON schema of a manifest (shipped in ``usdhands/schemas``)."""
    return load_schema("database")


def _unused_name(path: Path, tag: str) -> Path:
    """A hidden name beside ``path`` that no file has now (``.NAME.TAGxxxxxxxx``)."""
    import secrets

    while True:
        candidate = path.with_name(f".{path.name}.{tag}{secrets.token_hex(4)}")
        if not os.path.lexists(candidate):
            return candidate


def save_database(db: FingerDatabase, path: str | os.PathLike) -> Path:
    """Write ``db`` to the folder ``path`` (created; replaced atomically if it exists as a database).

    Raises
    ------
    ConfigError
        ``path`` exists and is not a folder, or is a non-empty folder that is not a database.
    """
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise ConfigError("exists and is not a folder", path=path)
        if any(path.iterdir()) and not (path / "manifest.json").exists():
            raise ConfigError("is a non-empty folder that is not a finger database; refusing to overwrite", path=path)
    # SIGTERM/SIGINT (raised as exceptions by the command line) wait while a temporary folder is
    # made and named, while the folders are renamed, and while they are removed: a signal there
    # left mkdtemp's folder or the old database behind. The old database is put back if the new
    # one did not take its place.
    tmp = old = None
    try:
        with signals_deferred():
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = _unused_name(path, "")
                os.mkdir(tmp)
            except OSError as e:  # read-only, a file in the way, a name too long
                tmp = None
                raise ConfigError(f"cannot write into folder {str(path.parent)!r}: {e.strerror}",
                                  path=path) from None
        for name in db._array_names():
            np.save(tmp / f"{name}.npy", np.ascontiguousarray(getattr(db, name)))
        (tmp / "manifest.json").write_text(json.dumps(db.manifest(), indent=1) + "\n")
        with signals_deferred():
            if path.exists():  # the old database moved aside under a fresh name (a fixed '.NAME.old'
                old = _unused_name(path, "old.")  # was a user's folder, and was removed)
                os.replace(path, old)
            os.replace(tmp, path)
    except OSError as e:  # the folder filled up or became unwritable while writing
        raise ConfigError(f"cannot write the database: {e.strerror}", path=path) from None
    finally:
        with signals_deferred():
            if tmp is not None:
                shutil.rmtree(tmp, ignore_errors=True)
            if old is not None and old.exists():
                if path.exists():
                    shutil.rmtree(old, ignore_errors=True)
                else:
                    os.replace(old, path)
    return path


def _spec_file(manifest: dict, name: str) -> str:
    """File name of array ``name`` in a (validated) manifest."""
    return manifest["arrays"][name]["file"]


def load_database(path: str | os.PathLike, mmap: bool = True, *, check_schema: bool = True) -> FingerDatabase:
    """Load a database folder; arrays memory-mapped unless ``mmap`` is False.

    ``check_schema=False`` skips the JSON-schema check of the manifest (importing
    jsonschema and validating cost 0.1-0.5 s of every ``synthesize``): for the database
    bundled in the package, which the tests validate. Shapes and dtypes are still checked.

    Raises
    ------
    ConfigError
        Missing folder or manifest, a manifest that fails the schema, an unknown
        version, or arrays whose shape or dtype differ from the manifest.
    """

    path = Path(path)
    mf = path / "manifest.json"
    if path.exists() and not path.is_dir():
        if not path.is_file():  # a named pipe, a device
            raise ConfigError("not a regular file", path=path)
        raise ConfigError("is a file, not a finger database (a folder made by 'usdhands db build')", path=path)
    if not path.is_dir():
        raise ConfigError("no such finger database folder", path=path)
    if not mf.is_file():
        raise ConfigError("not a finger database: manifest.json is missing", path=path)
    manifest = read_json(mf, what="manifest", error=ConfigError)
    if isinstance(manifest, dict) and manifest.get("format") == FORMAT and manifest.get("version") != VERSION:
        old = manifest.get("version") == 1
        why = ("; it stores rotation-vector wrist features, which wrap: rebuild it from its clips with "
               "'usdhands db build'") if old else ""
        raise ConfigError(f"database version {manifest.get('version')!r} is not supported (this usdhands reads "
                          f"{VERSION}){why}", path=mf)
    error = first_schema_error(manifest, "database") if check_schema else None
    if error is not None:
        where, message = error
        raise ConfigError(f"invalid database manifest at {where}: {message}", path=mf)
    arrays = {}
    names = manifest.get("arm_features")
    if (names is None) != (OPTIONAL_ARRAY not in manifest["arrays"]):
        raise ConfigError(f"the manifest lists arm_features and the array {OPTIONAL_ARRAY!r} only together",
                          path=mf)
    for name in ARRAYS + (() if names is None else (OPTIONAL_ARRAY,)):
        spec = manifest["arrays"][name]
        f = path / spec["file"]
        named = Path(spec["file"])
        if named.is_absolute() or ".." in named.parts:  # the manifest names files inside its folder
            raise ConfigError(f"array {name!r}: file {spec['file']!r} is outside the database folder", path=mf)
        check_regular_file(f, what=f"array file {name!r}", error=ConfigError)  # a pipe would block np.load
        try:
            a = np.load(f, mmap_mode="r" if mmap else None, allow_pickle=False)
        except (OSError, ValueError) as e:
            raise ConfigError(f"cannot read array {name!r}: {e}", path=f) from None
        if list(a.shape) != spec["shape"] or str(a.dtype) != spec["dtype"]:
            raise ConfigError(f"array {name!r} has shape {list(a.shape)} and dtype {a.dtype}, "
                              f"the manifest says {spec['shape']} and {spec['dtype']}", path=f)
        arrays[name] = a
    dof_index = np.array(manifest["dof_index"], dtype=np.int64)
    F = arrays["features"].shape[0]
    if arrays["fingers"].shape != (F, len(dof_index)) or arrays["features"].shape[1] != NUM_WRIST_FEATURES:
        raise ConfigError("features and fingers arrays do not match the manifest's DOFs", path=path)
    tr, sg = np.asarray(arrays["tracks"]), np.asarray(arrays["segments"])
    if len(tr) and ((tr[:, 0] < 0).any() or (tr[:, 1] > F).any() or (tr[:, 2] < 0).any()
                    or (tr[:, 2] >= len(manifest["clips"])).any()):
        raise ConfigError("tracks refer to frames or clips the database does not have", path=path)
    if len(tr) and ((tr[:, 1] <= tr[:, 0]).any() or ~np.isin(tr[:, 3:5], (0, 1)).all()):
        raise ConfigError("tracks with no frames, or a side or mirror flag other than 0 and 1", path=path)
    if len(sg) and ((sg[:, 2] < 0).any() or (sg[:, 2] >= len(tr)).any()):
        raise ConfigError("segments refer to tracks or frames the database does not have", path=path)
    if len(sg):
        own = tr[sg[:, 2]]
        bad = np.nonzero((sg[:, 0] < own[:, 0]) | (sg[:, 1] > own[:, 1]) | (sg[:, 1] <= sg[:, 0]))[0]
        if len(bad):
            raise ConfigError(f"segment {int(bad[0])} ({int(sg[bad[0], 0])}..{int(sg[bad[0], 1])}) is empty or "
                              f"outside its track; {len(bad)} such segments", path=path / _spec_file(manifest, "segments"))
    if names is not None:
        from usdhands.algorithms.synthesis.feature_sets import key_width, parse_feature_set

        try:
            for key in names:
                if parse_feature_set(key) != [(key, 1.0)]:
                    raise ValueError(key)
        except ValueError:
            raise ConfigError(f"arm_features lists {key!r}, not a feature key such as 'elbow_pos'", path=mf) from None
        if arrays[OPTIONAL_ARRAY].shape != (F, sum(key_width(k) for k in names)):
            raise ConfigError(f"array {OPTIONAL_ARRAY!r} has shape {list(arrays[OPTIONAL_ARRAY].shape)}, the "
                              f"features {names} need ({F}, {sum(key_width(k) for k in names)})",
                              path=path / _spec_file(manifest, OPTIONAL_ARRAY))
    # synthesis reads every feature row anyway (F x 12): check them here, not the fingers
    for name in ("features",) + (() if names is None else (OPTIONAL_ARRAY,)):
        finite = np.isfinite(arrays[name]).all(axis=1)
        if not finite.all():
            raise ConfigError(f"{name.replace('_', ' ')} hold NaN or infinite values (first at frame "
                              f"{int(np.argmin(finite))})", path=path / _spec_file(manifest, name))
    return FingerDatabase(
        fps=float(manifest["fps"]), reach_cm=float(manifest["reach_cm"]),
        features=arrays["features"], fingers=arrays["fingers"], dof_index=dof_index,
        tracks=np.asarray(tr), segments=np.asarray(sg), clips=manifest["clips"],
        segmentation=manifest.get("segmentation", {}), hands=manifest.get("hands", {}), path=path,
        arm_features=arrays.get(OPTIONAL_ARRAY), arm_feature_names=tuple(names or ()),
    )

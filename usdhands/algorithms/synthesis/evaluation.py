"""How well body motion predicts finger motion (seed 000, §4), and held-out synthesis error.

**Leave-one-out.** Every hand of every labelled clip is segmented by wrist speed (as
in synthesis). For each segment, the ``k`` most similar segments of the same hand in
the *other* clips are found by one predictor (a weighted sum of squared feature
differences after DTW alignment, as in eq. 1); the score is the share of those
neighbours whose clip has the segment's label, averaged over all segments. The
paper's figures on its 64 gestures: wrist rotation alone 75%, ``P + 0.5·R`` 80%.
The class confusion matrix gives, per true label, the share of neighbours of each
label (the paper's figure 8). Hands that hardly move in a clip (range of the wrist
under ``idle_range_cm``) are left out: a hand hanging at rest says nothing about the
gesture the other hand makes. **Rest trimming** (on by default, as the paper's §4
"trimmed the rest poses at the beginning and end of each gesture"): each hand's
frames before the wrist speed first exceeds the segmentation threshold and after it
last does are dropped before segmenting, so the rest segments every take shares do
not count as neighbours of every type. Shares are reported **per hand** (a right
hand's segments are only ever compared with right hands) and pooled over both.

Predictors are named by terms joined with ``+``; a term is an optional weight and
``<joint>_<pos|rot>`` with joint ``shoulder``, ``elbow`` or ``wrist``; a term of only
``pos`` or ``rot`` keeps the previous term's joint: ``wrist_pos+0.5rot`` is
``1·wrist_pos + 0.5·wrist_rot``.

**Held-out synthesis.** For clips with fingers, each clip's fingers are synthesized
from all the others and compared with its own (mean geodesic angle per finger joint
and frame, degrees), beside three baselines measured the same way: the database's
mean pose, random segments (same segmentation, random database segments of a
compatible length, stretched linearly, stitched alike) and, frame by frame, the
fingers of the database frame with the nearest wrist features. The fingers' mean
angular speed (degrees per second) is reported against the ground truth's: a method
can have a small error by barely moving.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from usdhands.algorithms.synthesis.database import FingerDatabase, same_rate, segment_track
from usdhands.algorithms.synthesis.finger_transfer import NUM_SLOTS, ORDER
from usdhands.algorithms.synthesis.segment_cost import knn_segments, weight_features
from usdhands.algorithms.synthesis.segmentation import wrist_speed
from usdhands.algorithms.synthesis.stitching import stitch_fragments
from usdhands.algorithms.synthesis.synthesize import db_side_segments, db_weighted_features, synthesize_hand
from usdhands.algorithms.synthesis.config import SynthesisConfig
from usdhands.algorithms.synthesis.wrist_features import FEATURE_JOINTS, arm_features
from usdhands.model.clip import Clip
from usdhands.model.handmap import SIDES, HandMap
from usdhands.model.rotations import euler_deg_to_quat, quat_angle_deg

__all__ = [
    "DEFAULT_PREDICTORS", "PAPER_PREDICTOR", "parse_predictor", "EvalSet", "prepare_eval_set",
    "leave_one_out", "evaluate_predictors", "holdout_evaluation", "finger_angle_error", "mean_angular_speed",
    "slot_quats", "shares_by_side", "parse_terms", "random_segments",
]

PAPER_PREDICTOR = "wrist_pos+0.5rot"
DEFAULT_PREDICTORS = (
    "shoulder_pos", "shoulder_rot", "elbow_pos", "elbow_rot", "wrist_pos", "wrist_rot",
    "wrist_pos+0.25rot", PAPER_PREDICTOR, "wrist_pos+rot", "elbow_pos+wrist_pos",
)
SINGLE_JOINT_PREDICTORS = DEFAULT_PREDICTORS[:6]

_TERM = re.compile(r"^\s*(?:(\d+(?:\.\d*)?|\.\d+)\s*\*?\s*)?(other_)?(?:(shoulder|elbow|wrist)_)?(pos|rot|vel)\s*$")


def parse_terms(name: str, what: str = "predictor", extended: bool = False) -> list[tuple[str, float]]:
    """Weighted feature terms of a name such as ``wrist_pos+0.5rot``.

    A term is ``[weight*]<joint>_<kind>``, joint ``shoulder``, ``elbow`` or ``wrist``,
    kind ``pos`` or ``rot`` (and, with ``extended``, ``vel`` and an ``other_`` prefix for
    the other hand's joint); a term of only a kind keeps the previous term's joint.

    Raises
    ------
    ValueError
        Quoting the name (as a ``what``) and the term that does not parse.
    """
    syntax = ("'[weight*][other_]<shoulder|elbow|wrist>_<pos|rot|vel>' or '[weight*]<pos|rot|vel>'" if extended
              else "'[weight]<shoulder|elbow|wrist>_<pos|rot>' or '[weight]<pos|rot>'")
    terms, joint, other = [], None, ""
    for part in str(name).split("+"):
        m = _TERM.match(part)
        if not m or (not extended and (m.group(2) or m.group(4) == "vel")):
            raise ValueError(f"Cannot read {what} {name!r}: term {part!r} is not {syntax}")
        w, o, j, kind = m.groups()
        if j:
            joint, other = j, o or ""
        elif o:
            raise ValueError(f"Cannot read {what} {name!r}: term {part!r} names no joint after 'other_'")
        if joint is None:
            raise ValueError(f"Cannot read {what} {name!r}: term {part!r} names no joint")
        terms.append((f"{other}{joint}_{kind}", 1.0 if w is None else float(w)))
    return terms


def parse_predictor(name: str) -> list[tuple[str, float]]:
    """Terms of a predictor name: ``[("wrist_pos", 1.0), ("wrist_rot", 0.5)]`` (:func:`parse_terms`).

    Raises
    ------
    ValueError
        Quoting the name and the term that does not parse.
    """
    return parse_terms(name, "predictor")


@dataclass(frozen=True, eq=False)
class EvalSet:
    """Segmented hands of a labelled clip set, with every arm feature per frame.

    Attributes
    ----------
    features : dict of str to (F, 3) float
        ``"wrist_pos"`` etc., all tracks' frames concatenated.
    segments : (N, 2) int
        Frame ranges.
    seg_clip : (N,) int
    seg_side : (N,) int
    seg_label : (N,) int
        Index into ``labels``.
    labels : list of str
    clip_names : list of str
    idle : list of (clip name, side)
        Hands left out for hardly moving.
    fps : float
    """

    features: dict
    segments: np.ndarray
    seg_clip: np.ndarray
    seg_side: np.ndarray
    seg_label: np.ndarray
    labels: list
    clip_names: list
    idle: list
    fps: float


def prepare_eval_set(items: list[tuple[str, Clip, HandMap]], config: SynthesisConfig | None = None,
                     fps: float | None = None, idle_range_cm: float = 5.0,
                     predictors=DEFAULT_PREDICTORS, trim_rest: bool = True) -> EvalSet:
    """Segment and featurize labelled clips.

    Parameters
    ----------
    items : list of (label, clip, handmap)
    config : SynthesisConfig, optional
        For the segmentation parameters.
    fps : float, optional
        Resample clips to this rate (default: the first clip's).
    idle_range_cm : float
        A hand whose wrist stays within this distance of its mean position is idle.
    predictors : sequence of str
        The predictors to be evaluated: only the joints they name must be in the hand
        maps (the wrist always is).
    trim_rest : bool
        Drop each hand's rest at both ends (see the module notes).
    """
    cfg = config or SynthesisConfig()
    if not items:
        raise ValueError("Expected at least one labelled clip")
    fps = float(fps or items[0][1].fps)
    labels = sorted({lab for lab, _, _ in items})
    roles = {"wrist"} | {key.split("_")[0] for p in predictors for key, _ in parse_predictor(p)}
    roles = tuple(r for r in FEATURE_JOINTS if r in roles)
    feats = {f"{j}_{k}": [] for j in roles for k in ("pos", "rot")}
    segs, sclip, sside, slabel, idle, names = [], [], [], [], [], []
    start = 0
    for ci, (label, clip, handmap) in enumerate(items):
        if not same_rate(clip.fps, fps):
            clip = clip.resample(fps)
        names.append(clip.name)
        world = clip.world_xforms()
        for hand in handmap.sides:
            f = arm_features(clip, hand, 1.0, roles, world)
            missing = sorted({key.split("_")[0] for key in feats if key not in f})
            if missing:
                raise ValueError(f"Hand {hand.side!r} of clip {clip.name!r} has no {' or '.join(missing)} joint "
                                 f"for the predictors asked for")
            wp = f["wrist_pos"]
            if np.linalg.norm(wp - wp.mean(axis=0), axis=1).max() < idle_range_cm:
                idle.append((clip.name, hand.side))
                continue
            if trim_rest:
                first, last = _active_span(wp, fps, cfg.segmentation)
                f = {key: v[first:last] for key, v in f.items()}
                wp = f["wrist_pos"]
            bounds = segment_track(np.concatenate([wp, f["wrist_rot"]], axis=1), fps, cfg.segmentation)
            for key in feats:
                feats[key].append(f[key])
            for a, b in zip(bounds[:-1], bounds[1:]):
                segs.append((start + a, start + b))
                sclip.append(ci)
                sside.append(SIDES.index(hand.side))
                slabel.append(labels.index(label))
            start += len(wp)
    if not segs:
        raise ValueError("Every hand of every clip is idle; nothing to evaluate")
    return EvalSet({k: np.concatenate(v) for k, v in feats.items()}, np.array(segs, dtype=np.int64),
                   np.array(sclip), np.array(sside), np.array(slabel), labels, names, idle, fps)


def _active_span(wrist_pos: np.ndarray, fps: float, seg) -> tuple[int, int]:
    """``[first, last)`` frames from the first to the last where the wrist speed exceeds the threshold.

    Widened symmetrically to at least the shortest segment; the whole track when the
    wrist never moves that fast.
    """
    speed = wrist_speed(wrist_pos, fps, seg.speed_smoothing_s)
    fast = np.nonzero(speed > seg.speed_threshold_cm_s)[0]
    T = len(wrist_pos)
    if not len(fast):
        return 0, T
    first, last = int(fast[0]), int(fast[-1]) + 1
    need = int(np.ceil(seg.min_segment_s * fps)) - (last - first)
    if need > 0:
        first = max(0, first - (need + 1) // 2)
        last = min(T, first + int(np.ceil(seg.min_segment_s * fps)))
    return first, last


def shares_by_side(es: EvalSet, neighbours: np.ndarray) -> dict:
    """Leave-one-out shares per hand: ``{"left": share, "right": share}`` (sides with segments only)."""
    found = neighbours >= 0
    same = found & (es.seg_label[np.maximum(neighbours, 0)] == es.seg_label[:, None])
    per = same.sum(axis=1) / np.maximum(found.sum(axis=1), 1)
    ok = found.any(axis=1)
    out = {}
    for s, side in enumerate(SIDES):
        sel = ok & (es.seg_side == s)
        if sel.any():
            out[side] = float(per[sel].mean())
    return out


def leave_one_out(es: EvalSet, predictor: str, k: int = 5, config: SynthesisConfig | None = None):
    """Leave-one-out neighbours of every segment by one predictor.

    Returns
    -------
    share : float
        Mean share of the k neighbours (those found) with the segment's label.
    neighbours : (N, k) int
        Neighbour segment indices (-1: none found).
    """
    cfg = config or SynthesisConfig()
    terms = parse_predictor(predictor)
    cols = np.concatenate([es.features[key] for key, _ in terms], axis=1)
    w = np.concatenate([np.full(es.features[key].shape[1], wt) for key, wt in terms])
    fw = weight_features(cols, w)
    N = len(es.segments)
    neighbours = np.full((N, k), -1, dtype=np.int64)
    sc = cfg.segment_cost
    for s in range(len(SIDES)):
        idx = np.nonzero(es.seg_side == s)[0]
        if not len(idx):
            continue
        res = knn_segments(fw, es.segments[idx], fw, es.segments[idx], k=k, length_factor=sc.length_factor,
                           band=sc.dtw_band, query_groups=es.seg_clip[idx], db_groups=es.seg_clip[idx],
                           bound=sc.lower_bound)
        neighbours[idx] = np.where(res.index >= 0, idx[np.maximum(res.index, 0)], -1)
    found = neighbours >= 0
    same = found & (es.seg_label[np.maximum(neighbours, 0)] == es.seg_label[:, None])
    per = same.sum(axis=1) / np.maximum(found.sum(axis=1), 1)
    ok = found.any(axis=1)
    return float(per[ok].mean()) if ok.any() else 0.0, neighbours


def _confusion(es: EvalSet, neighbours: np.ndarray) -> np.ndarray:
    L = len(es.labels)
    m = np.zeros((L, L))
    for s in range(len(neighbours)):
        for n in neighbours[s]:
            if n >= 0:
                m[es.seg_label[s], es.seg_label[n]] += 1
    return m / np.maximum(m.sum(axis=1, keepdims=True), 1)


def _chance(es: EvalSet) -> float:
    shares = []
    for s in range(len(es.segments)):
        other = (es.seg_side == es.seg_side[s]) & (es.seg_clip != es.seg_clip[s])
        if other.any():
            shares.append(float((es.seg_label[other] == es.seg_label[s]).mean()))
    return float(np.mean(shares)) if shares else 0.0


def evaluate_predictors(es: EvalSet, predictors=DEFAULT_PREDICTORS, k: int = 5,
                        config: SynthesisConfig | None = None, progress=None) -> dict:
    """Leave-one-out shares of several predictors.

    ``progress(done, total, predictor)``, when given, is called after each predictor.

    Returns
    -------
    dict
        ``{"k", "segments", "predictors": {name: share}, "per_hand": {name: {"left":
        share, "right": share}}, "best", "chance", "confusion": {"labels", "matrix",
        "predictor"}}``; ``predictors`` pools both hands; the confusion matrix is that
        of :data:`PAPER_PREDICTOR` when evaluated, else of the best predictor.
    """
    predictors = list(predictors)
    for p in predictors:
        parse_predictor(p)
    shares, neigh = {}, {}
    for i, p in enumerate(predictors):
        shares[p], neigh[p] = leave_one_out(es, p, k, config)
        if progress:
            progress(i + 1, len(predictors), p)
    best = max(predictors, key=lambda p: (shares[p], -predictors.index(p)))
    conf_p = PAPER_PREDICTOR if PAPER_PREDICTOR in shares else best
    return {
        "k": int(k),
        "segments": int(len(es.segments)),
        "predictors": shares,
        "per_hand": {p: shares_by_side(es, neigh[p]) for p in predictors},
        "best": best,
        "chance": _chance(es),
        "confusion": {"labels": list(es.labels), "matrix": _confusion(es, neigh[conf_p]).tolist(),
                      "predictor": conf_p},
    }


def slot_quats(curves: np.ndarray, slots: np.ndarray) -> np.ndarray:
    """Quaternions ``(T, S, 4)`` of the given finger slots of canonical curves ``(T, 60)`` (degrees)."""
    T = len(curves)
    return euler_deg_to_quat(curves.reshape(T, NUM_SLOTS, 3)[:, slots], ORDER)


def finger_angle_error(a: np.ndarray, b: np.ndarray, slots: np.ndarray) -> float:
    """Mean geodesic angle (deg) between two canonical curve sets ``(T, 60)`` over the given slots."""
    return float(quat_angle_deg(slot_quats(a, slots), slot_quats(b, slots)).mean())


def mean_angular_speed(curves: np.ndarray, slots: np.ndarray, fps: float) -> float:
    """Mean geodesic angular speed (deg/s) of canonical curves ``(T, 60)`` over the given slots."""
    if len(curves) < 2:
        return 0.0
    q = slot_quats(curves, slots)
    return float(quat_angle_deg(q[1:], q[:-1]).mean() * fps)


def random_segments(db: FingerDatabase, seg_idx: np.ndarray, bounds: np.ndarray, rng: np.random.Generator,
                    config: SynthesisConfig) -> np.ndarray:
    """The random-segments baseline: canonical curves ``(bounds[-1] - bounds[0], 60)``.

    Each input segment (``bounds``, frames) gets a random database segment among
    ``seg_idx`` of a compatible length (any, if none is), stretched linearly; the
    fragments are stitched like synthesis's.
    """
    sc, st = config.segment_cost, config.stitching
    lens = db.segments[seg_idx, 1] - db.segments[seg_idx, 0]
    frags = []
    for q0, q1 in zip(bounds[:-1], bounds[1:]):
        n = q1 - q0
        ok = np.nonzero((lens * sc.length_factor >= n) & (lens <= n * sc.length_factor))[0]
        pick = seg_idx[rng.choice(ok)] if len(ok) else seg_idx[rng.integers(len(seg_idx))]
        sa, sb = db.segments[pick, :2]
        frags.append(db.full_curves(np.round(np.linspace(sa, sb - 1, n)).astype(np.int64)))
    return stitch_fragments(frags, db.fps, st.blend_mean_deg, st.blend_max_deg, st.blend_duration_s)[0]


def holdout_evaluation(db: FingerDatabase, config: SynthesisConfig | None = None, seed: int = 0,
                       progress=None) -> dict:
    """Synthesize every clip of ``db`` from the others; errors of synthesis and baselines.

    Mirrored tracks are never held out (they are copies); a held-out clip's mirrored
    twins are excluded from its database along with the clip.

    Returns
    -------
    dict
        ``{"clips": n, "frames": n, "methods": {name: {"error_deg", "speed_deg_s"}},
        "ground_truth_speed_deg_s": x, "per_clip": [...]}`` with methods
        ``synthesis``, ``mean_pose``, ``random_segments``, ``nearest_wrist``.
    """
    from scipy.spatial import cKDTree

    cfg = config or SynthesisConfig()
    rng = np.random.default_rng(seed)
    dw = db_weighted_features(db, cfg)
    slots = np.nonzero(db.dof_mask().reshape(-1, 3).all(axis=1))[0]
    methods = ("synthesis", "mean_pose", "random_segments", "nearest_wrist")
    err = {m: [] for m in methods}
    spd = {m: [] for m in methods}
    gt_speed, frames, per_clip = [], [], []
    queries = [t for t in range(len(db.tracks)) if not db.tracks[t, 4]]
    for qi, t in enumerate(queries):
        a, b, c, s, _ = (int(x) for x in db.tracks[t])
        side = SIDES[s]
        feats = np.asarray(db.features[a:b], dtype=np.float64)
        truth = db.full_curves(slice(a, b))
        seg_idx = db_side_segments(db, side, (c,))
        if not len(seg_idx):
            continue
        syn = synthesize_hand(feats, db, side, cfg, (c,), dw,
                              query_weighted=None if cfg.segment_cost.features is None else dw[a:b])
        rows = np.concatenate([np.arange(*db.segments[i, :2]) for i in seg_idx])
        mean_pose = np.broadcast_to(db.full_curves(rows).mean(axis=0), truth.shape)
        rand = random_segments(db, seg_idx, syn.bounds, rng, cfg)
        tree = cKDTree(dw[rows])
        _, nn = tree.query(dw[a:b])
        nearest = db.full_curves(rows[nn])
        results = {"synthesis": syn.curves, "mean_pose": mean_pose, "random_segments": rand, "nearest_wrist": nearest}
        row = {"clip": db.clips[c]["name"], "side": side, "frames": b - a}
        for m in methods:
            e = finger_angle_error(results[m], truth, slots)
            err[m].append(e * (b - a))
            spd[m].append(mean_angular_speed(results[m], slots, db.fps) * (b - a))
            row[m] = e
        gt_speed.append(mean_angular_speed(truth, slots, db.fps) * (b - a))
        frames.append(b - a)
        per_clip.append(row)
        if progress:
            progress(qi + 1, len(queries), db.clips[c]["name"])
    total = max(sum(frames), 1)
    return {
        "clips": len({r["clip"] for r in per_clip}),
        "frames": int(sum(frames)),
        "methods": {m: {"error_deg": sum(err[m]) / total, "speed_deg_s": sum(spd[m]) / total} for m in methods},
        "ground_truth_speed_deg_s": sum(gt_speed) / total,
        "per_clip": per_clip,
    }

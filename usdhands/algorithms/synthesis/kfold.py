"""K-fold held-out synthesis against strong baselines, and feature sets compared by it.

Every hand track (a take's hand with fingers) is cut into ``K`` contiguous windows
of equal length. Fold ``f`` holds out window ``f`` of *every* track and synthesizes
each held-out window from the database segments that lie wholly outside the
held-out windows (a segment crossing a window's edge is not used), so every frame
is held out exactly once. Errors are pooled over all windows, frame-weighted.
A take too short for windows of ``min_window_s`` (4 s by default: two of the longest
segments) is held out whole instead, in fold ``take index mod K``: a window of a
few frames is a fragment of a gesture, and matching fragments to whole database
segments measures the cut, not the method (on the sample gestures, takes of 2.75 s,
windows of 0.55 s are a single segment each).

Baselines, computed in the same run from the same training frames (the frames of
the usable segments of the same side):

- ``mean_pose``: the training frames' mean finger pose, held;
- ``medoid_pose``: the most typical training pose (the medoid of up to 2,000 frames
  sampled evenly), held;
- ``nearest_frame``: frame by frame, the fingers of the training frame nearest in the
  weighted wrist features of eq. 1;
- ``nearest_10_mean``: frame by frame, the mean fingers of the 10 nearest frames;
- ``random_segments``: the input's segmentation filled with random training segments
  of a compatible length, stretched linearly and stitched like synthesis.

Measures, per method: the mean geodesic angle per finger joint and frame against
the truth (``error_deg``); the same over the most expressive quarter of the frames,
those whose true pose is farthest from the mean pose (``expressive_error_deg``); the
mean angular speed and its ratio to the truth's; the largest frame-to-frame jump of
any joint, against the truth's; and the share of repeated frames (no joint moves by
1e-3° or more), against the truth's.

Feature sets (:mod:`~usdhands.algorithms.synthesis.feature_sets`). The main synthesis
uses the configuration's features (``segment_cost.features``, the paper's
``wrist_pos+0.5rot`` by default); each set of ``feature_sets`` is synthesized on the
same folds besides, so sets compare as the paper's §4 compares predictors, but on the
finger error itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usdhands.algorithms.synthesis.config import SynthesisConfig
from usdhands.algorithms.synthesis.database import DatabaseClip, FingerDatabase, build_database, same_rate
from usdhands.algorithms.synthesis.evaluation import random_segments, slot_quats
from usdhands.algorithms.synthesis.feature_sets import PAPER_FEATURES, extra_keys, feature_terms, hand_columns, \
    parse_feature_set
from usdhands.algorithms.synthesis.finger_transfer import dof_names
from usdhands.algorithms.synthesis.segment_cost import weight_features
from usdhands.algorithms.synthesis.synthesize import db_side_segments, db_weighted_features, synthesize_hand
from usdhands.algorithms.synthesis.wrist_features import world_xforms_for
from usdhands.model.handmap import SIDES
from usdhands.model.rotations import quat_angle_deg

__all__ = ["METHODS", "PAPER_FEATURES", "parse_feature_set", "kfold_evaluation", "window_bounds"]

METHODS = ("synthesis", "mean_pose", "medoid_pose", "nearest_frame", "nearest_10_mean", "random_segments")
REPEAT_DEG = 1e-3
MEDOID_SAMPLE = 2000

def window_bounds(start: int, stop: int, folds: int) -> np.ndarray:
    """Edges ``(folds + 1,)`` of ``folds`` contiguous windows of ``[start, stop)`` of near-equal length."""
    return start + np.round(np.linspace(0, stop - start, folds + 1)).astype(np.int64)


@dataclass
class _Tally:
    """Frame-weighted sums of one method's measures over windows."""

    errors: list
    steps: int = 0
    speed_sum: float = 0.0
    largest: float = 0.0
    repeated: int = 0

    def add_motion(self, q: np.ndarray) -> None:
        if len(q) < 2:
            return
        step = quat_angle_deg(q[1:], q[:-1])  # (n-1, S)
        self.steps += len(step)
        self.speed_sum += float(step.mean(axis=1).sum())
        self.largest = max(self.largest, float(step.max()))
        self.repeated += int((step.max(axis=1) < REPEAT_DEG).sum())


def _track_columns(items: list[DatabaseClip], db: FingerDatabase, keys) -> list[dict]:
    """Per real track of ``db`` (in its order), the columns ``{key: (T, 3|9)}`` of the keys its hand map allows."""
    out = []
    for item in items:
        clip = item.clip if same_rate(item.clip.fps, db.fps) else item.clip.resample(db.fps)
        world = world_xforms_for(clip, list(item.handmap.sides))
        for hand in item.handmap.sides:
            if not hand.finger_joints:
                continue
            cols = {}
            for key in keys:
                try:
                    cols.update(hand_columns(clip, item.handmap, hand.side, [key], db.reach_cm, world))
                except ValueError:  # a joint this hand map lacks: the sets naming it are left out
                    pass
            out.append(cols)
    return out


def _weighted(columns: list[dict], terms, tracks_len: list[int]):
    """Weighted columns of a feature set for all real tracks, or None when a track lacks one."""
    parts = []
    for cols, n in zip(columns, tracks_len):
        if any(key not in cols for key, _ in terms):
            return None
        block = np.concatenate([cols[key] for key, _ in terms], axis=1)
        w = np.concatenate([np.full(cols[key].shape[1], wt) for key, wt in terms])
        assert len(block) == n
        parts.append(weight_features(block.astype(np.float32), w))  # stored like a database's features
    return np.concatenate(parts)


def _medoid(rows: np.ndarray) -> np.ndarray:
    """The row of least summed distance to the others (on at most MEDOID_SAMPLE rows sampled evenly)."""
    sample = rows[np.linspace(0, len(rows) - 1, min(len(rows), MEDOID_SAMPLE)).astype(np.int64)]
    sq = (sample ** 2).sum(axis=1)
    d2 = np.maximum(sq[:, None] + sq[None, :] - 2 * sample @ sample.T, 0.0)
    return sample[int(np.argmin(np.sqrt(d2).sum(axis=1)))]


def kfold_evaluation(items: list[DatabaseClip], config: SynthesisConfig | None = None, folds: int = 5,
                     fps: float = 30.0, feature_sets=(), seed: int = 0, progress=None,
                     min_window_s: float = 4.0) -> dict:
    """K-fold held-out synthesis of every take's fingers, with baselines and feature sets.

    Parameters
    ----------
    items : list of DatabaseClip
        Clips with finger animation.
    config : SynthesisConfig, optional
    folds : int
        K (at least 2).
    fps : float
        Rate every clip is resampled to.
    feature_sets : sequence of str
        Feature sets (:func:`parse_feature_set`) to synthesize with besides the
        configuration's wrist features; a set naming a joint some hand lacks is
        reported under ``"feature_sets_left_out"``.
    seed : int
        Seed of the random-segments baseline.
    progress : callable, optional
        ``progress(done, total, label)`` after each held-out window.
    min_window_s : float
        Takes whose windows would be shorter are held out whole (see the module notes).

    Returns
    -------
    dict
        ``{"folds", "windows", "frames", "tracks", "k", "truth": {...}, "methods": {name:
        {"error_deg", "expressive_error_deg", "speed_deg_s", "speed_ratio",
        "largest_jump_deg", "jump_ratio", "repeated_share"}}, "ratios": {...},
        "feature_sets": {name: {"error_deg", "expressive_error_deg", "to_mean_pose"}},
        "feature_sets_left_out": [...], "worst_window": {...}}`` (see the module notes).

    Raises
    ------
    ValueError
        Fewer than 2 folds, or no track long enough for them.
    """
    from scipy.spatial import cKDTree

    cfg = config or SynthesisConfig()
    folds = int(folds)
    if folds < 2:
        raise ValueError(f"Expected at least 2 folds, got {folds}")
    sets = [s for s in dict.fromkeys(feature_sets) if s]
    parsed = {s: parse_feature_set(s) for s in sets}
    db = build_database(items, fps=fps, segmentation=cfg.segmentation,
                        arm_features=extra_keys(feature_terms(cfg.segment_cost)))
    real = [t for t in range(len(db.tracks)) if not db.tracks[t, 4]]
    lens = [int(db.tracks[t, 1] - db.tracks[t, 0]) for t in real]
    if len({int(db.tracks[t, 2]) % folds for t in real}) < 2 and not any(n / folds >= min_window_s * fps for n in lens):
        raise ValueError(f"{folds} folds need more than one take, or a take of {folds * min_window_s:g} s or more")
    rng = np.random.default_rng(seed)
    sc = cfg.segment_cost
    dw = db_weighted_features(db, cfg)
    set_dw, left_out = {}, []
    if sets:
        keys = {key for terms in parsed.values() for key, _ in terms}
        columns = _track_columns(items, db, sorted(keys))
        for s in sets:
            w = _weighted(columns, parsed[s], lens)
            if w is None:
                left_out.append(s)
            else:
                set_dw[s] = w
    sets = [s for s in sets if s in set_dw]
    slots = np.nonzero(db.dof_mask().reshape(-1, 3).all(axis=1))[0]
    tallies = {m: _Tally([]) for m in METHODS}
    set_err = {s: [] for s in sets}
    truth_t = _Tally([])
    expressiveness = []
    worst = None
    seg_track = db.segments[:, 2]
    edges = {}
    for t in real:
        a, b, c = (int(x) for x in db.tracks[t, :3])
        if (b - a) / folds >= min_window_s * db.fps:
            edges[t] = window_bounds(a, b, folds)
        else:  # whole take in fold c mod K
            edges[t] = np.where(np.arange(folds + 1) <= c % folds, a, b)
    total = sum(1 for t in real for f in range(folds) if edges[t][f + 1] - edges[t][f] >= 2)
    if not total:
        raise ValueError(f"No take has 2 frames or more at {fps:g} fps")
    done = 0
    for f in range(folds):
        w0 = np.zeros(len(db.tracks), dtype=np.int64)
        w1 = np.zeros(len(db.tracks), dtype=np.int64)
        for t in real:
            w0[t], w1[t] = edges[t][f], edges[t][f + 1]
        allowed = (db.segments[:, 1] <= w0[seg_track]) | (db.segments[:, 0] >= w1[seg_track])
        training = {}
        for t in real:
            a, b = int(w0[t]), int(w1[t])
            if b - a < 2:
                continue
            side = SIDES[int(db.tracks[t, 3])]
            if side not in training:
                idx = db_side_segments(db, side)
                idx = idx[allowed[idx]]
                if not len(idx):
                    raise ValueError(f"Fold {f + 1}: no {side}-hand segment outside the held-out windows")
                rows = np.concatenate([np.arange(*db.segments[i, :2]) for i in idx])
                full = db.full_curves(rows)
                training[side] = (idx, rows, full, cKDTree(dw[rows]), full.mean(axis=0), _medoid(full))
            idx, rows, full, tree, mean_pose, medoid = training[side]
            feats = np.asarray(db.features[a:b], dtype=np.float64)
            truth = db.full_curves(slice(a, b))
            n = b - a
            syn = synthesize_hand(feats, db, side, cfg, (), dw, segments=allowed,
                                  query_weighted=None if sc.features is None else dw[a:b])
            k10 = min(10, len(rows))
            _, nn = tree.query(dw[a:b], k=k10)
            nn = nn.reshape(n, k10)
            rand = random_segments(db, idx, syn.bounds, rng, cfg)
            results = {
                "synthesis": syn.curves,
                "mean_pose": np.broadcast_to(mean_pose, truth.shape),
                "medoid_pose": np.broadcast_to(medoid, truth.shape),
                "nearest_frame": full[nn[:, 0]],
                "nearest_10_mean": full[nn].mean(axis=1),
                "random_segments": rand,
            }
            qt = slot_quats(truth, slots)
            truth_t.add_motion(qt)
            for m_name, curves in results.items():
                q = slot_quats(np.ascontiguousarray(curves), slots)
                per_frame = quat_angle_deg(q, qt).mean(axis=1)
                tallies[m_name].errors.append(per_frame)
                tallies[m_name].add_motion(q)
                if m_name == "mean_pose":
                    expressiveness.append(per_frame)
            for s in sets:
                res = synthesize_hand(feats, db, side, cfg, (), set_dw[s], segments=allowed, query_weighted=set_dw[s][a:b])
                set_err[s].append(quat_angle_deg(slot_quats(res.curves, slots), qt).mean(axis=1))
            err = float(tallies["synthesis"].errors[-1].mean())
            if worst is None or err > worst["error_deg"]:
                moving = np.nonzero(np.ptp(truth, axis=0) > 0)[0]
                top = moving[np.argsort(-np.ptp(truth[:, moving], axis=0), kind="stable")[:3]]
                c = int(db.tracks[t, 2])
                worst = {"clip": db.clips[c]["name"], "side": side, "fold": f + 1,
                         "frames": [a - int(db.tracks[t, 0]), b - int(db.tracks[t, 0])], "error_deg": err,
                         "dofs": [dof_names()[i] for i in top], "truth": truth[:, top].T.tolist(),
                         "synthesis": syn.curves[:, top].T.tolist()}
            done += 1
            if progress:
                progress(done, total, f"fold {f + 1}/{folds}")
    expr = np.concatenate(expressiveness)
    quarter = expr >= np.quantile(expr, 0.75)
    truth_speed = truth_t.speed_sum / max(truth_t.steps, 1) * db.fps
    methods = {}
    for m_name, tl in tallies.items():
        e = np.concatenate(tl.errors)
        speed = tl.speed_sum / max(tl.steps, 1) * db.fps
        methods[m_name] = {
            "error_deg": float(e.mean()), "expressive_error_deg": float(e[quarter].mean()),
            "speed_deg_s": speed, "speed_ratio": speed / truth_speed if truth_speed > 0 else float("nan"),
            "largest_jump_deg": tl.largest,
            "jump_ratio": tl.largest / truth_t.largest if truth_t.largest > 0 else float("nan"),
            "repeated_share": tl.repeated / max(tl.steps, 1),
        }
    mp = methods["mean_pose"]
    fs = {}
    for s in sets:
        e = np.concatenate(set_err[s])
        fs[s] = {"error_deg": float(e.mean()), "expressive_error_deg": float(e[quarter].mean()),
                 "to_mean_pose": float(e.mean()) / mp["error_deg"] if mp["error_deg"] > 0 else float("nan")}
    syn_m = methods["synthesis"]
    ratio = lambda a, b: a / b if b > 0 else float("nan")  # noqa: E731
    return {
        "folds": folds, "windows": done, "frames": int(len(expr)), "tracks": len(real), "k": int(sc.k),
        "truth": {"speed_deg_s": truth_speed, "largest_jump_deg": truth_t.largest,
                  "repeated_share": truth_t.repeated / max(truth_t.steps, 1)},
        "methods": methods,
        "ratios": {"to_mean_pose": ratio(syn_m["error_deg"], mp["error_deg"]),
                   "to_nearest_frame": ratio(syn_m["error_deg"], methods["nearest_frame"]["error_deg"]),
                   "expressive_to_mean_pose": ratio(syn_m["expressive_error_deg"], mp["expressive_error_deg"])},
        "feature_sets": fs,
        "feature_sets_left_out": left_out,
        "worst_window": worst,
    }

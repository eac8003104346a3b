"""Finger-motion synthesis from wrist motion (Jörg, Hodgins, Safonova 2012, §3).

For each hand independently:

1. segment the input by wrist speed (:mod:`~usdhands.algorithms.synthesis.segmentation`);
2. find the ``k`` database segments of least DTW-aligned segment cost (eq. 1,
   :mod:`~usdhands.algorithms.synthesis.segment_cost`);
3. compute transition costs between the candidates of consecutive segments (eq. 2)
   and take the least-cost path through the layered graph (eq. 3,
   :mod:`~usdhands.algorithms.synthesis.motion_graph`);
4. sample each chosen segment's finger curves along a smoothed version of the DTW
   alignment with interpolation (:mod:`~usdhands.algorithms.synthesis.output_warp`),
   stitch them with offsets and blends (:mod:`~usdhands.algorithms.synthesis.stitching`)
   and limit every DOF's frame step to the database's high-percentile step.

:func:`synthesize_hand` runs this on arrays (wrist features in, canonical finger
curves out); :func:`synthesize_clip` does it on a :class:`~usdhands.model.Clip`,
changing nothing but the finger joints' rotations.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from usdhands.algorithms.synthesis.database import FingerDatabase, same_rate, segment_track
from usdhands.algorithms.synthesis.finger_transfer import (
    NUM_DOFS, HandRig, canonical_local_rotations, hand_rig, slot_names,
)
from usdhands.algorithms.synthesis.motion_graph import least_cost_path, transition_costs_between
from usdhands.algorithms.synthesis.output_warp import (
    limit_steps, limit_steps_fast, play_kernels, play_segments, play_segments_fast,
)
from usdhands.algorithms.synthesis.segmentation import wrist_speed
from usdhands.algorithms.synthesis.segment_cost import SearchResult, knn_segments, weight_features
from usdhands.algorithms.synthesis.stitching import SeamReport, stitch_fragments, stitch_fragments_fast
from usdhands.algorithms.synthesis.config import SynthesisConfig
from usdhands.algorithms.synthesis.feature_sets import extra_keys, feature_terms, hand_columns, weighted_columns
from usdhands.algorithms.synthesis.wrist_features import NUM_WRIST_FEATURES, reach_cm, world_xforms_for, wrist_features
from usdhands.model.clip import Clip, resampled_frames
from usdhands.model.handmap import SIDES, HandMap

_log = logging.getLogger(__name__)

__all__ = ["HandSynthesis", "ClipSynthesis", "synthesize_hand", "synthesize_clip", "db_side_segments",
           "resample_rows", "segment_weights", "db_weighted_features", "query_features", "candidate_weights",
           "played_weights"]


@dataclass(frozen=True, eq=False)
class HandSynthesis:
    """Everything synthesis decided for one hand.

    Attributes
    ----------
    side : str
    bounds : (N+1,) int
        Input segment boundaries (frames at the database's rate).
    speed : (T,) float
        Wrist speed, cm/s (body-size scaled).
    candidates : (N, k) int
        Database segment indices per input segment, cheapest first (-1: none).
    segment_costs : (N, k) float
        Their eq. 1 costs.
    transitions : list of (k, k) float
        Eq. 2 costs between consecutive rows.
    path : (N,) int
        Chosen node per row.
    chosen : (N,) int
        Chosen database segment per input segment.
    curves : (T, 60) float
        Canonical finger curves, degrees.
    seams : SeamReport
    search : SearchResult
    """

    side: str
    bounds: np.ndarray
    speed: np.ndarray
    candidates: np.ndarray
    segment_costs: np.ndarray
    transitions: list
    path: np.ndarray
    chosen: np.ndarray
    curves: np.ndarray
    seams: SeamReport
    search: SearchResult


@dataclass(frozen=True, eq=False)
class ClipSynthesis:
    """Result of :func:`synthesize_clip`: the new clip and a per-hand account."""

    clip: Clip
    hands: dict = field(default_factory=dict)  # side -> HandSynthesis
    mapping: dict = field(default_factory=dict)  # side -> {"mapped": [...], "no_source": [...], "dropped": [...]}
    scale: dict = field(default_factory=dict)  # side -> body-size factor


def db_side_segments(db: FingerDatabase, side: str, exclude_clips=()) -> np.ndarray:
    """Indices of the database segments of one side, leaving out some clips."""
    s = SIDES.index(side)
    keep = db.segment_side() == s
    if len(exclude_clips):
        keep &= ~np.isin(db.segment_clip(), np.asarray(list(exclude_clips), dtype=np.int64))
    return np.nonzero(keep)[0]


def _candidate_ends(db: FingerDatabase, cand: np.ndarray):
    """Finger DOFs and velocities (degrees per frame) at the first and last frame of candidate segments.

    ``cand (N, k)`` database segment indices (-1: none, given zeros). Velocities are
    one-sided differences inside the segment's track.
    """
    valid = cand >= 0
    seg = db.segments[np.maximum(cand, 0)]  # (N, k, 3)
    a, b, t = seg[..., 0], seg[..., 1], seg[..., 2]
    ta, tb = db.tracks[t, 0], db.tracks[t, 1]
    fingers = db.fingers
    rows = lambda r: np.asarray(fingers[r.ravel()], dtype=np.float64).reshape(r.shape + (fingers.shape[1],))  # noqa: E731

    def velocity(first, second):
        first = np.clip(first, ta, tb - 1)
        second = np.clip(second, ta, tb - 1)
        v = rows(second) - rows(first)  # per frame: eq. 2 weighs it like the angles (wW = 0.5)
        return np.where((second > first)[..., None], v, 0.0)

    starts, ends = rows(a), rows(b - 1)
    fwd = a + 1 < tb
    vstart = velocity(np.where(fwd, a, a - 1), np.where(fwd, a + 1, a))
    back = b - 2 >= ta
    vend = velocity(np.where(back, b - 2, b - 1), np.where(back, b - 1, b))
    z = ~valid[..., None]
    return (np.where(z, 0.0, starts), np.where(z, 0.0, ends), np.where(z, 0.0, vstart), np.where(z, 0.0, vend))


def _uniform_knn(query: np.ndarray, db_weighted: np.ndarray, segments: np.ndarray, k: int):
    """The ``k`` cheapest segments when each is sampled uniformly at the query's length.

    ``query (n, D)`` and ``db_weighted (F, D)`` weighted features, ``segments (N, 2)``
    frame ranges. Returns indices ``(k,)`` into ``segments`` (-1 past N) and their
    eq. 1 costs ``(k,)`` (inf past N); ties go to the lower index.
    """
    n = len(query)
    cost = np.empty(len(segments))
    for s, (a, b) in enumerate(segments):
        j = a + np.round(np.linspace(0, b - a - 1, n)).astype(np.int64)
        cost[s] = float(((query - db_weighted[j]) ** 2).sum()) / n
    order = np.argsort(cost, kind="stable")[:k]
    idx = np.full(k, -1, dtype=np.int64)
    out = np.full(k, np.inf)
    idx[:len(order)], out[:len(order)] = order, cost[order]
    return idx, out


def synthesize_hand(features: np.ndarray, db: FingerDatabase, side: str, config: SynthesisConfig | None = None,
                    exclude_clips=(), db_weighted: np.ndarray | None = None, hooks=None,
                    segments: np.ndarray | None = None, query_weighted: np.ndarray | None = None) -> HandSynthesis:
    """Synthesize one hand's canonical finger curves from its wrist features.

    Parameters
    ----------
    features : (T, 12) float
        Wrist position (cm, scaled to the database's body size) and rotation features
        (:func:`~usdhands.algorithms.synthesis.wrist_features.wrist_features`) at the
        database's frame rate.
    db : FingerDatabase
    side : {"left", "right"}
        Which of the database's tracks to search.
    config : SynthesisConfig, optional
    exclude_clips : sequence of int
        Database clips not to use (leave-one-out).
    db_weighted : (F, D) float, optional
        ``weight_features(db.features, segment_weights(config))`` when already computed,
        or, with ``query_weighted``, other weighted features behind the segment cost.
    hooks : object, optional
        Interactions (seed 002): ``hooks.cuts(bounds) -> bounds`` adds segment boundaries
        (proximity to props), ``hooks.penalty(bounds, candidates) -> (N, k)`` adds a
        collision term to the segment costs
        (:class:`~usdhands.algorithms.interaction.synthesis_terms.InteractionTerms`).
    segments : (N,) bool, optional
        Database segments that may be used (k-fold: those outside the held-out windows).
    query_weighted : (T, D) float, optional
        Weighted features of the input matching ``db_weighted`` columns (the wrist
        ``features`` still segment the input).

    Raises
    ------
    ValueError
        The database has no segment for this side.
    """
    cfg = config or SynthesisConfig()
    feats = np.asarray(features, dtype=np.float64)
    if feats.ndim != 2 or feats.shape[1] != NUM_WRIST_FEATURES or len(feats) == 0:
        raise ValueError(f"Expected features to have shape (T, {NUM_WRIST_FEATURES}) with T > 0, got {feats.shape}")
    sc = cfg.segment_cost
    weights = segment_weights(cfg)
    if query_weighted is None and sc.features is not None:
        raise ValueError(f"Features {sc.features!r} need query_weighted and db_weighted "
                         f"(query_features, db_weighted_features)")
    if query_weighted is not None:
        if db_weighted is None or np.shape(query_weighted) != (len(feats), np.shape(db_weighted)[1]):
            raise ValueError("Expected query_weighted (T, D) with db_weighted (F, D)")
        qw = np.ascontiguousarray(query_weighted, dtype=np.float64)
    else:
        qw = weight_features(feats, weights)
    dw = weight_features(db.features, weights) if db_weighted is None else db_weighted
    seg_idx = db_side_segments(db, side, exclude_clips)
    usable = None  # frames the model may learn from (None: all of the database)
    if segments is not None or len(exclude_clips):
        usable_segments = np.ones(len(db.segments), dtype=bool) if segments is None else \
            np.asarray(segments, dtype=bool).copy()
        if len(exclude_clips):
            usable_segments &= ~np.isin(db.segment_clip(), np.asarray(list(exclude_clips), dtype=np.int64))
        seg_idx = seg_idx[usable_segments[seg_idx]]
        usable = db.segment_frames(usable_segments)
    if not len(seg_idx):
        raise ValueError(f"The database has no {side}-hand segments to choose from")
    k = min(sc.k, len(seg_idx))  # more candidates than segments: (k, k) transition arrays for nothing
    bounds = segment_track(feats, db.fps, cfg.segmentation)
    if hooks is not None:
        bounds = hooks.cuts(bounds)
    speed = wrist_speed(feats[:, :3], db.fps, cfg.segmentation.speed_smoothing_s)
    qb = np.stack([bounds[:-1], bounds[1:]], axis=1)
    dsegs = db.segments[seg_idx, :2]
    res = knn_segments(qw, qb, dw, dsegs, k=k, length_factor=sc.length_factor, band=sc.dtw_band,
                       bound=sc.lower_bound)
    cand_local = res.index.copy()
    costs = res.cost.copy()
    missing = np.nonzero(cand_local[:, 0] < 0)[0]
    if len(missing):
        # no segment of a compatible length: widen the length factor for these only
        wide = knn_segments(qw, qb[missing], dw, dsegs, k=k, length_factor=1e6, band=1.0)
        cand_local[missing] = wide.index
        costs[missing] = wide.cost
    for i in np.nonzero(cand_local[:, 0] < 0)[0]:
        # shorter than half of every database segment (a clip of a few frames): no warp
        # with steps of at most 2 fits, so compare with each segment sampled uniformly
        cand_local[i], costs[i] = _uniform_knn(qw[qb[i, 0]:qb[i, 1]], dw, dsegs, k)
    cand = np.where(cand_local >= 0, seg_idx[np.maximum(cand_local, 0)], -1)
    if hooks is not None:
        costs = costs + hooks.penalty(bounds, cand)
    N = len(cand)
    starts, ends, vstart, vend = _candidate_ends(db, cand)
    tc = cfg.transition
    moving = db.moving_dofs(usable)
    transitions = list(transition_costs_between(ends[:-1], vend[:-1], starts[1:], vstart[1:], tc.w_joint,
                                                tc.w_velocity, moving))
    path, _ = least_cost_path(costs, transitions, cfg.path.w_segment, cfg.path.w_transition,
                              cfg.path.normalize_terms)
    chosen = cand[np.arange(N), path]
    st = cfg.stitching
    played = played_weights(costs, cand, path, st.candidate_mix, db.segment_clip()[np.maximum(cand, 0)])
    lens = db.segments[np.maximum(cand, 0), 1] - db.segments[np.maximum(cand, 0), 0]  # (N, k)
    n = (qb[:, 1] - qb[:, 0])[:, None]
    bands = np.where((sc.length_factor * lens >= n) & (lens <= sc.length_factor * n), sc.dtw_band, 1.0)
    kernels = play_kernels()  # numba's only where the search loaded numba anyway
    if kernels is not None:
        out = play_segments_fast(qw, dw, db.fingers, db.segments[:, :2], qb, cand, played, bands, db.fps,
                                 st.warp_smoothing_s, kernels)
    else:
        out = play_segments(qw, dw, db.fingers, db.segments[:, :2], qb, cand, played, bands, db.fps,
                            st.warp_smoothing_s)
    _log.info("%s hand: %d segment(s) of the wrist motion; chose database segments %s (path cost %.3g)", side, N,
              " ".join(str(int(c)) for c in chosen), float(sum(costs[i, path[i]] for i in range(N))))
    limits = db.step_limits(st.step_percentile, usable)
    if kernels is not None:
        compact, seams = stitch_fragments_fast(out, bounds, db.fps, st.blend_mean_deg, st.blend_max_deg,
                                               st.blend_duration_s, moving, kernels)
        compact = limit_steps_fast(compact, limits, kernels)
    else:
        compact, seams = stitch_fragments([out[q0:q1] for q0, q1 in qb], db.fps, st.blend_mean_deg,
                                          st.blend_max_deg, st.blend_duration_s, moving)
        compact = limit_steps(compact, limits)
    curves = np.zeros((len(feats), NUM_DOFS))
    curves[:, db.dof_index] = compact
    return HandSynthesis(side, bounds, speed, cand, costs, transitions, path, chosen, curves, seams, res)


def candidate_weights(costs: np.ndarray) -> np.ndarray:
    """Weights ``(k,)`` summing to 1 of a row's candidates, proportional to ``1 / cS²`` (eq. 1 costs).

    Missing candidates (``inf``) get 0; candidates of zero cost (the input's own
    motion is in the database) share all the weight. The square makes the weights fall
    fast with the cost: a candidate twice as far as the best counts a quarter as much
    (with ``1 / cS``, on the small test set of the tests, where only two of the five
    candidates show the held-out gesture, mixing hurt; see docs/synthesis.md).
    """
    c = np.asarray(costs, dtype=np.float64)
    ok = np.isfinite(c)
    w = np.zeros(len(c))
    if not ok.any():
        return w
    zero = ok & (c <= 0)
    if zero.any():
        w[zero] = 1.0
    else:
        w[ok] = (c[ok].min() / c[ok]) ** 2
    return w / w.sum()


def played_weights(costs: np.ndarray, cand: np.ndarray, path: np.ndarray, mix: float,
                   takes: np.ndarray | None = None) -> np.ndarray:
    """Weight ``(N, k)`` of every candidate in the fragment played for each input segment.

    ``(1 − mix)`` for the path's candidate plus ``mix`` times :func:`candidate_weights`
    of the row (``costs (N, k)``, ``cand (N, k)`` with -1 for none, ``path (N,)``).
    With ``takes (N, k)`` (the database clip of each candidate), the other candidates
    from the path's own take get no share: the mix is there to average out the few
    degrees of finger pose each take holds of its own, which candidates of one take
    share (mixing them only blurs its motion; on a database of one take the fragment
    is the path's candidate alone, as in the paper).
    """
    c = np.where(np.asarray(cand) >= 0, np.asarray(costs, dtype=np.float64), np.inf)
    if takes is not None:
        rows = np.arange(len(c))
        takes = np.asarray(takes)
        same = (takes == takes[rows, path][:, None]) & (np.arange(c.shape[1])[None] != np.asarray(path)[:, None])
        c = np.where(same, np.inf, c)
    ok = np.isfinite(c)
    zero = ok & (c <= 0)
    best = np.where(ok, c, np.inf).min(axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(zero.any(axis=1, keepdims=True), zero.astype(float), np.where(ok, (best / c) ** 2, 0.0))
    total = w.sum(axis=1, keepdims=True)
    w = mix * np.divide(w, total, out=np.zeros_like(w), where=total > 0)  # each row as candidate_weights
    w[np.arange(len(w)), path] += 1.0 - mix
    return w


def segment_weights(config: SynthesisConfig) -> list[float]:
    """Weights of the wrist feature columns in eq. 1: ``wP`` for the 3 positions, ``wR`` for the rotation entries.

    Only for the paper's features (``segment_cost.features`` unset); see :func:`db_weighted_features`.
    """
    sc = config.segment_cost
    return [sc.w_position] * 3 + [sc.w_rotation] * (NUM_WRIST_FEATURES - 3)


def db_weighted_features(db: FingerDatabase, config: SynthesisConfig) -> np.ndarray:
    """The database's weighted feature columns of eq. 1, ``(F, D)`` float64, for the configuration's features.

    The paper's wrist features weighted by ``w_position``/``w_rotation``, or the
    columns of ``segment_cost.features`` (:mod:`~usdhands.algorithms.synthesis.feature_sets`).

    Raises
    ------
    ValueError
        The features name columns the database does not hold (built without them).
    """
    terms = feature_terms(config.segment_cost)
    missing = [key for key in extra_keys(terms) if key not in db.arm_feature_names]
    if missing:
        raise ValueError(f"The database holds no {', '.join(repr(k) for k in missing)} features; build it with a "
                         f"configuration naming them (segment_cost.features)")
    if config.segment_cost.features is None:
        return weight_features(db.features, segment_weights(config))
    return weighted_columns(db.features, db.arm_features, db.arm_feature_names, terms)


def query_features(clip: Clip, handmap: HandMap, side: str, wrist: np.ndarray, reach: float,
                   config: SynthesisConfig, world: np.ndarray | None = None) -> np.ndarray | None:
    """The input's weighted feature columns ``(T, D)`` for ``segment_cost.features``, at the clip's rate.

    ``wrist (T, 12)`` are the hand's wrist features (scaled to ``reach``, the database's
    body size). None for the paper's features (synthesis weights ``wrist`` itself).
    """
    if config.segment_cost.features is None:
        return None
    terms = feature_terms(config.segment_cost)
    keys = extra_keys(terms)
    cols = hand_columns(clip, handmap, side, keys, reach, world)
    extra = np.concatenate([cols[key] for key in keys], axis=1) if keys else None
    return weighted_columns(wrist, extra, keys, terms)


def resample_rows(values: np.ndarray, fps_from: float, fps_to: float, n_to: int) -> np.ndarray:
    """Linear resampling of rows ``(T, C)`` from one frame rate to ``n_to`` rows at another."""
    values = np.asarray(values, dtype=np.float64)
    t_from = np.arange(len(values)) / fps_from
    t_to = np.arange(n_to) / fps_to
    out = np.empty((n_to, values.shape[1]))
    for c in range(values.shape[1]):
        out[:, c] = np.interp(t_to, t_from, values[:, c])
    return out


def _mapping(rig: HandRig, db: FingerDatabase, skeleton) -> tuple[HandRig, dict]:
    db_slots = db.dof_mask().reshape(-1, 3).all(axis=1)
    names = slot_names()
    mapped, no_source, dropped = [], [], []
    keep = rig.slot_joint.copy()
    for s, j in enumerate(rig.slot_joint):
        if j >= 0 and db_slots[s]:
            mapped.append([skeleton.joint_names[j], names[s]])
        elif j >= 0:
            no_source.append(skeleton.joint_names[j])
            keep[s] = -1
        elif db_slots[s]:
            dropped.append(names[s])
    no_source.extend(rig.unmapped)
    return (HandRig(rig.side, keep, rig.frame, rig.unmapped, rig.reference),
            {"mapped": mapped, "no_source": no_source, "dropped": dropped})


def synthesize_clip(clip: Clip, handmap: HandMap, db: FingerDatabase, config: SynthesisConfig | None = None,
                    hands: tuple[str, ...] = SIDES, exclude_clips=(), finger_reference: str = "rest",
                    interaction=None) -> ClipSynthesis:
    """Give a clip finger motion from the database; every other joint is left as it was.

    Parameters
    ----------
    clip : Clip
    handmap : HandMap
    db : FingerDatabase
    config : SynthesisConfig, optional
    hands : tuple of {"left", "right"}
        Hands to synthesize (those the hand map lacks are skipped).
    exclude_clips : sequence of int
        Database clips not to use.
    finger_reference : {"rest", "input"}
        What the synthesized finger rotations are relative to: the rig's rest pose, or
        the pose the input's fingers hold at its first frame (for body-only clips whose
        frozen fingers show the rig's natural pose while its rest pose does not, such
        as a BVH whose zero pose is not the bind pose).
    interaction : callable, optional
        ``interaction(side, hand, rig) -> hooks`` for :func:`synthesize_hand` (props).

    Returns
    -------
    ClipSynthesis
        ``mapping[side]`` lists the joints mapped (with their slot), the character's
        finger joints with no counterpart in the database (left as they were), and
        the database slots the character has no joint for.
    """
    cfg = config or SynthesisConfig()
    if finger_reference not in ("rest", "input"):
        raise ValueError(f"Expected finger_reference 'rest' or 'input', got {finger_reference!r}")
    for h in hands:
        if h not in SIDES:
            raise ValueError(f"Expected hands among {SIDES}, got {h!r}")
    arms = handmap.sides if cfg.segment_cost.features is not None else [handmap[s] for s in hands]  # other_ keys
    world = world_xforms_for(clip, [h for h in arms if h is not None])
    out = clip
    results, mapping, scales = {}, {}, {}
    joints, locals_ = [], []
    dw = db_weighted_features(db, cfg)
    for side in hands:
        hand = handmap[side]
        if hand is None or not hand.finger_joints:
            continue
        pose = clip if finger_reference == "input" else None
        rig, mapping[side] = _mapping(hand_rig(clip.skeleton, hand, pose), db, clip.skeleton)
        scale = db.reach_cm / reach_cm(clip.skeleton, hand)
        scales[side] = scale
        feats = wrist_features(clip, hand, scale, world)
        qw = query_features(clip, handmap, side, feats, db.reach_cm, cfg, world)
        resampled = not same_rate(clip.fps, db.fps)
        if resampled:
            n = resampled_frames(clip.num_frames, clip.fps, db.fps)
            feats = resample_rows(feats, clip.fps, db.fps, n)
            qw = None if qw is None else resample_rows(qw, clip.fps, db.fps, n)
        hooks = interaction(side, hand, rig) if interaction is not None else None
        res = synthesize_hand(feats, db, side, cfg, exclude_clips, dw, hooks=hooks, query_weighted=qw)
        curves = res.curves
        if resampled:
            curves = resample_rows(curves, db.fps, clip.fps, clip.num_frames)
        results[side] = res
        j, local = canonical_local_rotations(clip, rig, curves)
        joints += j
        locals_.append(local)
    if joints:  # both hands written at once: one copy of the clip's arrays
        out = clip.with_joint_rotations(joints, np.concatenate(locals_, axis=1))
    return ClipSynthesis(out, results, mapping, scales)

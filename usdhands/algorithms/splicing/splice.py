"""Splicing a separately captured hand performance onto a body performance.

Majkowska, Zordan and Faloutsos 2006, *Automatic splicing for hand and body
animations* (sections 3 and 4). For each hand:

1. **Markers** (:func:`markers_from_joints`): two wrist markers ``p1, p2``, a forearm
   marker ``p3`` and a hand marker ``p4`` per frame, from joints at fixed offsets in
   the wrist's and the forearm's local frames (:class:`MarkerOffsets`), or real
   marker positions given as arrays. Centimetres, Y up.
2. **First pass** (phase matching): the shoulder is subtracted from the markers, the
   hand clip is turned about the vertical axis onto the body (eq. 7, windows of 5
   frames, or the trunk angles), and DTW in the band of eq. 3 (30 % of the body
   length), bent through the user's constraints (eq. 4–5), minimises the distance of
   eq. 6: how many signs of the first and second derivatives of the markers differ.
3. **Second pass** (within phases): DTW in a narrower band (10 %) around the first
   path, still through the constraints, over the angle between the hand vectors once
   the forearms are aligned (eq. 8–9), in degrees. By default the forearms are aligned
   as joint frames (:func:`hand_directions`); ``forearm_align="vector"`` is the paper's
   minimal rotation between the markers' forearm vectors.
4. **Merge**: a body frame matched to several hand frames takes their median
   (a fractional frame, sampled by slerp); where the hand frame jumps ahead, the
   finger motion is cross-faded over a window (:func:`transfer_fingers`).

Finger rotations are transferred relative to each skeleton's rest pose:
``q_body = rest_body * (rest_hand⁻¹ * q_hand)`` when both rigs' finger joints share
their axis conventions and rest rotations, as they are when only the declared rest
rotations differ (a glTF character and its BVH export), otherwise through the hands'
rest axes (:func:`transfer_axes`); ``SpliceOptions.transfer`` chooses
(:func:`choose_transfer`). Finger joints are paired
finger by finger from the distal end of each chain, so a chain with a metacarpal
pairs with one without.

A hand clip without a shoulder joint (a hand-only capture such as a Leap Motion
BVH rooted at the forearm) is used without subtraction: the capture's trunk is
assumed still, as in the paper's hand sessions, and the signs of derivatives do not
change when a constant is subtracted (eq. 7 fits the horizontal translation too).
Subtracting the forearm instead would erase the arm motion the first pass relies on.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from usdhands.algorithms.dtw import Band, Constraint, WarpResult, check_constraints, dtw
from usdhands.model.clip import Clip
from usdhands.model.handmap import FINGERS, HandSide
from usdhands.model.rotations import quat_conjugate, quat_multiply, quat_slerp
from usdhands.algorithms.splicing.markers import (
    transfer_axes, choose_transfer, default_marker_offsets, _to_yup_cm,
    markers_from_xforms, trunk_yaw_from_xforms,
)
from usdhands.algorithms.splicing.costs import (
    sign_features, FirstPassInput, first_pass_band_cost, forearm_hand_vectors,
    hand_directions_from_xforms, forearm_rest_basis, fit_rotation, direction_angle_band_cost, hand_angle_cost,
)
from usdhands.algorithms.splicing.kinematics import chain_xforms
from usdhands.algorithms.splicing.sampling import one_hemisphere, relative_rotations, rest_times, sample_rotations

_log = logging.getLogger(__name__)

__all__ = [
    "SpliceOptions", "SideAlignment", "median_alignment", "phase_boundaries", "align_hands", "pair_finger_joints", "FingerTransfer", "transfer_fingers", "SpliceResult", "splice_clips",
]


# -- the two passes ---------------------------------------------------------------------
@dataclass(frozen=True)
class SpliceOptions:
    """Parameters of the alignment (defaults from the paper where it gives them).

    Parameters
    ----------
    band1, band2 : float
        Band half-widths of the first and second pass as fractions of the body length.
    yaw : {"window", "trunk", "none"}
        Rotation about the vertical axis: eq. 7 over ``yaw_window`` frames, the
        difference of trunk headings, or none.
    yaw_window : int
        Frames per eq. 7 window (5 in the paper: 20 marker positions).
    hand_trunk_yaw_deg : float
        Heading of the hand capture's trunk when its skeleton has no root (``"trunk"``).
    smooth_window : int
        Savitzky–Golay window (frames) for the derivatives.
    dead_zone : float
        Fraction of the RMS derivative under which a sign counts as 0.
    blend_window : int
        Frames on each side of a jump in the hand timing that are cross-faded.
    jump_frames : float
        A step of the matched hand frame larger than the clips' mean rate plus this
        many frames is a discontinuity to blend.
    min_phase : int
        Shortest phase, in frames, reported among the phase boundaries.
    forearm_align : {"frame", "vector"}
        Second pass: align the forearms as joint frames (:func:`hand_directions`,
        needs joints) or, as in the paper, by the minimal rotation between the
        forearm vectors of the markers (eq. 9).
    refit : int
        With ``forearm_align="frame"``: how many times the rest-pose guess of the
        rotation between the two rigs' forearm frames is refitted on the second pass's
        matches.
    transfer : {"auto", "local", "copy", "hand"}
        How finger rotations go from one rig to the other (:func:`transfer_fingers`);
        ``"auto"`` asks :func:`choose_transfer`.
    auto_transfer_deg : float
        The threshold of ``"auto"``.
    still_range_cm : float
        A hand whose wrist moves less than this (range of the wrist markers relative to
        the shoulder, centimetres, largest over the axes) in either clip carries no
        timing: when the other hand moves, the still hand takes the other hand's
        alignment (both hands of a take share one timing). 0 turns this off.
    """

    band1: float = 0.3
    band2: float = 0.1
    yaw: str = "window"
    yaw_window: int = 5
    hand_trunk_yaw_deg: float = 0.0
    smooth_window: int = 7
    dead_zone: float = 0.05
    blend_window: int = 4
    jump_frames: float = 2.0
    min_phase: int = 4
    forearm_align: str = "frame"
    refit: int = 1
    transfer: str = "auto"
    auto_transfer_deg: float = 10.0
    still_range_cm: float = 5.0

    def __post_init__(self) -> None:
        if self.transfer not in ("local", "copy", "hand", "auto"):
            raise ValueError(f"Expected transfer 'auto', 'local', 'copy' or 'hand', got {self.transfer!r}")
        if self.forearm_align not in ("frame", "vector"):
            raise ValueError(f"Expected forearm_align 'frame' or 'vector', got {self.forearm_align!r}")
        if self.yaw not in ("window", "trunk", "none"):
            raise ValueError(f"Expected yaw 'window', 'trunk' or 'none', got {self.yaw!r}")
        for k in ("band1", "band2"):
            v = getattr(self, k)
            if not v > 0:
                raise ValueError(f"Expected {k} > 0, got {v}")
        if self.yaw_window < 1 or self.yaw_window % 2 == 0:
            raise ValueError(f"Expected an odd yaw_window >= 1, got {self.yaw_window}")


@dataclass(frozen=True, eq=False)
class SideAlignment:
    """The alignment of one hand.

    Parameters
    ----------
    side : str
    first, second : WarpResult
        The two passes (path rows are body frames, columns hand frames).
    alignment : (n,) float
        For each body frame the hand frame used (median of the second path's matches;
        .5 where the median falls between two frames).
    phases : (P, 2) float
        Phase boundaries: body frame and the hand frame the first pass matched to it.
    """

    side: str
    first: WarpResult
    second: WarpResult
    alignment: np.ndarray
    phases: np.ndarray


def median_alignment(path: np.ndarray, n: int) -> np.ndarray:
    """For each of ``n`` rows the median column the path visits, ``(n,)`` float.

    A monotone path visits consecutive columns within a row, so the median is the
    mean of the row's first and last column.
    """
    path = np.asarray(path)
    rows = np.arange(n)
    starts = np.searchsorted(path[:, 0], rows, side="left")
    stops = np.searchsorted(path[:, 0], rows, side="right")
    if np.any(stops <= starts):
        raise ValueError(f"Expected a path that visits every row 0..{n - 1}")
    return 0.5 * (path[starts, 1] + path[stops - 1, 1])


def phase_boundaries(vel: np.ndarray, eps: float, min_phase: int) -> np.ndarray:
    """Frames where the sign pattern of the wrist's velocity changes, ``(P,)`` int.

    Parameters
    ----------
    vel : (T, 3) float
        Velocity of the wrist centre (cm/s).
    eps : float
        Dead zone (cm/s): smaller components count as 0.
    min_phase : int
        Runs shorter than this many frames do not start a phase.
    """
    code = np.where(vel > eps, 1, np.where(vel < -eps, -1, 0))
    key = code[:, 0] * 9 + code[:, 1] * 3 + code[:, 2]
    change = np.nonzero(key[1:] != key[:-1])[0] + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [len(key)]])
    out = []
    cur = None
    for s, e in zip(starts, ends):
        if e - s < min_phase:
            continue
        if cur is not None and key[s] != cur and s > 0:
            out.append(int(s))
        cur = key[s]
    return np.array(out, dtype=np.int64)


def align_hands(body_markers: np.ndarray, hand_markers: np.ndarray, fps: float, *,
                body_ref: np.ndarray | None = None, hand_ref: np.ndarray | None = None,
                constraints: Sequence[Constraint] = (), options: SpliceOptions = SpliceOptions(),
                body_yaw_deg: np.ndarray | None = None, hand_yaw_deg: np.ndarray | None = None,
                body_hand_dirs: np.ndarray | None = None, hand_hand_dirs: np.ndarray | None = None,
                frame_rotation: np.ndarray | None = None, side: str = "right") -> SideAlignment:
    """Two-pass DTW of one hand's markers (section 3 and 4 of the paper).

    Parameters
    ----------
    body_markers : (n, 4, 3) float
        p1, p2 (wrist), p3 (forearm), p4 (hand) of the body clip, cm, Y up.
    hand_markers : (m, 4, 3) float
        The same for the hand clip, at the same frame rate.
    fps : float
        Frame rate of both.
    body_ref, hand_ref : (n, 3), (m, 3) float, optional
        Shoulder positions (cm, Y up) subtracted from the markers; omitted: nothing
        subtracted (a still trunk).
    constraints : sequence of Constraint
        Body frame to hand frame pairs with tolerances.
    options : SpliceOptions
    body_yaw_deg, hand_yaw_deg : (n,), (m,) float, optional
        Trunk headings in degrees, needed for ``options.yaw == "trunk"``.
    body_hand_dirs, hand_hand_dirs : (n, 3), (m, 3) float, optional
        Forearm-aligned unit hand vectors (:func:`hand_directions`); with
        ``options.forearm_align == "frame"`` the second pass compares these, otherwise
        it aligns the markers' forearm vectors (eq. 8–9).
    frame_rotation : (3, 3) float, optional
        A guess of the rotation from the hand rig's forearm frame to the body rig's
        (``forearm_rest_basis(body) @ forearm_rest_basis(hands).T``); tried, refitted,
        against no rotation.

    Returns
    -------
    SideAlignment
    """
    P = np.array(body_markers, dtype=np.float64)
    Q = np.array(hand_markers, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3 or Q.ndim != 3 or Q.shape[1:] != P.shape[1:]:
        raise ValueError(f"Expected markers of shapes (n, K, 3) and (m, K, 3), got {P.shape} and {Q.shape}")
    n, m = P.shape[0], Q.shape[0]
    if body_ref is not None:
        P -= np.asarray(body_ref, dtype=np.float64)[:, None, :]
    if hand_ref is not None:
        Q -= np.asarray(hand_ref, dtype=np.float64)[:, None, :]
    cons = check_constraints(list(constraints), n, m)
    vb, ab, evb, eab = sign_features(P, fps, window=options.smooth_window, dead_zone=options.dead_zone)
    vh, ah, evh, eah = sign_features(Q, fps, window=options.smooth_window, dead_zone=options.dead_zone)
    yaw_b = yaw_h = None
    if options.yaw == "trunk":
        if body_yaw_deg is None:
            raise ValueError("yaw='trunk' needs body_yaw_deg")
        yaw_b = np.asarray(body_yaw_deg, dtype=np.float64)
        yaw_h = (np.full(m, options.hand_trunk_yaw_deg) if hand_yaw_deg is None
                 else np.asarray(hand_yaw_deg, dtype=np.float64))
    elif options.yaw == "none":
        yaw_b, yaw_h = np.zeros(n), np.zeros(m)
    inp = FirstPassInput(np.ascontiguousarray(P), np.ascontiguousarray(Q), vb, ab, vh, ah,
                        (evb, eab, evh, eah), options.yaw_window // 2, yaw_b, yaw_h)
    band1 = Band.diagonal(n, m, options.band1, cons)
    first = dtw(lambda band: first_pass_band_cost(inp, band), band1, shape=(n, m), on_band=True)
    band2 = Band.around_path(first.path, n, m, options.band2).intersect(Band.diagonal(n, m, np.inf, cons))
    if options.forearm_align == "frame" and body_hand_dirs is not None and hand_hand_dirs is not None:
        ub = np.asarray(body_hand_dirs, dtype=np.float64)
        uh = np.asarray(hand_hand_dirs, dtype=np.float64)
        if ub.shape != (n, 3) or uh.shape != (m, 3):
            raise ValueError(f"Expected hand directions of shapes ({n}, 3) and ({m}, 3), got {ub.shape} and {uh.shape}")
        # The two rigs' forearm frames may differ by a constant rotation. Candidates: none (same
        # joint axes), and the rest-pose guess refitted on the second pass's matches; the one
        # whose second pass costs less wins.
        candidates = [(np.eye(3), 0)]
        if frame_rotation is not None:
            G = np.asarray(frame_rotation, dtype=np.float64)
            if G.shape != (3, 3):
                raise ValueError(f"Expected frame_rotation of shape (3, 3), got {G.shape}")
            if np.degrees(np.arccos(np.clip((np.trace(G) - 1) / 2, -1, 1))) > 1.0:
                candidates.append((G, options.refit))
        second = None
        for R, refits in candidates:
            for k in range(refits + 1):
                uh_r = uh @ R.T
                res = dtw(lambda band: direction_angle_band_cost(ub, uh_r, band), band2, shape=(n, m), on_band=True)
                if k < refits:
                    match = np.clip(np.round(median_alignment(res.path, n)).astype(int), 0, m - 1)
                    R = fit_rotation(ub, uh[match])
            if second is None or res.cost < second.cost:
                second = res
    else:
        fb, hb = forearm_hand_vectors(P)
        fh, hh = forearm_hand_vectors(Q)
        second = dtw(lambda r, c: hand_angle_cost(fb, hb, fh, hh, r, c), band2, shape=(n, m))
    align = median_alignment(second.path, n)
    wrist_v = 0.5 * (vb[:, 0] + vb[:, 1])
    pb = phase_boundaries(wrist_v, evb, options.min_phase)
    first_align = median_alignment(first.path, n)
    phases = np.stack([pb.astype(float), first_align[pb]], axis=1) if pb.size else np.zeros((0, 2))
    return SideAlignment(side=side, first=first, second=second, alignment=align, phases=phases)


# -- merging: fingers onto the body -------------------------------------------------------
def pair_finger_joints(body_side: HandSide, hand_side: HandSide) -> tuple[list[tuple[str, str]], list[str], list[str]]:
    """Pair finger joints of two rigs by finger and position from the fingertip.

    Returns
    -------
    pairs : list of (body joint, hand joint)
    body_unmatched : list of str
        Body finger joints with no counterpart (they keep the body's animation).
    hand_unmatched : list of str
        Hand finger joints not used.
    """
    pairs, bu, hu = [], [], []
    for f in FINGERS:
        b = list(body_side.fingers[f])
        h = list(hand_side.fingers[f])
        k = min(len(b), len(h))
        pairs += list(zip(b[len(b) - k:], h[len(h) - k:]))
        bu += b[:len(b) - k]
        hu += h[:len(h) - k]
    return pairs, bu, hu


@dataclass(frozen=True, eq=False)
class FingerTransfer:
    """Finger rotations for the body.

    Parameters
    ----------
    joints : list of int
        Body skeleton indices.
    rotations : (n, len(joints), 4) float
        Local rotations, xyzw.
    seams : (S,) int
        Body frames after which the hand timing jumped and the motion was cross-faded.
    """

    joints: list
    rotations: np.ndarray
    seams: np.ndarray


def transfer_fingers(body: Clip, hands: Clip, pairs: Sequence[tuple[str, str]], alignment: np.ndarray, *,
                     blend_window: int = 4, jump_frames: float = 2.0, mode: str = "local",
                     axes: np.ndarray | None = None) -> FingerTransfer:
    """Finger rotations of ``hands`` at the aligned frames, put on ``body``'s joints.

    Parameters
    ----------
    body, hands : Clip
        Same frame rate.
    pairs : sequence of (body joint name, hand joint name)
    alignment : (n,) float
        Hand frame for each body frame (fractional allowed).
    blend_window : int
        Half-width (frames) of the cross-fade at a jump.
    jump_frames : float
        Extra hand frames per body frame beyond the mean rate that make a jump.
    mode : {"local", "copy", "hand"}
        ``"local"``: rotations relative to rest, ``q_body = rest_body · rest_hand⁻¹ ·
        q_hand``; ``"copy"``: local rotations as they are, ``q_body = q_hand`` (rigs
        whose joint frames coincide but whose declared rest rotations differ, such as
        a glTF character and its BVH export); ``"hand"``: rotations relative to rest
        carried through the hands' rest axes, ``q_body = rest_body · c · rest_hand⁻¹ ·
        q_hand · c⁻¹`` with ``c`` from ``axes``.
    axes : (len(pairs), 4) float, optional
        :func:`transfer_axes`, for ``mode="hand"``.
    """
    if mode not in ("local", "copy", "hand"):
        raise ValueError(f"Expected mode 'local', 'copy' or 'hand', got {mode!r}")
    if mode == "hand" and axes is None:
        raise ValueError("mode='hand' needs axes (transfer_axes)")
    a = np.asarray(alignment, dtype=np.float64)
    n = body.num_frames
    if a.shape != (n,):
        raise ValueError(f"Expected alignment of shape ({n},), got {a.shape}")
    bj = [body.skeleton.index(b) for b, _ in pairs]
    hj = [hands.skeleton.index(h) for _, h in pairs]
    if not pairs:
        return FingerTransfer([], np.zeros((n, 0, 4)), np.zeros(0, np.int64))
    rel = np.array(hands.rotations[:, hj])
    if mode != "copy":
        rel = relative_rotations(rel, hands.skeleton.rest_rotations[hj])
    one_hemisphere(rel)  # so slerp and blends take short arcs
    out = sample_rotations(rel, a)
    rate = (hands.num_frames - 1) / max(n - 1, 1)
    steps = np.diff(a)
    seams = np.nonzero(steps > rate + jump_frames)[0]
    w = int(blend_window)
    if w > 0:
        for s in seams:
            lo, hi = max(s - w + 1, 0), min(s + w, n - 1)
            t = np.arange(lo, hi + 1)
            left_t = np.where(t <= s, a[t], a[s] + (t - s) * rate)
            right_t = np.where(t >= s + 1, a[t], a[s + 1] - (s + 1 - t) * rate)
            alpha = (t - lo + 1) / (hi - lo + 2)
            alpha = alpha * alpha * (3 - 2 * alpha)  # smoothstep
            ql = sample_rotations(rel, left_t)
            qr = sample_rotations(rel, right_t)
            out[t] = quat_slerp(ql, qr, alpha[:, None] * np.ones(len(pairs)))
    if mode == "copy":
        return FingerTransfer(bj, out, seams.astype(np.int64))
    if mode == "hand":
        c = np.asarray(axes, dtype=np.float64)
        if c.shape != (len(pairs), 4):
            raise ValueError(f"Expected axes of shape ({len(pairs)}, 4), got {c.shape}")
        out = quat_multiply(quat_multiply(c[None], out), quat_conjugate(c)[None])
    rots = rest_times(body.skeleton.rest_rotations[bj], out)
    return FingerTransfer(bj, rots, seams.astype(np.int64))


@dataclass(frozen=True, eq=False)
class SpliceResult:
    """The body clip with spliced fingers and what was found on the way.

    Parameters
    ----------
    clip : Clip
        The body clip, finger joints replaced.
    sides : dict of str to SideAlignment
        Per hand.
    transfers : dict of str to FingerTransfer
    pairs : dict of str to list of (body joint, hand joint)
    body_unmatched, hand_unmatched : dict of str to list of str
        Finger joints without a counterpart, per hand.
    transfer_modes : dict of str to str
        ``"local"``, ``"copy"`` or ``"hand"`` per hand (what ``"auto"`` chose).
    timing_from : dict of str to str
        Per hand, the hand whose alignment it uses: itself, or the other hand when its
        own arm is still (``SpliceOptions.still_range_cm``).
    wrist_range_cm : dict of str to (float, float)
        Per hand, the wrist's range relative to the shoulder in BODY and in HANDS.
    """

    clip: Clip
    sides: dict
    transfers: dict
    pairs: dict
    body_unmatched: dict
    hand_unmatched: dict
    transfer_modes: dict
    timing_from: dict = field(default_factory=dict)
    wrist_range_cm: dict = field(default_factory=dict)


def splice_clips(body: Clip, hands: Clip, body_sides: dict, hand_sides: dict, *,
                 constraints: Sequence[Constraint] = (), options: SpliceOptions = SpliceOptions(),
                 body_offsets: dict | None = None, hand_offsets: dict | None = None,
                 body_markers: dict | None = None, hand_markers: dict | None = None,
                 progress=None) -> SpliceResult:
    """Splice the fingers of ``hands`` onto ``body``, each hand on its own.

    Parameters
    ----------
    body : Clip
        Full-body clip.
    hands : Clip
        Hand clip at the same frame rate (resample first).
    body_sides, hand_sides : dict of str to HandSide
        The hands to splice, keyed ``"left"``/``"right"``; the same keys in both.
    constraints : sequence of Constraint
        Body frame to hand frame pairs (frames of these two clips), used for every hand.
    options : SpliceOptions
    body_offsets, hand_offsets : dict of str to MarkerOffsets, optional
        Marker placement per hand; :func:`default_marker_offsets` otherwise.
    body_markers, hand_markers : dict of str to (T, 4, 3) float, optional
        Real marker positions per hand (p1, p2 wrist, p3 forearm, p4 hand; centimetres,
        Y up; one row per frame of ``body`` / ``hands``), used instead of markers placed
        on the joints. The second pass with ``forearm_align="frame"`` still compares the
        joints' frames; ``"vector"`` uses these markers (eq. 8–9).
    progress : callable, optional
        ``progress(done, total, label)``.

    Raises
    ------
    ValueError
        Frame rates that differ, sides that do not match, a hand without forearm.
    """
    if abs(body.fps - hands.fps) > 1e-6 * body.fps:
        raise ValueError(f"Expected clips at the same frame rate, got {body.fps} and {hands.fps}")
    if set(body_sides) != set(hand_sides) or not body_sides:
        raise ValueError(f"Expected the same non-empty sides, got {sorted(body_sides)} and {sorted(hand_sides)}")
    # forward kinematics once for both hands, only the joints read below and their ancestors
    wb = chain_xforms(body, [j for s in body_sides.values() for j in _side_joints(body.skeleton, s)])
    wh = chain_xforms(hands, [j for s in hand_sides.values() for j in _side_joints(hands.skeleton, s)])
    rot = None
    sides, transfers, pairs_all, bun, hun, modes, ranges = {}, {}, {}, {}, {}, {}, {}
    order = [s for s in ("left", "right") if s in body_sides]
    for k, s in enumerate(order):
        bs, hs = body_sides[s], hand_sides[s]
        bo = (body_offsets or {}).get(s) or default_marker_offsets(body.skeleton, bs)
        ho = (hand_offsets or {}).get(s) or default_marker_offsets(hands.skeleton, hs)
        bw, bf = wb[body.skeleton.index(bs.wrist)], wb[body.skeleton.index(bs.forearm)]
        hw, hf = wh[hands.skeleton.index(hs.wrist)], wh[hands.skeleton.index(hs.forearm)]
        bm = _given_markers(body_markers, s, body.num_frames, "body") if body_markers and s in body_markers \
            else markers_from_xforms(bw, bf, bo, body.skeleton)
        hm = _given_markers(hand_markers, s, hands.num_frames, "hand") if hand_markers and s in hand_markers \
            else markers_from_xforms(hw, hf, ho, hands.skeleton)
        bref = _ref(body, bs, wb)
        href = _ref(hands, hs, wh)
        yb = yh = None
        if options.yaw == "trunk":
            # a root counts as a trunk only on rigs with a shoulder (a hand-only rig's root is its forearm)
            yb = (_trunk_yaw(body, bs.root, wb) if bs.root and bs.shoulder else np.zeros(body.num_frames))
            yh = _trunk_yaw(hands, hs.root, wh) if hs.root and hs.shoulder else None
        al = align_hands(bm, hm, body.fps, body_ref=bref, hand_ref=href, constraints=constraints,
                         options=options, body_yaw_deg=yb, hand_yaw_deg=yh,
                         body_hand_dirs=hand_directions_from_xforms(bw, bf, bo),
                         hand_hand_dirs=hand_directions_from_xforms(hw, hf, ho),
                         frame_rotation=forearm_rest_basis(body.skeleton, bs, bo)
                         @ forearm_rest_basis(hands.skeleton, hs, ho).T, side=s)
        sides[s] = al
        ranges[s] = (_wrist_range_cm(bm, bref), _wrist_range_cm(hm, href))
        if progress is not None:
            progress(k + 1, len(order) + 1, s)
    timing = {s: s for s in order}
    if options.still_range_cm > 0 and len(order) == 2:
        still = {s: min(ranges[s]) < options.still_range_cm for s in order}
        for s, other in zip(order, order[::-1]):
            if still[s] and not still[other]:
                timing[s] = other
    for s in order:
        bs, hs = body_sides[s], hand_sides[s]
        al = sides[timing[s]]
        pairs, bu, hu = pair_finger_joints(bs, hs)
        mode = options.transfer
        if mode == "auto":
            mode = choose_transfer(body.skeleton, hands.skeleton, pairs, options.auto_transfer_deg) if pairs else "local"
        axes = transfer_axes(body.skeleton, bs, hands.skeleton, hs, pairs) if mode == "hand" and pairs else None
        modes[s] = mode
        tr = transfer_fingers(body, hands, pairs, al.alignment, blend_window=options.blend_window,
                              jump_frames=options.jump_frames, mode=mode, axes=axes)
        if tr.joints:  # both hands' fingers written into one copy of the rotations
            if rot is None:
                rot = np.array(body.rotations)
            rot[:, tr.joints] = tr.rotations
        transfers[s], pairs_all[s], bun[s], hun[s] = tr, pairs, bu, hu
        _log.info("%s hand: timing from the %s hand, %d finger joint pair(s), transfer %r, %d body / %d hand "
                  "finger joint(s) unpaired", s, timing[s], len(pairs), mode, len(bu), len(hu))
    sides = {s: sides[timing[s]] for s in order}
    if progress is not None:
        progress(len(order) + 1, len(order) + 1, "fingers")
    out = body if rot is None else body.replace(rotations=rot)
    return SpliceResult(out, sides, transfers, pairs_all, bun, hun, modes, timing, ranges)


def _wrist_range_cm(markers: np.ndarray, ref: np.ndarray | None) -> float:
    """Largest range over the axes of the wrist markers' midpoint, relative to ``ref`` (cm)."""
    w = 0.5 * (markers[:, 0] + markers[:, 1])
    if ref is not None:
        w = w - ref
    return float(np.ptp(w, axis=0).max())


def _given_markers(markers: dict, side: str, frames: int, what: str) -> np.ndarray:
    m = np.asarray(markers[side], dtype=np.float64)
    if m.shape != (frames, 4, 3):
        raise ValueError(f"Expected {what} markers of the {side} hand of shape ({frames}, 4, 3), got {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError(f"Expected finite {what} markers of the {side} hand, got NaN or infinite values")
    return m


def _side_joints(skeleton, side: HandSide) -> list[int]:
    names = [side.wrist, side.forearm, side.shoulder, side.root]
    return [skeleton.index(n) for n in names if n is not None]


def _ref(clip: Clip, side: HandSide, world: dict) -> np.ndarray | None:
    """The shoulder's position at every frame, ``(T, 3)`` (cm, Y up), or None for a rig
    without a shoulder (still trunk). ``world``: :func:`chain_xforms` of the clip.
    """
    if side.shoulder is None:
        return None
    return _to_yup_cm(world[clip.skeleton.index(side.shoulder)][:, :3, 3], clip.skeleton)


def _trunk_yaw(clip: Clip, root: str, world: dict) -> np.ndarray:
    """:func:`trunk_yaw_deg` of the joint ``root`` from :func:`chain_xforms` of the clip."""
    j = clip.skeleton.index(root)
    return trunk_yaw_from_xforms(world[j], clip.skeleton, j)

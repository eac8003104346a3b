"""Inverse kinematics on a finger chain: the largest curl that stays clear of the colliders.

A chain's pose is opened along one path, ``u`` from 0 (the pose given) to 1 (every
joint at its rest angles, within limits). The path opens the distal joint first and
the proximal last, in overlapping ramps, so a touching finger tip straightens the last
joint before the knuckle moves (the order cyclic coordinate descent visits joints, end
effector first, changing as little of the chain as it can). Every angle stays inside
the joint's limits. Bisection on ``u`` per frame, all frames at once, finds the least
opening whose capsules pass :func:`~usdhands.algorithms.interaction.clearance.axis_clearance`:
the bound the smoother must stay above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usdhands.algorithms.interaction.clearance import axis_clearance
from usdhands.algorithms.interaction.finger_geometry import FingerChain
from usdhands.algorithms.interaction.known_distances import ChainDistances, joint_cutoffs
from usdhands.model.rotations import DEFAULT_EULER_ORDER, euler_deg_to_quat, quat_multiply, trs_to_xform

__all__ = ["ChainPoser", "ChainGroup", "group_stride", "opening_weights", "clear_together", "least_openings",
           "JointsSeen"]


def opening_weights(u: np.ndarray, n: int) -> np.ndarray:
    """How far each joint is opened, ``(K, n)`` in [0, 1], for path parameters ``u`` ``(K,)``.

    Joint ``k`` (0 proximal) ramps over ``[(n-1-k)/(n+1), (n+1-k)/(n+1)]``: the distal
    joint first, neighbours overlapping; all 0 at ``u = 0``, all 1 at ``u = 1``.
    """
    u = np.asarray(u, dtype=np.float64)[:, None]
    k = np.arange(n)[None, :]
    return np.clip((u * (n + 1) - (n - 1 - k)) / 2.0, 0.0, 1.0)


@dataclass(eq=False)
class ChainPoser:
    """Poses and capsules of one finger chain along its opening path, for a clip.

    Parameters
    ----------
    chain : FingerChain
    parent_world : (T, 4, 4) float
        World transform of the chain's parent joint per frame (never changed).
    translations, scales : (T, n, 3) float
        The chain joints' local translations and scales per frame.
    rest_rotations : (n, 4) float
        The chain joints' rest rotations, xyzw.
    order : str
        Euler order of the curves.
    given_points : (T, n + 1, 3) float, optional
        The chain's joint positions and tip in the pose given, world (from the clip's
        forward kinematics), for the broad phase.
    between : (T, n, 4, 4) float, optional
        Where a chain joint's parent is not the joint before it but a joint below that one
        (a roll or twist joint in between, never changed): the transform from the joint before
        to the parent, per frame (identity elsewhere).
    """

    chain: FingerChain
    parent_world: np.ndarray
    translations: np.ndarray
    scales: np.ndarray
    rest_rotations: np.ndarray
    order: str = DEFAULT_EULER_ORDER
    given_points: np.ndarray | None = None
    between: np.ndarray | None = None

    def angles(self, base: np.ndarray, u: np.ndarray, via: np.ndarray | None = None,
               frames: np.ndarray | None = None) -> np.ndarray:
        """Euler angles ``(K, n, 3)`` degrees at path parameters ``u`` ``(K,)`` from ``base`` ``(K, n, 3)``.

        Without ``via`` the path opens ``base`` toward the rest pose (:func:`opening_weights`).
        With ``via`` ``(K, n, 3)`` (an IK pose within the limits, :meth:`ccd`) the first half
        of the path goes straight from ``base`` to ``via`` and the second half opens ``via``.
        ``u == 0`` returns ``base`` itself (not clamped); otherwise the path is clamped into the limits.
        ``frames``: the rows' frames (unused here; :class:`ChainGroup` finds each row's chain by it).
        """
        base = np.asarray(base, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64)
        lo, hi = self.chain.limits[..., 0], self.chain.limits[..., 1]
        start = np.clip(base, lo, hi)
        if via is not None:
            via = np.clip(np.asarray(via, dtype=np.float64), lo, hi)
            first = np.clip(2.0 * u, 0.0, 1.0)[:, None, None]
            near = start + first * (via - start)
            far = self._open(via, np.clip(2.0 * u - 1.0, 0.0, 1.0))
            out = np.where((u <= 0.5)[:, None, None], near, far)
        else:
            out = self._open(start, u)
        same = u <= 0
        out[same] = base[same]
        return out

    def _open(self, start: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``start`` (within the limits) opened toward the rest pose by ``u``, distal joints first."""
        lo, hi = self.chain.limits[..., 0], self.chain.limits[..., 1]
        target = np.clip(np.zeros_like(start[:1]), lo, hi)
        w = opening_weights(u, start.shape[1])[..., None]
        return np.clip(start + w * (target - start), lo, hi)

    def ccd(self, colliders, frames: np.ndarray, base: np.ndarray, margin: float, resolution: float,
            passes: int = 2, iterations: int = 7,
            known: ChainDistances | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Cyclic coordinate descent: each joint, tip to root, turned about its flexion axis
        toward extension by the least angle (bisection to ``2**-iterations`` of the way to its
        limit) that brings its segment and the ones after it clear of the colliders; a joint
        that cannot clear them even at its limit is left for the joints before it; ``passes``
        sweeps.

        Parameters
        ----------
        frames : (K,) int
        base : (K, n, 3) float
            Poses within the limits, Euler degrees.
        known : ChainDistances, optional
            :meth:`clear`, one row per frame.

        Returns
        -------
        pose : (K, n, 3) float
            Within the limits; only flexion angles differ from ``base``.
        clear : (K,) bool
            Whether ``pose`` passed the clearance test.
        """
        frames = np.asarray(frames, dtype=np.int64)
        pose = np.array(base, dtype=np.float64)
        n = pose.shape[1]
        todo = np.nonzero(~self.clear(colliders, frames, pose, margin, resolution, known=known))[0]
        for _ in range(passes):
            if len(todo) == 0:
                break
            for k in range(n - 1, -1, -1):
                work = todo[~self.clear(colliders, frames[todo], pose[todo], margin, resolution, first=k,
                                        known=known)]
                if len(work) == 0:
                    continue
                ax = int(self.chain.axes[k, 0])
                limit = self.chain.limits[k, ax, 0 if self.chain.flexion_sign[k] > 0 else 1]
                start = pose[work, k, ax].copy()

                def turned(sel, t, work=work, start=start, k=k, ax=ax, limit=limit):
                    p = pose[work[sel]].copy()
                    p[:, k, ax] = start[sel] + t * (limit - start[sel])
                    return p

                sel = np.arange(len(work))
                sel = sel[self.clear(colliders, frames[work], turned(sel, 1.0), margin, resolution, first=k,
                                     known=known)]
                if len(sel) == 0:
                    continue
                lo_t, hi_t = np.zeros(len(sel)), np.ones(len(sel))
                for _ in range(iterations):
                    mid = 0.5 * (lo_t + hi_t)
                    ok = self.clear(colliders, frames[work[sel]], turned(sel, mid), margin, resolution,
                                    first=k, known=known)
                    hi_t = np.where(ok, mid, hi_t)
                    lo_t = np.where(ok, lo_t, mid)
                pose[work[sel]] = turned(sel, hi_t)
            todo = todo[~self.clear(colliders, frames[todo], pose[todo], margin, resolution, known=known)]
        done = np.ones(len(frames), dtype=bool)
        done[todo] = False
        return pose, done

    def local_rotations(self, angles: np.ndarray) -> np.ndarray:
        """Local rotations ``(K, n, 4)`` xyzw from Euler angles relative to rest ``(K, n, 3)``."""
        rel = euler_deg_to_quat(angles, self.order)
        return quat_multiply(self.rest_rotations[None], rel)

    def capsules(self, frames: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segment end points ``a, b`` ``(K, n, 3)``, world, clip units."""
        frames = np.asarray(frames, dtype=np.int64)
        q = self.local_rotations(angles)
        local = trs_to_xform(self.translations[frames], q, self.scales[frames])
        n = q.shape[1]
        world = self.parent_world[frames]
        pts = np.empty((len(frames), n + 1, 3))
        for k in range(n):
            if self.between is not None and k > 0:
                world = world @ self.between[frames, k]
            world = world @ local[:, k]
            pts[:, k] = world[:, :3, 3]
        pts[:, n] = world[:, :3, :3] @ self.chain.tip_offset + world[:, :3, 3]
        return pts[:, :-1], pts[:, 1:]

    def clear(self, colliders, frames: np.ndarray, angles: np.ndarray, margin: float,
              resolution: float, first: int = 0, known: ChainDistances | None = None,
              rows: np.ndarray | None = None) -> np.ndarray:
        """Whether every capsule of the chain (from segment ``first`` on) clears the colliders by
        ``margin`` (up to ``resolution / 2``), ``(K,)`` bool.

        ``known``: what was measured on this chain before (rows ``rows``, default ``frames``), reused
        and added to; the answer is the same with it or without.
        """
        frames = np.asarray(frames, dtype=np.int64)
        K = len(frames)
        if K == 0:
            return np.zeros(0, dtype=bool)
        a, b = self.capsules(frames, angles)
        a, b = a[:, first:], b[:, first:]
        need = np.tile(self.chain.radii[first:] + margin, (K, 1))
        if known is None:
            return _capsules_clear(colliders, [(frames, a, b, need)], resolution)[0]
        lower, upper = known.axis_bounds(colliders, frames if rows is None else rows, frames, a, b, need,
                                         resolution, first)
        ok = (lower >= need - 0.5 * resolution) & (upper >= need)
        return ok.all(axis=1)

    def least_opening(self, colliders, frames: np.ndarray, base: np.ndarray, margin: float, resolution: float,
                      iterations: int = 9, via: np.ndarray | None = None, known: ChainDistances | None = None,
                      rows: np.ndarray | None = None, every: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """The least path parameter clear of the colliders at each frame, by bisection.

        Parameters
        ----------
        frames : (K,) int
        base : (K, n, 3) float
            The poses to open, Euler degrees.
        via : (K, n, 3) float, optional
            IK poses the path passes through (:meth:`angles`).
        known, rows : optional
            What was measured on the chain and the memo row of each frame (:meth:`clear`).
        every : int
            1: every frame bisected. ``k > 1`` (``frames`` distinct clip frames): only frames whose
            number is a multiple of ``k`` are bisected, and frames with no such failing frame within
            ``k - 1``; each other failing frame is tried at the largest bound found within ``k - 1``
            frames of it and bisected above that only where it is not clear (neighbouring frames'
            bounds differ little, and the smoother holds the opening near the bound's running maximum
            anyway: :data:`~usdhands.algorithms.interaction.correction.HOLD_OF_TIME_SCALE`).

        Returns
        -------
        u : (K,) float
            0 where ``base`` is clear; otherwise a ``u`` tested clear: the smallest found (within
            ``2**-iterations``), or with ``every > 1`` a neighbour's where that is clear; 1 where even
            the open pose is not clear.
        resolved : (K,) bool
            False where even the fully open pose touches (the palm or wrist is inside a prop).
        """
        frames = np.asarray(frames, dtype=np.int64)
        rows = frames if rows is None else np.asarray(rows, dtype=np.int64)
        K = len(frames)
        u = np.zeros(K)
        resolved = np.ones(K, dtype=bool)
        bad = ~self.clear(colliders, frames, base, margin, resolution, known=known, rows=rows)
        if not bad.any():
            return u, resolved
        idx = np.nonzero(bad)[0]
        ones = np.ones(len(idx))
        v = None if via is None else via[idx]
        open_ok = self.clear(colliders, frames[idx], self.angles(base[idx], ones, v, frames[idx]), margin, resolution,
                             known=known, rows=rows[idx])
        u[idx] = 1.0
        resolved[idx[~open_ok]] = False
        idx = idx[open_ok]
        if every > 1 and len(idx) > 1:
            # full bisections on every `every`-th frame of the clip (and on any frame with none of
            # those within reach), then the frames between them tried at the largest bound of
            # those within `every - 1` frames, and bisected above it (to the same 2**-iterations)
            # only where that is not clear
            f = frames[idx]
            anchor = f % every == 0
            af = np.sort(f[anchor])
            reach = np.searchsorted(af, f + every - 1, side="right") - np.searchsorted(af, f - every + 1)
            anchor |= reach == 0
            a_idx, b_idx = idx[anchor], idx[~anchor]
            u[a_idx] = self._bisect(colliders, frames, base, a_idx, np.zeros(len(a_idx)), iterations, margin,
                                    resolution, via, known, rows)
            if len(b_idx):
                af, au = frames[a_idx], u[a_idx]
                order = np.argsort(af, kind="stable")
                af, au = af[order], au[order]
                fb = frames[b_idx]
                lo_i = np.searchsorted(af, fb - every + 1)
                hi_i = np.searchsorted(af, fb + every - 1, side="right")
                cand = np.array([au[i:j].max() for i, j in zip(lo_i, hi_i)])
                v = None if via is None else via[b_idx]
                ok = self.clear(colliders, frames[b_idx], self.angles(base[b_idx], cand, v, frames[b_idx]), margin, resolution,
                                known=known, rows=rows[b_idx])
                u[b_idx[ok]] = cand[ok]
                rest = b_idx[~ok]
                u[rest] = self._bisect(colliders, frames, base, rest, cand[~ok], iterations, margin, resolution,
                                       via, known, rows)
            return u, resolved
        u[idx] = self._bisect(colliders, frames, base, idx, np.zeros(len(idx)), iterations, margin, resolution, via,
                              known, rows)
        return u, resolved

    def _bisect(self, colliders, frames, base, idx, lo, iterations, margin, resolution, via, known, rows):
        """Bisection between ``lo`` (not clear) and 1 (clear) for the frames ``idx``, to ``2**-iterations``
        of the path: the least parameter found clear, ``(len(idx),)``."""
        v = None if via is None else via[idx]
        lo = np.array(lo, dtype=np.float64)
        hi = np.ones(len(idx))
        step = 2.0 ** -iterations
        for _ in range(iterations):
            live = np.nonzero(hi - lo > step)[0]  # a frame started above 0 may be done sooner
            if len(live) == 0:
                break
            mid = 0.5 * (lo[live] + hi[live])
            ok = self.clear(colliders, frames[idx[live]], self.angles(base[idx[live]], mid,
                                                                      None if v is None else v[live], frames[idx[live]]),
                            margin, resolution, known=known, rows=rows[idx[live]])
            hi[live] = np.where(ok, mid, hi[live])
            lo[live] = np.where(ok, lo[live], mid)
        return hi

    def clear_below(self, colliders, frames: np.ndarray, base: np.ndarray, clear_u: np.ndarray,
                    blocked_u: np.ndarray, margin: float, resolution: float, iterations: int = 6,
                    via: np.ndarray | None = None, known: ChainDistances | None = None) -> np.ndarray:
        """A clear path parameter between ``clear_u`` (clear) and ``blocked_u`` (not), as near ``blocked_u``
        as ``iterations`` bisection steps find, ``(K,)`` (clear by the test; ``clear_u`` at worst); ``known``:
        :meth:`clear`, one row per frame."""
        lo = np.array(clear_u, dtype=np.float64)
        hi = np.array(blocked_u, dtype=np.float64)
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            ok = self.clear(colliders, frames, self.angles(base, mid, via, frames), margin, resolution, known=known)
            lo = np.where(ok, mid, lo)
            hi = np.where(ok, hi, mid)
        return lo


class ChainGroup:
    """Several finger chains with the same number of joints as one :class:`ChainPoser` over virtual frames:
    chain ``c`` at clip frame ``f`` is frame ``c * stride + f``, so one bisection, one clearance test
    and one query a step serve them all (:meth:`ChainPoser.least_opening`, :meth:`ChainPoser.clear_below`
    run on it as on one chain). Each row is posed by its own chain and searched alone, so every answer
    is the one its chain gives alone, bit for bit.

    Parameters
    ----------
    posers : list of ChainPoser
        Chains of ``n`` joints each, in the same Euler order.
    stride : int
        At least the clip's frame count plus ``every - 1`` and a multiple of ``every`` (the bisection's
        anchors are frames whose number is a multiple of ``every``, its neighbours within ``every - 1``:
        :func:`group_stride`).
    """

    least_opening = ChainPoser.least_opening
    _bisect = ChainPoser._bisect
    clear_below = ChainPoser.clear_below

    def __init__(self, posers: list, stride: int):
        self.posers = list(posers)
        self.stride = int(stride)

    def frames_of(self, c: int, frames: np.ndarray) -> np.ndarray:
        """The virtual frames of chain ``c`` at clip ``frames``."""
        return c * self.stride + np.asarray(frames, dtype=np.int64)

    def _split(self, frames: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """``(chain, rows, clip frames)`` of each chain among the virtual ``frames``."""
        frames = np.asarray(frames, dtype=np.int64)
        chain = frames // self.stride
        out = []
        for c in np.unique(chain):
            rows = np.nonzero(chain == c)[0]
            out.append((int(c), rows, frames[rows] - c * self.stride))
        return out

    def angles(self, base: np.ndarray, u: np.ndarray, via: np.ndarray | None = None,
               frames: np.ndarray | None = None) -> np.ndarray:
        """:meth:`ChainPoser.angles`, each row by its chain (``frames``: the rows' virtual frames)."""
        base = np.asarray(base, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64)
        out = np.empty(base.shape)
        for c, rows, _ in self._split(frames):
            out[rows] = self.posers[c].angles(base[rows], u[rows], None if via is None else via[rows])
        return out

    def clear(self, colliders, frames: np.ndarray, angles: np.ndarray, margin: float, resolution: float,
              first: int = 0, known: ChainDistances | None = None, rows: np.ndarray | None = None) -> np.ndarray:
        """:meth:`ChainPoser.clear` of each row by its chain, all in one test (``frames``: virtual; ``known``:
        one memo row per virtual frame)."""
        frames = np.asarray(frames, dtype=np.int64)
        K = len(frames)
        if K == 0:
            return np.zeros(0, dtype=bool)
        n = len(self.posers[0].chain.joints)
        a, b = np.empty((K, n, 3)), np.empty((K, n, 3))
        need = np.empty((K, n))
        real = np.empty(K, dtype=np.int64)
        for c, idx, f in self._split(frames):
            poser = self.posers[c]
            a[idx], b[idx] = poser.capsules(f, angles[idx])
            need[idx] = poser.chain.radii + margin
            real[idx] = f
        a, b, need = a[:, first:], b[:, first:], need[:, first:]
        if known is None:
            return _capsules_clear(colliders, [(real, a, b, need)], resolution)[0]
        lower, upper = known.axis_bounds(colliders, frames if rows is None else rows, real, a, b, need,
                                         resolution, first)
        return ((lower >= need - 0.5 * resolution) & (upper >= need)).all(axis=1)


def group_stride(num_frames: int, every: int) -> int:
    """A :class:`ChainGroup` stride for a clip of ``num_frames`` bisected on every ``every``-th frame."""
    every = max(int(every), 1)
    return -(-(num_frames + every) // every) * every


def clear_together(posers: list, colliders, frames: list, angles: list, margin: float,
                   resolution: float, joints_seen: list | None = None) -> list:
    """:meth:`ChainPoser.clear` of several chains at once (each with its own frames and poses), with one
    collider query for all their joints and one clearance search for all their capsules.

    Each capsule's search is its own (its intervals, its queries), so every answer is the one
    :meth:`ChainPoser.clear` gives the chain alone, bit for bit; only the calls are fewer.

    ``joints_seen``: per chain, a :class:`JointsSeen` of its frames' rows (``frames[i]`` at the rows
    ``rows``), or None: a joint met again at the very position measured before takes that value.

    Returns
    -------
    list of (K_i,) bool
    """
    parts = []
    for i, (poser, f, ang) in enumerate(zip(posers, frames, angles)):
        f = np.asarray(f, dtype=np.int64)
        if len(f) == 0:
            parts.append(None)
            continue
        a, b = poser.capsules(f, ang)
        seen = None if joints_seen is None else joints_seen[i]
        parts.append((f, a, b, np.tile(poser.chain.radii + margin, (len(f), 1)), seen))
    return _capsules_clear(colliders, parts, resolution)


class JointsSeen:
    """The distances last measured at a chain's joints (tip counted), for rows of poses tested again and
    again at the same frames (a bisection): a joint found at the very position it had, with a value that
    was exact (below its cutoff then) or is beyond its cutoff now, takes it instead of a query, as
    :class:`~usdhands.algorithms.interaction.known_distances.ChainDistances` does (a value beyond the
    cutoff, whichever lower bound it is, only closes the capsules it ends at their first level: the
    same answers). The joints the opening path has not turned yet keep their positions.

    Parameters
    ----------
    rows : int
    joints : int
        The chain's joints plus its tip.
    """

    def __init__(self, rows: int, joints: int):
        self.position = np.full((rows, joints, 3), np.nan)
        self.value = np.zeros((rows, joints))
        self.cutoff = np.full((rows, joints), -np.inf)
        self.rows = np.arange(rows)  # the rows of the poses of the next test (set by the caller)

    def known(self, joints: np.ndarray, cut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For the joints ``(K, m, 3)`` of the poses at :attr:`rows` and their cutoffs ``(K, m)``: which
        have a value ``(K, m)`` bool, and the values ``(K, m)``."""
        old_v, old_c = self.value[self.rows], self.cutoff[self.rows]
        same = np.all(self.position[self.rows] == joints, axis=2) & ((old_v < old_c) | (old_v >= cut))
        return same, old_v

    def remember(self, joints: np.ndarray, cut: np.ndarray, values: np.ndarray, measured: np.ndarray) -> None:
        """Keep the ``measured`` ``(K, m)`` joints' positions, cutoffs and values."""
        kk, jj = np.nonzero(measured)
        r = self.rows[kk]
        self.position[r, jj] = joints[kk, jj]
        self.cutoff[r, jj] = cut[kk, jj]
        self.value[r, jj] = values[kk, jj]


def _share_base(frames: np.ndarray, joints: np.ndarray, cut: np.ndarray, have: np.ndarray):
    """Rows of several poses at one frame whose base joint (the same point: the chain's first joint does
    not move with the chain's angles) is not known: ``(rows, their representative row)`` for all but the
    first row at each frame with that very position, None if there are none; the representative's cutoff
    ``cut[:, 0]`` is raised to the largest of its group (in place), so its value is exact below every
    row's cutoff and a lower bound beyond them all."""
    k = np.nonzero(~have[:, 0])[0]
    if len(k) < 2:
        return None
    _, first, inv = np.unique(frames[k], return_index=True, return_inverse=True)
    rep = k[first][inv]
    same = np.all(joints[k, 0] == joints[rep, 0], axis=1) & (rep != k)
    if not same.any():
        return None
    top = cut[k[first], 0].copy()
    np.maximum.at(top, inv[same], cut[k[same], 0])
    cut[k[first], 0] = top
    cut[k[same], 0] = top[inv[same]]  # remembered under the cutoff the value was measured with
    return k[same], rep[same]


def _capsules_clear(colliders, parts: list, resolution: float) -> list:
    """Whether each frame's capsules clear the colliders by their ``need`` (up to ``resolution / 2``),
    for several sets at once: ``parts`` holds ``(frames (K,), a (K, n, 3), b (K, n, 3), need (K, n)[, seen])``
    or None (no frames); one collider query for all their joints (each joint, the end of one segment
    and the start of the next, measured once; with a :class:`JointsSeen` ``seen``, only those not met
    before at the same position) and one clearance search for all their capsules.

    Returns
    -------
    list of (K_i,) bool
    """
    live = []
    for q in parts:
        if q is not None:
            f, a, b, need = q[:4]
            n = a.shape[1]
            joints = np.concatenate([a, b[:, -1:]], axis=1)  # (K, n + 1, 3)
            cut = joint_cutoffs(need, np.linalg.norm(b - a, axis=2))
            seen = q[4] if len(q) > 4 else None
            share = None
            if seen is None:
                have, values = np.zeros(cut.shape, dtype=bool), np.zeros(cut.shape)
            else:
                have, values = seen.known(joints, cut)
                share = _share_base(f, joints, cut, have)
            live.append((f, a, b, n, need, joints, cut, have, values, seen, share))
    if not live:
        return [np.zeros(0, dtype=bool) for _ in parts]
    ask = [~x[7] for x in live]
    for x, m in zip(live, ask):
        if x[10] is not None:
            m[x[10][0], 0] = False  # the base joint measured once per frame
    d_all = colliders.signed_distance(
        np.concatenate([np.broadcast_to(x[0][:, None], x[7].shape)[m] for x, m in zip(live, ask)]),
        np.concatenate([x[5][m] for x, m in zip(live, ask)]),
        np.concatenate([x[6][m] for x, m in zip(live, ask)]))
    d_split = np.split(d_all, np.cumsum([int(m.sum()) for m in ask])[:-1])
    ends0, ends1, fr, aa, bb, nn = [], [], [], [], [], []
    for (f, a, b, n, need, joints, cut, have, values, seen, share), m, d_new in zip(live, ask, d_split):
        d = np.array(values)
        d[m] = d_new
        if share is not None:
            rows, rep = share
            d[rows, 0] = d[rep, 0]
            m[rows, 0] = True  # remembered as measured, with the cutoff it was measured under
        if seen is not None:
            seen.remember(joints, cut, d, m)
        ends0.append(d[:, :-1].reshape(-1))
        ends1.append(d[:, 1:].reshape(-1))
        fr.append(np.repeat(f, n))
        aa.append(a.reshape(-1, 3))
        bb.append(b.reshape(-1, 3))
        nn.append(need.reshape(-1))
    lower, upper = axis_clearance(colliders, np.concatenate(fr), np.concatenate(aa), np.concatenate(bb),
                                  np.concatenate(nn), resolution,
                                  end_distances=(np.concatenate(ends0), np.concatenate(ends1)))
    out, at = [], 0
    for q in parts:
        if q is None:
            out.append(np.zeros(0, dtype=bool))
            continue
        f, a, _, need = q[:4]
        n = a.shape[1]
        k = len(f) * n
        lo, up = lower[at:at + k].reshape(len(f), n), upper[at:at + k].reshape(len(f), n)
        at += k
        out.append(((lo >= need - 0.5 * resolution) & (up >= need)).all(axis=1))
    return out


def least_openings(posers: list, colliders, frames: list, bases: list, margin: float, resolution: float,
                   iterations: int = 9) -> list:
    """:meth:`ChainPoser.least_opening` (no IK pose to pass through, nothing remembered) of several chains
    at once, their bisections in step (:func:`clear_together`): the same answers, bit for bit. A joint
    the path has not moved yet (the chain's base always, the next ones while only the joints after them
    turn) is measured once per pose (:class:`JointsSeen`).

    Returns
    -------
    list of (u (K_i,), resolved (K_i,))
    """
    frames = [np.asarray(f, dtype=np.int64) for f in frames]
    u = [np.zeros(len(f)) for f in frames]
    resolved = [np.ones(len(f), dtype=bool) for f in frames]
    seen = [JointsSeen(len(f), len(p.chain.joints) + 1) for p, f in zip(posers, frames)]
    bad = [~ok for ok in clear_together(posers, colliders, frames, bases, margin, resolution, seen)]
    idx = [np.nonzero(b)[0] for b in bad]
    for s, i in zip(seen, idx):
        s.rows = i
    open_ok = clear_together(posers, colliders, [f[i] for f, i in zip(frames, idx)],
                             [p.angles(b[i], np.ones(len(i))) for p, b, i in zip(posers, bases, idx)],
                             margin, resolution, seen)
    for c in range(len(posers)):
        u[c][idx[c]] = 1.0
        resolved[c][idx[c][~open_ok[c]]] = False
        idx[c] = idx[c][open_ok[c]]
        seen[c].rows = idx[c]
    lo = [np.zeros(len(i)) for i in idx]
    hi = [np.ones(len(i)) for i in idx]
    if any(len(i) for i in idx):
        for _ in range(iterations):
            mid = [0.5 * (a + b) for a, b in zip(lo, hi)]
            ok = clear_together(posers, colliders, [f[i] for f, i in zip(frames, idx)],
                                [p.angles(b[i], m) for p, b, i, m in zip(posers, bases, idx, mid)], margin, resolution,
                                seen)
            hi = [np.where(o, m, h) for o, m, h in zip(ok, mid, hi)]
            lo = [np.where(o, low, m) for o, m, low in zip(ok, mid, lo)]
    for c in range(len(posers)):
        u[c][idx[c]] = hi[c]
    return list(zip(u, resolved))

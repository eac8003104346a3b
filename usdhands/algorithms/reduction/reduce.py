"""Finger DOF reduction by range and RMS deviation (Jörg and O'Sullivan 2009, §4-§5).

Input: finger DOF curves ``(T, D)`` in degrees (Euler angles relative to rest, see
:mod:`usdhands.model.finger_dofs`) and their names. Output: for each simplification
step, a :class:`~usdhands.algorithms.reduction.model.ReductionModel` that rebuilds all
``D`` curves from the few that are left, with the number of DOFs left and the
reconstruction error.

The rules (paper §4):

1. **Range** (irrelevance): a curve whose range ``max - min`` is below the threshold
   becomes its mean.
2. **rmsd1** (positive relation): each curve is standardised,
   ``z = (a - mean(a)) / std(a)`` with the population standard deviation (divide by
   ``n``, so that ``z`` has mean 0 and standard deviation 1 exactly, as the paper says),
   and ``rmsd1(a, b) = sqrt(mean((z_a - z_b)^2))``.
3. **rmsd2** (negative relation): the same with the second curve "inverted", i.e.
   mirrored across the time axis (negated): ``rmsd2(a, b) = sqrt(mean((z_a + z_b)^2))``.

For standardised curves ``mean(z_a^2) = mean(z_b^2) = 1`` and ``mean(z_a z_b) = r``, the
Pearson correlation, so ``rmsd1^2 = 2 - 2r`` and ``rmsd2^2 = 2 + 2r``: every pair comes
from one correlation matrix ``Z^T Z / n`` (one matrix product instead of a loop over
pairs). Thresholds are thus correlation thresholds: ``rmsd < 0.3`` means
``|r| > 0.955``, ``rmsd < 0.5`` means ``|r| > 0.875``.

Below a threshold the curve ``a`` with the smaller standard deviation is rebuilt from the
curve ``b`` with the larger one, ``a = ±(b - mean(b)) / std(b) * std(a) + mean(a)``
(the paper's rule 3 prints "(mean(b) - b) = std(b)"; the "=" is a typo for "/", as its
§4.2 shows). Mean and standard deviation of ``a`` are preserved.

Chains (paper §5.2): when ``a``'s controller ``b`` is itself controlled by ``c``, ``a`` is
rebuilt from ``c`` (the composed map has the same form, the signs multiply), even if
``rmsd(a, c)`` exceeds the threshold. When ``a`` has several candidate controllers, the
one with the larger standard deviation wins. Standard deviations that are exactly equal
are ordered by column (the earlier curve controls), so the order is total and chains
always end.

Steps run in the order given and accumulate as in the paper's table 5: a range step
sets the range rule (replacing an earlier one) and starts afresh; an rmsd step adds
relations on top of the current range rule. So ``range<1, rmsd<0.3, range<5, rmsd<0.5``
gives the conditions ``range < 1``, ``range < 1 + rmsd < 0.3``, ``range < 5``,
``range < 5 + rmsd < 0.5`` — the paper's 39, 27, 31, 15 DOFs (31 > 27: its third step
drops the relations of the second). Ranges, statistics and distances are always those of
the original curves; curves made constant by the current range rule take no part in
relations.

Curves that never move (range below :data:`DEGENERATE_RANGE_DEG`) cannot be
standardised: they take part in no relation, and they stay free until a range rule
makes them constants.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from usdhands.algorithms.reduction.model import Constant, ReductionModel, Relation
from usdhands.errors import ConfigError
from usdhands.model.finger_dofs import apply_finger_curves, finger_curves
from usdhands.model.handmap import FINGERS, HandMap
from usdhands.model.skeleton import short_joint_name

__all__ = [
    "DEFAULT_STEPS", "DEGENERATE_RANGE_DEG", "RangeRule", "RmsdRule", "parse_steps", "format_steps",
    "curve_statistics", "standardise", "align_euler_branches", "pair_rmsd", "StepResult", "ReductionResult", "reduce_curves",
    "paper_style_names", "continuous_euler_curves", "model_curves", "expand_clip", "curve_names", "curve_joint_name",
]

DEFAULT_STEPS = "range<1,rmsd<0.3,range<5,rmsd<0.5"
"""The paper's four steps (§5)."""

DEGENERATE_RANGE_DEG = 1e-9
"""Degrees: a curve with a smaller range never moves and is not standardised."""


@dataclass(frozen=True)
class RangeRule:
    """Curves with ``range < threshold`` (degrees) become their mean."""

    threshold: float

    def __str__(self) -> str:
        return f"range < {self.threshold:g}"


@dataclass(frozen=True)
class RmsdRule:
    """Pairs with ``rmsd < threshold`` (of the given kinds) are related."""

    threshold: float
    kinds: tuple[str, ...] = ("rmsd1", "rmsd2")

    def __str__(self) -> str:
        name = "rmsd" if len(self.kinds) == 2 else self.kinds[0]
        return f"{name} < {self.threshold:g}"


_STEP_RE = re.compile(r"^\s*(range|rmsd|rmsd1|rmsd2)\s*<\s*(\S+?)\s*$")


def parse_steps(text: str) -> tuple[RangeRule | RmsdRule, ...]:
    """Parse a comma-separated list of steps such as ``"range<1,rmsd<0.3,range<5,rmsd<0.5"``.

    Each step is ``range<N`` (degrees), ``rmsd<N`` (rmsd1 or rmsd2), ``rmsd1<N`` or
    ``rmsd2<N``, with ``N`` a positive finite number; spaces are allowed.

    Raises
    ------
    ConfigError
        ``bad step 'foo': expected range<N, rmsd<N, rmsd1<N or rmsd2<N with N a positive number``,
        or ``no steps given``.
    """
    items = [t for t in (s.strip() for s in str(text).split(","))]
    if not any(items):
        raise ConfigError("no steps given")
    rules: list[RangeRule | RmsdRule] = []
    for item in items:
        m = _STEP_RE.match(item)
        value = None
        if m:
            try:
                value = float(m.group(2))
            except ValueError:
                value = None
        if m is None or value is None or not math.isfinite(value) or value <= 0:
            raise ConfigError(f"bad step {item!r}: expected range<N, rmsd<N, rmsd1<N or rmsd2<N "
                              f"with N a positive number")
        kind = m.group(1)
        if kind == "range":
            rules.append(RangeRule(value))
        else:
            rules.append(RmsdRule(value, ("rmsd1", "rmsd2") if kind == "rmsd" else (kind,)))
    return tuple(rules)


def format_steps(rules) -> str:
    """Inverse of :func:`parse_steps` (``"range<1,rmsd<0.3"``)."""
    return ",".join(str(r).replace(" ", "") for r in rules)


# ---------------------------------------------------------------------------- statistics
def curve_statistics(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean, population standard deviation and range of each curve.

    Parameters
    ----------
    values : (T, D) float
        Degrees.

    Returns
    -------
    mean, std, range : (D,) float64
        Degrees.
    """
    v = _check_values(values)
    mean, vmin, vmax = _mean_min_max(v)
    return mean, np.sqrt(np.diag(_covariance(v, mean))), vmax - vmin


def standardise(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Standardised curves ``(v - mean) / std`` (population std).

    Parameters
    ----------
    values : (T, D) float
        Degrees.

    Returns
    -------
    z : (T, D) float64
        Mean 0 and standard deviation 1 per column; columns of curves that never move
        (range below :data:`DEGENERATE_RANGE_DEG`) are zero.
    valid : (D,) bool
        False for those curves.
    """
    v = _check_values(values)
    mean, centred, cov, rng = _moments(v)
    std = np.sqrt(np.diag(cov))
    valid = _valid(std, rng)
    centred /= np.where(valid, std, 1.0)
    centred[:, ~valid] = 0.0
    return centred, valid


def pair_rmsd(values: np.ndarray, groups=None) -> tuple[np.ndarray, np.ndarray]:
    """``rmsd1`` and ``rmsd2`` of every pair of standardised curves, from the correlation matrix.

    Parameters
    ----------
    values : (T, D) float
        Degrees.
    groups : (D,) sequence, optional
        A label per curve (the hand); pairs across labels are not compared.

    Returns
    -------
    rmsd1, rmsd2 : (D, D) float64
        Symmetric; NaN on the diagonal, across groups, and for curves that never move.
        ``rmsd1 = sqrt(2 - 2r)``, ``rmsd2 = sqrt(2 + 2r)`` with ``r`` the correlation.
    """
    v = _check_values(values)
    mean, vmin, vmax = _mean_min_max(v)
    return _rmsd_from_cov(_covariance(v, mean), vmax - vmin, _group_codes(groups, v.shape[1]))


def _moments(v: np.ndarray):
    """Mean (D,), centred curves (T, D), covariance ``C^T C / T`` (D, D), range (D,).

    One pass for the mean, one for the centring, one matrix product; the standard
    deviations are the square roots of the covariance's diagonal.
    """
    mean, vmin, vmax = _mean_min_max(v)
    centred = v - mean
    cov = (centred.T @ centred) / v.shape[0]
    return mean, centred, cov, vmax - vmin


def _mean_min_max(v: np.ndarray):
    mean = v.mean(axis=0)
    vmin, vmax = v.min(axis=0), v.max(axis=0)
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(vmax - vmin))):
        raise ValueError("Expected finite values, got NaN or infinity")
    return mean, vmin, vmax


_CHUNK_ROWS = 8192


def _covariance(v: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """``C^T C / T`` of the centred curves, centring a block of rows at a time (no (T, D) copy)."""
    T, D = v.shape
    cov = np.zeros((D, D))
    block = np.empty((min(T, _CHUNK_ROWS), D))
    for a in range(0, T, _CHUNK_ROWS):
        b = min(a + _CHUNK_ROWS, T)
        c = block[: b - a]
        np.subtract(v[a:b], mean, out=c)
        cov += c.T @ c
    return cov / T


def _valid(std: np.ndarray, rng: np.ndarray) -> np.ndarray:
    return (rng >= DEGENERATE_RANGE_DEG) & (std > 0)


def _rmsd_from_cov(cov: np.ndarray, rng: np.ndarray, codes: np.ndarray):
    std = np.sqrt(np.diag(cov))
    valid = _valid(std, rng)
    s = np.where(valid, std, 1.0)
    r = np.clip(cov / s[:, None] / s[None, :], -1.0, 1.0)
    r[~valid, :] = np.nan
    r[:, ~valid] = np.nan
    np.fill_diagonal(r, np.nan)
    r[codes[:, None] != codes[None, :]] = np.nan
    rmsd1 = np.sqrt(np.maximum(2.0 - 2.0 * r, 0.0))
    rmsd2 = np.sqrt(np.maximum(2.0 + 2.0 * r, 0.0))
    return rmsd1, rmsd2


# ---------------------------------------------------------------------------- results
@dataclass(frozen=True, eq=False)
class StepResult:
    """One simplification step.

    Parameters
    ----------
    rule : RangeRule or RmsdRule
        The step as given.
    condition : str
        The accumulated condition (``"range < 1 + rmsd < 0.3"``).
    model : ReductionModel
        Constants and relations in force after this step.
    dofs_left : int
        Curves neither constant nor dependent.
    dofs_left_by_group : dict
        The same per group label (hand).
    rms_error_deg, max_error_deg : float
        Degrees: RMS and maximum of ``rebuilt - original`` over all curves and frames.
    curve_rms_error_deg, curve_max_error_deg : (D,) float64
        Degrees: RMS and maximum error per curve.
    """

    rule: RangeRule | RmsdRule
    condition: str
    model: ReductionModel
    dofs_left: int
    dofs_left_by_group: dict
    rms_error_deg: float
    max_error_deg: float
    curve_rms_error_deg: np.ndarray
    curve_max_error_deg: np.ndarray

    @property
    def worst_curve(self) -> str | None:
        """The curve with the largest error (None when nothing is rebuilt with an error)."""
        k = int(np.argmax(self.curve_max_error_deg))
        return self.model.curves[k] if self.curve_max_error_deg[k] > 0 else None

    def to_dict(self) -> dict:
        """The step's line of the JSON report."""
        return {
            "condition": self.condition,
            "dofs_left": int(self.dofs_left),
            "rms_error_deg": float(self.rms_error_deg),
            "max_error_deg": float(self.max_error_deg),
            "dofs_left_by_hand": {str(k): int(v) for k, v in self.dofs_left_by_group.items()},
            "num_constants": len(self.model.constants),
            "num_relations": len(self.model.relations),
            "worst_curve": self.worst_curve,
        }


@dataclass(frozen=True, eq=False)
class ReductionResult:
    """All steps of a reduction and the statistics they were made from.

    Parameters
    ----------
    names : tuple of str, length D
        Curve names.
    groups : tuple, length D
        Group label (hand) per curve.
    mean, std, range : (D,) float64
        Degrees: statistics of the original curves.
    rmsd1, rmsd2 : (D, D) float64
        Pair distances (see :func:`pair_rmsd`).
    steps : tuple of StepResult
    """

    names: tuple[str, ...]
    groups: tuple
    mean: np.ndarray
    std: np.ndarray
    range: np.ndarray
    rmsd1: np.ndarray
    rmsd2: np.ndarray
    steps: tuple[StepResult, ...] = field(default_factory=tuple)

    @property
    def final(self) -> StepResult:
        """The last step."""
        return self.steps[-1]

    def pair_values(self, kind: str = "rmsd1") -> np.ndarray:
        """The distances of every compared pair once (upper triangle, NaN dropped), shape (P,)."""
        m = self.rmsd1 if kind == "rmsd1" else self.rmsd2
        iu = np.triu_indices(m.shape[0], 1)
        v = m[iu]
        return v[np.isfinite(v)]

    def to_dict(self, step: int = -1) -> dict:
        """The JSON report: ``steps`` (the original first), and ``relations`` and
        ``constants`` of step ``step`` (default the last)."""
        chosen = self.steps[step]
        groups = sorted({str(g) for g in self.groups})
        original = {"condition": "original", "dofs_left": len(self.names), "rms_error_deg": 0.0,
                    "max_error_deg": 0.0,
                    "dofs_left_by_hand": {g: sum(1 for x in self.groups if str(x) == g) for g in groups},
                    "num_constants": 0, "num_relations": 0, "worst_curve": None}
        return {
            "curves": len(self.names),
            "steps": [original] + [s.to_dict() for s in self.steps],
            "model_step": chosen.condition,
            "relations": [{"dependent": r.dependent, "controlling": r.controlling, "kind": r.kind,
                           "rmsd": float(r.rmsd)} for r in chosen.model.relations],
            "constants": [{"curve": c.curve, "value": float(c.value)} for c in chosen.model.constants],
        }


# ---------------------------------------------------------------------------- the method
def reduce_curves(values: np.ndarray, names, steps=DEFAULT_STEPS, *, groups=None, across_groups: bool = False,
                  order: str = "XYZ", source: str = "") -> ReductionResult:
    """Run the simplification steps on a set of curves.

    Parameters
    ----------
    values : (T, D) float
        Degrees; the finger DOF curves (``T >= 2``).
    names : sequence of str, length D
        Curve names (``"LeftHandIndex2.y"``).
    steps : str or sequence of RangeRule/RmsdRule
        Default the paper's ``"range<1,rmsd<0.3,range<5,rmsd<0.5"``.
    groups : (D,) sequence, optional
        A label per curve (``"left"``/``"right"``): relations only within a label
        (hands are independent). Default: one group.
    across_groups : bool
        Relate curves of different groups too (the paper pooled both hands); the groups
        then only label the DOF counts.
    order : str
        Euler order of the curves, recorded in the models.
    source : str
        Recorded in the models.

    Returns
    -------
    ReductionResult
    """
    v = _check_values(values)
    names = tuple(str(n) for n in names)
    D = v.shape[1]
    if len(names) != D:
        raise ValueError(f"Expected {D} names, got {len(names)}")
    if len(set(names)) != D:
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"Duplicate curve names {dup}")
    rules = parse_steps(steps) if isinstance(steps, str) else tuple(steps)
    if not rules:
        raise ValueError("Expected at least one step, got none")
    for r in rules:
        if not isinstance(r, (RangeRule, RmsdRule)):
            raise TypeError(f"Expected RangeRule or RmsdRule steps, got {r!r}")
    group_labels = tuple(groups) if groups is not None else ("all",) * D
    if len(group_labels) != D:
        raise ValueError(f"Expected {D} group labels, got {len(group_labels)}")
    codes = _group_codes(group_labels, D)

    mean, vmin, vmax = _mean_min_max(v)
    cov = _covariance(v, mean)
    rng = vmax - vmin
    std = np.sqrt(np.diag(cov))
    rmsd1, rmsd2 = _rmsd_from_cov(cov, rng, np.zeros(D, dtype=np.int64) if across_groups else codes)
    valid = _valid(std, rng)
    # total order: larger std ranks higher; equal std -> the earlier column ranks higher
    rank = np.empty(D, dtype=np.int64)
    rank[np.lexsort((-np.arange(D), std))] = np.arange(D)

    range_rule: RangeRule | None = None
    rmsd_thr: dict[str, float] = {}
    results = []
    metadata = {"groups": [str(g) for g in group_labels]} if groups is not None else {}
    max_cache: dict = {}
    for rule in rules:
        if isinstance(rule, RangeRule):
            range_rule, rmsd_thr = rule, {}
        else:
            for k in rule.kinds:
                rmsd_thr[k] = rule.threshold
        condition = _condition(range_rule, rmsd_thr)
        constant = np.zeros(D, dtype=bool) if range_rule is None else rng < range_rule.threshold
        active = valid & ~constant
        final, sign = _resolve_relations(rmsd1, rmsd2, rmsd_thr, active, rank)
        constants = tuple(Constant(names[k], float(mean[k]), float(rng[k])) for k in np.flatnonzero(constant))
        relations = []
        for i in np.flatnonzero(final >= 0):
            f = final[i]
            kind = "rmsd1" if sign[i] > 0 else "rmsd2"
            dist = rmsd1[i, f] if sign[i] > 0 else rmsd2[i, f]
            relations.append(Relation.from_statistics(names[i], names[f], kind, float(dist),
                                                      mean[i], std[i], mean[f], std[f]))
        model = ReductionModel(names, constants, tuple(relations), order=order, condition=condition,
                               source=source, metadata=metadata,
                               means={n: float(mean[k]) for k, n in enumerate(names)})
        free = ~constant & (final < 0)
        by_group = {g: int(np.sum(free[codes == c])) for c, g in _group_items(group_labels, codes)}
        rms, mx, per_curve, per_curve_max = _errors(v, constant, final, sign, mean, std, vmin, vmax,
                                                    rmsd1, rmsd2, model, max_cache)
        results.append(StepResult(rule, condition, model, int(free.sum()), by_group, rms, mx, per_curve,
                                  per_curve_max))
    return ReductionResult(names, group_labels, mean, std, rng, rmsd1, rmsd2, tuple(results))


def _resolve_relations(rmsd1, rmsd2, thr: dict, active: np.ndarray, rank: np.ndarray):
    """Final controller (-1: none) and sign (+1/-1) of each curve."""
    D = active.size
    final = np.full(D, -1, dtype=np.int64)
    sign = np.ones(D)
    if not thr or not active.any():
        return final, sign
    with np.errstate(invalid="ignore"):
        pass1 = rmsd1 < thr["rmsd1"] if "rmsd1" in thr else np.zeros((D, D), dtype=bool)
        pass2 = rmsd2 < thr["rmsd2"] if "rmsd2" in thr else np.zeros((D, D), dtype=bool)
    both = pass1 & pass2  # only possible for thresholds above sqrt(2): keep the closer
    neg = pass2 & ~(both & (rmsd1 <= rmsd2))
    cand = (pass1 | pass2) & active[:, None] & active[None, :] & (rank[None, :] > rank[:, None])
    has = cand.any(axis=1)
    score = np.where(cand, rank[None, :], -1)
    ctrl = np.where(has, score.argmax(axis=1), -1)
    direct_sign = np.ones(D)
    rows = np.flatnonzero(has)
    direct_sign[rows] = np.where(neg[rows, ctrl[rows]], -1.0, 1.0)
    final = ctrl.copy()
    sign = direct_sign.copy()
    # follow the chains; ranks strictly increase along a chain, so this ends in < D rounds
    for _ in range(D):
        nxt = np.where(final >= 0, ctrl[np.maximum(final, 0)], -1)
        moving = nxt >= 0
        if not moving.any():
            break
        sign[moving] *= direct_sign[final[moving]]
        final[moving] = nxt[moving]
    return final, sign


def _errors(v, constant, final, sign, mean, std, vmin, vmax, rmsd1, rmsd2, model: ReductionModel, max_cache: dict):
    """RMS and max over all entries, and RMS and max per curve, of ``rebuilt - v``.

    The RMS needs no pass over the data: a constant's error ``v - mean`` has RMS
    ``std``; a dependent curve's error ``±std_a z_c - std_a z_a`` has RMS
    ``std_a * rmsd(a, c)`` of its kind. Maxima of constants come from the curves' minima
    and maxima; those of relations from one pass per relation not seen in an earlier
    step (``max_cache``, keyed by dependent, controller and sign).
    """
    T, D = v.shape
    sq = np.zeros(D)
    cmax = np.zeros(D)
    k = np.flatnonzero(constant)
    sq[k] = std[k] ** 2
    cmax[k] = np.maximum(vmax[k] - mean[k], mean[k] - vmin[k])
    dep = np.flatnonzero(final >= 0)
    if dep.size:
        ctrl = final[dep]
        dist = np.where(sign[dep] > 0, rmsd1[dep, ctrl], rmsd2[dep, ctrl])
        sq[dep] = (std[dep] * dist) ** 2
        keys = [(int(i), int(f), float(sg)) for i, f, sg in zip(dep, ctrl, sign[dep])]
        todo = [n for n, key in enumerate(keys) if key not in max_cache]
        if todo:
            by_dep = {r.dependent: r for r in model.relations}
            rel = [by_dep[model.curves[keys[n][0]]] for n in todo]
            scale = np.array([r.scale for r in rel])
            offset = np.array([r.offset for r in rel])
            d_idx, c_idx = dep[todo], ctrl[todo]
            e = v[:, c_idx] * scale + offset
            e -= v[:, d_idx]
            for n, m in zip(todo, np.abs(e).max(axis=0)):
                max_cache[keys[n]] = float(m)
        cmax[dep] = [max_cache[key] for key in keys]
    rms = math.sqrt(sq.sum() / D) if D else 0.0  # sq holds per-curve mean squares
    return rms, float(cmax.max()) if D else 0.0, np.sqrt(sq), cmax


def _condition(range_rule, rmsd_thr: dict) -> str:
    parts = [] if range_rule is None else [str(range_rule)]
    if rmsd_thr:
        if len(rmsd_thr) == 2 and rmsd_thr["rmsd1"] == rmsd_thr["rmsd2"]:
            parts.append(f"rmsd < {rmsd_thr['rmsd1']:g}")
        else:
            parts += [f"{k} < {rmsd_thr[k]:g}" for k in ("rmsd1", "rmsd2") if k in rmsd_thr]
    return " + ".join(parts) if parts else "original"


def _check_values(values) -> np.ndarray:
    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 2:
        raise ValueError(f"Expected values to have shape (T, D), got {v.shape}")
    if v.shape[0] < 2:
        raise ValueError(f"Expected at least 2 frames, got {v.shape[0]}")
    return v


def _group_codes(groups, D: int) -> np.ndarray:
    if groups is None:
        return np.zeros(D, dtype=np.int64)
    g = list(groups)
    if len(g) != D:
        raise ValueError(f"Expected {D} group labels, got {len(g)}")
    if isinstance(groups, np.ndarray) and groups.dtype.kind in "iu":
        return groups.astype(np.int64)
    index: dict = {}
    return np.array([index.setdefault(x, len(index)) for x in g], dtype=np.int64)


def _group_items(labels, codes):
    seen = {}
    for lab, c in zip(labels, codes):
        seen.setdefault(int(c), str(lab))
    return [(c, seen[c]) for c in sorted(seen)]


# ---------------------------------------------------------------------------- Euler branches
def continuous_euler_curves(values: np.ndarray, use: np.ndarray | None = None) -> np.ndarray:
    """Euler curves that follow the rotation through gimbal regions without jumps.

    Every rotation has two Tait-Bryan triples, ``(a, b, c)`` and
    ``(a + 180, 180 - b, c + 180)`` (any order with three distinct axes); a per-frame
    conversion keeps ``|b| <= 90`` and so jumps by 180 degrees on two axes whenever the
    middle angle passes 90 degrees (a finger bent about the middle axis of the order).
    Starting from the first frame as given, this picks at each frame the triple (each
    angle shifted by a multiple of 360) nearest to the previous frame's, so the curves
    stay continuous and the rotations unchanged.

    Parameters
    ----------
    values : (T, 3N) float
        Degrees; columns ``3i, 3i+1, 3i+2`` are the three angles of joint ``i`` in the
        order's sequence (the layout of :class:`~usdhands.model.finger_dofs.FingerCurves`).
    use : (3N,) bool, optional
        The angles that measure nearness (all when omitted; all of a joint none of whose
        angles is used). ``usdhands expand`` measures on the curves it keeps, so that a
        rotation jump (a tracking glitch) is followed the same way in a clip and in its
        expansion.

    Returns
    -------
    (T, 3N) float64
        Degrees; the same rotations frame by frame.
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] % 3:
        raise ValueError(f"Expected values to have shape (T, 3N), got {v.shape}")
    T = v.shape[0]
    if T == 0:
        return v.copy()
    e = v.reshape(T, -1, 3)
    alt = np.stack([e[..., 0] + 180.0, 180.0 - e[..., 1], e[..., 2] + 180.0], axis=-1)
    w = np.ones(e.shape[1:])
    if use is not None:
        u = np.asarray(use, dtype=bool)
        if u.shape != (v.shape[1],):
            raise ValueError(f"Expected use to have shape ({v.shape[1]},), got {u.shape}")
        u = u.reshape(-1, 3)
        w = np.where(u.any(axis=1, keepdims=True), u, True).astype(np.float64)

    def dist(a, b):  # L1 distance of triples over the used angles, each angle modulo 360
        return (np.abs((a - b + 180.0) % 360.0 - 180.0) * w).sum(axis=-1)

    # (a, b, c) -> (a+180, 180-b, c+180) preserves these distances, so whether frame t
    # switches branch relative to frame t-1 does not depend on the branch t-1 is on:
    # the branch of each frame is the parity of the switches so far (no loop over frames)
    switch = dist(alt[1:], e[:-1]) < dist(e[1:], e[:-1])  # (T-1, N)
    parity = np.concatenate([np.zeros((1, e.shape[1]), dtype=np.int64), np.cumsum(switch, axis=0)]) % 2
    chosen = np.where(parity[..., None] == 1, alt, e)
    # remove 360-degree steps (whole multiples of 360 added: values otherwise untouched)
    steps = np.round(np.diff(chosen, axis=0) / 360.0)
    shift = np.concatenate([np.zeros((1,) + chosen.shape[1:]), -360.0 * np.cumsum(steps, axis=0)])
    return (chosen + shift).reshape(v.shape)


def align_euler_branches(values: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Continuous Euler curves put, joint by joint, on the branch whose means are nearest ``reference``.

    A continuous curve triple ``(a, b, c)`` has a continuous twin ``(a + 180, 180 - b,
    c + 180)`` describing the same rotations. Read back from rotations, a triple starts
    on the branch with ``|b| <= 90`` at the first frame (:func:`continuous_euler_curves`),
    which need not be the branch the curves were made on: a rebuilt curve can leave that
    range. This picks, per joint, the triple or its twin (shifted by whole turns so that
    its first frame lies in ``(-180, 180]``, as a curve read from rotations starts),
    whichever has means nearer the reference (squared distance over the angles that have
    a reference; the triple on a tie or without a reference).

    Parameters
    ----------
    values : (T, 3N) float
        Degrees, continuous (:func:`continuous_euler_curves`), joint ``i`` in columns
        ``3i .. 3i+2``.
    reference : (3N,) float
        Degrees: the means to match; NaN where unknown.

    Returns
    -------
    (T, 3N) float64
        Degrees; the same rotations frame by frame.
    """
    v = np.asarray(values, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] % 3:
        raise ValueError(f"Expected values to have shape (T, 3N), got {v.shape}")
    if ref.shape != (v.shape[1],):
        raise ValueError(f"Expected reference to have shape ({v.shape[1]},), got {ref.shape}")
    T = v.shape[0]
    if T == 0:
        return v.copy()
    e = v.reshape(T, -1, 3)
    r = ref.reshape(-1, 3)
    known = np.isfinite(r)
    alt = np.stack([e[..., 0] + 180.0, 180.0 - e[..., 1], e[..., 2] + 180.0], axis=-1)
    alt = alt - 360.0 * np.ceil((alt[:1] - 180.0) / 360.0)  # first frame into (-180, 180]

    def dist(c):
        return np.where(known, (c.mean(axis=0) - np.where(known, r, 0.0)) ** 2, 0.0).sum(axis=-1)

    take = dist(alt) < dist(e) - 1e-9  # (N,)
    return np.where(take[None, :, None], alt, e).reshape(v.shape)


def model_curves(clip, joints, model: ReductionModel):
    """A clip's finger curves read for a model: continuous, on the Euler branch the model was made on.

    Continuity (:func:`continuous_euler_curves`) and the branch
    (:func:`align_euler_branches`, against ``model.means``) are both judged on the
    model's free curves, which :meth:`ReductionModel.apply` keeps: a clip and its
    expansion are read the same way, so expanding an expansion changes nothing even
    where a recording's rotations jump (tracking glitches).

    Parameters
    ----------
    clip : Clip
    joints : sequence of int
        Skeleton indices of the model's joints, in the model's curve order.
    model : ReductionModel

    Returns
    -------
    FingerCurves
        Degrees, in ``model.order``; their names are :func:`curve_names`.
    """
    curves = finger_curves(clip, list(joints), model.order)
    names = curve_names(clip.skeleton, joints, model.order)
    free = set(model.free_curves)
    use = np.array([c in free for c in names])
    values = continuous_euler_curves(curves.values, use=use)
    if model.means:
        values = align_euler_branches(values, np.array([model.means.get(c, np.nan) if u else np.nan
                                                        for c, u in zip(names, use)]))
    return curves.with_values(values)


def expand_clip(clip, joints, model: ReductionModel):
    """The clip with every constant and dependent finger curve of ``model`` rebuilt from its free curves.

    The curves are read by :func:`model_curves` (same parameters). Returns a Clip in
    which only the model's joints' rotations change.

    Raises
    ------
    ValueError
        The joints' curve names (``<joint>.<axis>`` in ``model.order``) do not cover the model's curves.
    """
    curves = model_curves(clip, joints, model)
    names = curve_names(clip.skeleton, joints, model.order)
    return apply_finger_curves(clip, curves.with_values(model.apply(curves.values, names)))


# ---------------------------------------------------------------------------- naming
_JOINT_LABELS = {
    "thumb": ("IP", "MCP", "CMC", "MC"),
    "finger": ("DIP", "PIP", "MCP", "CMC"),
}


def curve_joint_name(skeleton, joint: int) -> str:
    """The joint part of a curve name: the joint's short name, or its full name where the short one is not unique.

    USD joint names are paths: ``.../LeftHand/Index1`` and ``.../RightHand/Index1`` share
    the short name ``Index1``, so their curves are named by the full paths. Either form
    finds the joint again with ``skeleton.index``.
    """
    short = skeleton.short_names[joint]
    return short if skeleton.short_names.count(short) == 1 else skeleton.joint_names[joint]


def curve_names(skeleton, joints, order: str = "XYZ") -> tuple[str, ...]:
    """Curve names ``"<joint>.<axis>"`` of joints (:func:`curve_joint_name`), in the layout of ``FingerCurves``."""
    return tuple(f"{curve_joint_name(skeleton, int(j))}.{a.lower()}" for j in joints for a in order)


def paper_style_names(handmap: HandMap, order: str = "XYZ", skeleton=None) -> dict[str, str]:
    """Paper-style names (``riRingMCPy``) of the finger curves of a hand map.

    Joints are labelled from the distal end of each chain: ``IP, MCP, CMC`` for the
    thumb and ``DIP, PIP, MCP`` for the other fingers; a fourth joint (a metacarpal) is
    ``CMC`` on a finger and ``MC`` on a thumb; further joints are ``J5``, ``J6``, ...

    Parameters
    ----------
    handmap : HandMap
    order : str
        Euler order: the axis letters.
    skeleton : Skeleton, optional
        Keys curves as :func:`curve_names` does (full names where short ones repeat);
        short joint names otherwise.

    Returns
    -------
    dict
        ``"<joint>.<axis>"`` to ``"<le|ri><Finger><Joint><axis>"``.
    """
    out: dict[str, str] = {}
    for hand in handmap.sides:
        prefix = "le" if hand.side == "left" else "ri"
        for finger in FINGERS:
            chain = hand.fingers[finger]
            labels = _JOINT_LABELS["thumb" if finger == "thumb" else "finger"]
            n = len(chain)
            for k, joint in enumerate(chain):
                from_distal = n - 1 - k
                label = labels[from_distal] if from_distal < len(labels) else f"J{from_distal + 1}"
                key = short_joint_name(joint) if skeleton is None else \
                    curve_joint_name(skeleton, skeleton.index(joint))
                for axis in order:
                    out[f"{key}.{axis.lower()}"] = f"{prefix}{finger.capitalize()}{label}{axis.lower()}"
    return out

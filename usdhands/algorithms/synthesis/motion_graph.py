"""Transition costs (eq. 2) and the least-cost path through the layered graph (eq. 3).

Row ``i`` of the graph holds the ``k`` database segments most similar to input
segment ``i`` (their eq. 1 costs ``cS``); every node of row ``i`` connects to every
node of row ``i + 1`` with the transition cost ``cT`` between the finger motion at the
end of the first and the start of the second::

    cT = (wJ · Σ_i (J_A(i) − J_B(i))² + wW · Σ_i (W_A(i) − W_B(i))²) / m      (eq. 2)

over the ``m`` finger DOFs (degrees and degrees per frame at the database's rate:
with ``wW = 0.5`` the paper weighs velocity like the angles, which holds per frame;
in degrees per second the velocity term would be fps² = 900 times larger at 30 fps
and decide every transition alone). Entering node ``b`` from
``a`` costs ``wS · cS(b) + wT · cT(a, b)`` (eq. 3). The paper runs Dijkstra's
algorithm; on a layered graph the dynamic programme below finds the same least-cost
path in ``O(L k²)``. Ties go to the lower node index, so the path is deterministic.

**Normalised terms** (``normalize=True``, the default of synthesis). The paper's
weights ``wS = 1, wT = 0.5`` assume both terms have the same influence on average;
their raw scales differ by an order of magnitude (segment costs in cm² and deg² of
wrist motion, about 2,000 on real capture, against transition costs of finger
degrees² of about 200), so the transition term would hardly count. Each term is
therefore divided by its mean over the graph (all finite ``cS`` of the nodes, all
finite ``cT`` of the edges) before weighting. Only the DOFs that move anywhere in the
database count in ``m`` (``mask``): a constant DOF adds nothing but a larger divisor.
"""

from __future__ import annotations

import numpy as np

__all__ = ["transition_costs", "transition_costs_between", "least_cost_path", "term_scale"]


def term_scale(values) -> float:
    """Mean of the finite entries of some arrays (1 when there are none or it is 0)."""
    finite = [np.asarray(v, dtype=np.float64)[np.isfinite(v)] for v in values]
    total = sum(float(f.sum()) for f in finite)
    count = sum(f.size for f in finite)
    mean = total / count if count else 0.0
    return mean if mean > 0 else 1.0


def transition_costs(end_pose: np.ndarray, end_velocity: np.ndarray, start_pose: np.ndarray,
                     start_velocity: np.ndarray, w_joint: float = 1.0, w_velocity: float = 0.5,
                     mask: np.ndarray | None = None) -> np.ndarray:
    """Eq. 2 for every pair of a fragment ending (A) and a fragment starting (B).

    Parameters
    ----------
    end_pose, end_velocity : (Ka, C) float
        Finger DOFs (degrees) and their velocities (degrees per frame) at the last
        frame of each fragment A.
    start_pose, start_velocity : (Kb, C) float
        The same at the first frame of each fragment B.
    w_joint, w_velocity : float
        wJ and wW.
    mask : (C,) bool, optional
        The DOFs that count (m = their number); all when omitted.

    Returns
    -------
    (Ka, Kb) float
        Transition costs.
    """
    arrays = [np.asarray(a, dtype=np.float64) for a in (end_pose, end_velocity, start_pose, start_velocity)]
    ea, va, sb, vb = arrays
    if ea.shape != va.shape or sb.shape != vb.shape or ea.ndim != 2 or sb.ndim != 2 or ea.shape[1] != sb.shape[1]:
        raise ValueError(f"Expected (Ka, C) and (Kb, C) arrays, got {[a.shape for a in arrays]}")
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        ea, va, sb, vb = ea[:, mask], va[:, mask], sb[:, mask], vb[:, mask]
    m = ea.shape[1]
    if m == 0:
        return np.zeros((len(ea), len(sb)))
    dj = ((ea[:, None, :] - sb[None, :, :]) ** 2).sum(axis=2)
    dw = ((va[:, None, :] - vb[None, :, :]) ** 2).sum(axis=2)
    return (w_joint * dj + w_velocity * dw) / m


def transition_costs_between(end_pose: np.ndarray, end_velocity: np.ndarray, start_pose: np.ndarray,
                             start_velocity: np.ndarray, w_joint: float = 1.0, w_velocity: float = 0.5,
                             mask: np.ndarray | None = None) -> np.ndarray:
    """:func:`transition_costs` of every layer at once: ``(L, Ka, C)`` and ``(L, Kb, C)`` in, ``(L, Ka, Kb)`` out."""
    arrays = [np.asarray(a, dtype=np.float64) for a in (end_pose, end_velocity, start_pose, start_velocity)]
    ea, va, sb, vb = arrays
    if ea.shape != va.shape or sb.shape != vb.shape or ea.ndim != 3 or sb.ndim != 3 or ea.shape[::2] != sb.shape[::2]:
        raise ValueError(f"Expected (L, Ka, C) and (L, Kb, C) arrays, got {[a.shape for a in arrays]}")
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        ea, va, sb, vb = ea[..., mask], va[..., mask], sb[..., mask], vb[..., mask]
    m = ea.shape[2]
    if m == 0:
        return np.zeros((len(ea), ea.shape[1], sb.shape[1]))
    dj = ((ea[:, :, None, :] - sb[:, None, :, :]) ** 2).sum(axis=3)
    dw = ((va[:, :, None, :] - vb[:, None, :, :]) ** 2).sum(axis=3)
    return (w_joint * dj + w_velocity * dw) / m


def least_cost_path(segment_costs: np.ndarray, transitions: list[np.ndarray],
                    w_segment: float = 1.0, w_transition: float = 0.5,
                    normalize: bool = False) -> tuple[np.ndarray, float]:
    """Least-cost path through the layered graph.

    Parameters
    ----------
    segment_costs : (L, K) float
        ``cS`` of each node; ``inf`` marks a missing node.
    transitions : list of L-1 arrays (K, K) float
        ``cT`` from node a of row i to node b of row i+1.
    w_segment, w_transition : float
        wS and wT.
    normalize : bool
        Divide each term by its mean (:func:`term_scale`) first (see the module notes).

    Returns
    -------
    path : (L,) int
        The node chosen in each row.
    cost : float
        Total cost of the path (``inf`` if a row has no node).
    """
    cs = np.asarray(segment_costs, dtype=np.float64)
    if cs.ndim != 2:
        raise ValueError(f"Expected segment_costs to have shape (L, K), got {cs.shape}")
    L, K = cs.shape
    if len(transitions) != max(L - 1, 0):
        raise ValueError(f"Expected {max(L - 1, 0)} transition matrices, got {len(transitions)}")
    if L == 0:
        return np.zeros(0, dtype=np.int64), 0.0
    if normalize:
        w_segment = w_segment / term_scale([cs])
        w_transition = w_transition / term_scale(transitions)
    acc = w_segment * cs[0]
    back = np.zeros((L, K), dtype=np.int64)
    for i in range(1, L):
        t = np.asarray(transitions[i - 1], dtype=np.float64)
        if t.shape != (K, K):
            raise ValueError(f"Expected transitions[{i - 1}] to have shape ({K}, {K}), got {t.shape}")
        total = acc[:, None] + w_transition * np.where(np.isfinite(t), t, np.inf)
        back[i] = np.argmin(total, axis=0)  # first minimum: lower index wins ties
        acc = total[back[i], np.arange(K)] + w_segment * cs[i]
    end = int(np.argmin(acc))
    cost = float(acc[end])
    path = np.empty(L, dtype=np.int64)
    path[-1] = end
    for i in range(L - 1, 0, -1):
        path[i - 1] = back[i, path[i]]
    return path, cost

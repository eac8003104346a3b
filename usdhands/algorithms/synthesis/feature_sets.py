"""Feature sets: which arm features stand behind the segment cost (eq. 1), and their columns.

The paper compares wrist motion only: position and rotation relative to the root,
``wP = 1``, ``wR = 0.5`` (``segment_cost.w_position``, ``w_rotation``). A feature set
(``segment_cost.features`` in a configuration, ``--feature-sets`` of ``evaluate``)
names other columns as a sum of weighted terms
``[weight*][other_]<wrist|elbow|shoulder>_<pos|rot|vel>``; a term of only ``pos``,
``rot`` or ``vel`` keeps the previous term's joint. The paper's is
``wrist_pos+0.5rot`` (:data:`PAPER_FEATURES`).

- ``<joint>_pos`` ``(T, 3)``: position relative to the root, centimetres, scaled to
  the database's body size; ``<joint>_rot`` ``(T, 9)``: rotation features (matrix
  entries in "degrees", :func:`~usdhands.algorithms.synthesis.wrist_features.arm_features`);
- ``<joint>_vel`` ``(T, 3)``: the time derivative of ``<joint>_pos``, cm/s (central
  differences inside a clip, one-sided at its ends);
- ``other_<...>``: the same of the other hand of the same clip (a mirrored track's
  other hand is the mirrored other hand).

A database stores the wrist's position and rotation for every frame
(``features.npy``); the columns of any other term go into ``arm_features.npy`` when
the database is built with a configuration that names them (``db build --config``),
listed in the manifest's ``arm_features``. Synthesis computes the same columns for
its input, weights both sides alike (each column times the square root of its
term's weight, :func:`~usdhands.algorithms.synthesis.segment_cost.weight_features`)
and compares them in eq. 1 as it does the wrist features.
"""

from __future__ import annotations

import numpy as np

from usdhands.algorithms.synthesis.wrist_features import arm_features, reach_cm
from usdhands.model.clip import Clip
from usdhands.model.handmap import HandMap

__all__ = ["PAPER_FEATURES", "WRIST_KEYS", "parse_feature_set", "key_width", "feature_terms", "extra_keys",
           "hand_columns", "check_keys", "mirror_columns", "weighted_columns"]

PAPER_FEATURES = "wrist_pos+0.5rot"
#: The keys of the database's own wrist features (features.npy: position, then rotation).
WRIST_KEYS = ("wrist_pos", "wrist_rot")
_ROLE_JOINT = {"wrist": "wrist", "elbow": "forearm", "shoulder": "shoulder"}


def parse_feature_set(name: str) -> list[tuple[str, float]]:
    """Terms of a feature set: ``[("wrist_pos", 1.0), ("wrist_rot", 0.5), ("other_wrist_pos", 0.5)]``.

    The grammar of :func:`~usdhands.algorithms.synthesis.evaluation.parse_terms` with
    ``vel`` and ``other_``. A key named twice gets the sum of its weights.

    Raises
    ------
    ValueError
        Quoting the name and the term that does not parse.
    """
    from usdhands.algorithms.synthesis.evaluation import parse_terms

    merged: dict[str, float] = {}
    for key, weight in parse_terms(name, "feature set", extended=True):
        merged[key] = merged.get(key, 0.0) + weight
    return list(merged.items())


def key_width(key: str) -> int:
    """Columns of a feature key: 9 for a rotation, 3 for a position or velocity."""
    return 9 if key.endswith("_rot") else 3


def feature_terms(segment_cost) -> list[tuple[str, float]]:
    """The weighted terms behind eq. 1 for a ``SegmentCostConfig``.

    Without ``features``, the paper's wrist terms with ``w_position`` and ``w_rotation``.
    """
    if segment_cost.features is None:
        return [("wrist_pos", float(segment_cost.w_position)), ("wrist_rot", float(segment_cost.w_rotation))]
    return parse_feature_set(segment_cost.features)


def extra_keys(terms) -> list[str]:
    """Keys of the terms that are not the database's own wrist features, in order."""
    return [key for key, _ in terms if key not in WRIST_KEYS]


def _role(key: str) -> tuple[bool, str, str]:
    """``(other, role, kind)`` of a key such as ``other_elbow_vel``."""
    other = key.startswith("other_")
    role, kind = (key[6:] if other else key).rsplit("_", 1)
    return other, role, kind


def hand_columns(clip: Clip, handmap: HandMap, side: str, keys, reach: float, world: np.ndarray | None = None) -> dict:
    """Columns ``{key: (T, 3|9)}`` of one hand of a clip for feature keys (see the module notes).

    Parameters
    ----------
    clip : Clip
    handmap : HandMap
    side : {"left", "right"}
        The hand the features are for (``other_`` keys take the other side's).
    keys : iterable of str
        Feature keys (:func:`parse_feature_set`).
    reach : float
        The database's body size, cm: positions of each hand are scaled by
        ``reach / reach_cm(hand)``.
    world : (T, J, 4, 4) float, optional
        The clip's world transforms of the arm chains, when already computed.

    Raises
    ------
    ValueError
        A key names a joint the hand map lacks (a rig without shoulders, a clip
        with one hand), naming the key.
    """
    check_keys(handmap, side, keys, clip.name)
    cache: dict = {}
    out = {}
    for key in keys:
        other, role, kind = _role(key)
        s = ("right" if side == "left" else "left") if other else side
        hand = handmap[s]
        if s not in cache:
            if world is None:
                world = clip.world_xforms()
            roles = tuple(r for r in ("wrist", "elbow", "shoulder") if r == "wrist" or getattr(hand, _ROLE_JOINT[r]))
            cache[s] = arm_features(clip, hand, reach / reach_cm(clip.skeleton, hand), roles, world)
        pos = cache[s][f"{role}_pos"]
        if kind == "vel":
            out[key] = np.gradient(pos, axis=0) * clip.fps if len(pos) > 1 else np.zeros_like(pos)
        else:
            out[key] = cache[s][f"{role}_{kind}"]
    return out


def check_keys(handmap: HandMap, side: str, keys, name: str = "") -> None:
    """Raise ValueError naming the first key whose joint the hand map lacks for this side (``name``: the clip's)."""
    for key in keys:
        other, role, _ = _role(key)
        s = ("right" if side == "left" else "left") if other else side
        hand = handmap[s]
        if hand is None or (role != "wrist" and not getattr(hand, _ROLE_JOINT[role])):
            of = f" of {name!r}" if name else ""
            raise ValueError(f"feature {key!r} of the {side} hand needs the {s} hand's {_ROLE_JOINT[role]} joint, "
                             f"which the hand map{of} does not have")


def mirror_columns(key: str, values: np.ndarray) -> np.ndarray:
    """Columns of a key mirrored left↔right (X flips; rotations ``M R M``, ``M = diag(−1, 1, 1)``)."""
    v = np.array(values, dtype=np.float64)
    if key.endswith("_rot"):
        v[:, [1, 2, 3, 6]] *= -1
    else:
        v[:, 0] *= -1
    return v


def weighted_columns(wrist: np.ndarray, extra: np.ndarray | None, extra_names, terms) -> np.ndarray:
    """The weighted feature columns ``(T, D)`` of eq. 1 for some terms.

    Parameters
    ----------
    wrist : (T, 12) float
        Wrist position and rotation features (a database's ``features``).
    extra : (T, C) float or None
        Other columns, laid out as ``extra_names`` (keys, :func:`key_width` columns each).
    extra_names : sequence of str
    terms : list of (key, weight)

    Raises
    ------
    ValueError
        A term's key is neither a wrist key nor among ``extra_names``.
    """
    from usdhands.algorithms.synthesis.segment_cost import weight_features

    offsets, at = {}, 0
    for name in extra_names:
        offsets[name] = at
        at += key_width(name)
    blocks, weights = [], []
    for key, weight in terms:
        if key == "wrist_pos":
            block = wrist[:, :3]
        elif key == "wrist_rot":
            block = wrist[:, 3:12]
        elif key in offsets and extra is not None:
            block = extra[:, offsets[key]:offsets[key] + key_width(key)]
        else:
            raise ValueError(f"No columns for feature {key!r}; have {list(WRIST_KEYS) + list(extra_names)}")
        blocks.append(np.asarray(block, dtype=np.float64))
        weights.append(np.full(block.shape[1], weight))
    return weight_features(np.concatenate(blocks, axis=1), np.concatenate(weights))

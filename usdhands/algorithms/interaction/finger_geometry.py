"""The hand as capsules: one per finger segment, with joint axes and limits from the rig.

Radii per finger and segment are those of an average adult hand (about 6.5 to 10 mm,
proximal to distal), configurable, or measured on the hand's skinned mesh where the file
has one (:func:`mesh_radii`); lengths come from the rig (joint to child joint, the
last segment to the end joint, or 0.8 of the previous bone where the rig has no end
joint). Each finger joint's Euler axes get a role found from the rest pose: **twist**
along the bone, **flexion** across the hand (the axis nearest the line from the index
base to the pinky base), **abduction** the third; flexion is signed so that positive
curls toward the palm (the side the thumb base stands out to). Limits per finger, joint
and role, in degrees.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from usdhands.errors import ConfigError
from usdhands.input_files import read_json
from usdhands.json_schemas import first_schema_error
from usdhands.model.handmap import FINGERS, HandSide
from usdhands.model.rotations import DEFAULT_EULER_ORDER
from usdhands.model.skeleton import Skeleton

__all__ = ["InteractionConfig", "FingerChain", "finger_chains", "load_interaction_config", "mesh_radii",
           "DEFAULT_RADII_MM", "DEFAULT_LIMITS_DEG"]

#: Capsule radius per finger, proximal to distal segment, millimetres (average adult hand).
DEFAULT_RADII_MM = {
    "thumb": (10.0, 9.0, 8.0),
    "index": (9.0, 8.0, 7.0),
    "middle": (9.0, 8.5, 7.0),
    "ring": (8.5, 8.0, 7.0),
    "pinky": (8.0, 7.0, 6.5),
}

_FINGER_LIMITS = {"flexion": [[-45.0, 110.0], [-15.0, 125.0], [-20.0, 100.0]],
                  "abduction": [[-35.0, 35.0], [-20.0, 20.0], [-20.0, 20.0]],
                  "twist": [[-40.0, 40.0], [-30.0, 30.0], [-30.0, 30.0]]}
_THUMB_LIMITS = {"flexion": [[-60.0, 100.0], [-40.0, 100.0], [-40.0, 110.0]],
                 "abduction": [[-70.0, 70.0], [-40.0, 40.0], [-30.0, 30.0]],
                 "twist": [[-70.0, 70.0], [-45.0, 45.0], [-40.0, 40.0]]}
#: Joint limits per finger, role and joint (proximal to distal), degrees from the rest pose.
DEFAULT_LIMITS_DEG = {f: (_THUMB_LIMITS if f == "thumb" else _FINGER_LIMITS) for f in FINGERS}

ROLES = ("flexion", "abduction", "twist")


@dataclass(frozen=True)
class InteractionConfig:
    """Finger geometry, joint limits and correction settings (``schemas/interaction_config.schema.json``).

    Parameters
    ----------
    radii_mm : dict
        Finger name to capsule radii, proximal to distal segment, mm. Chains with more
        joints (metacarpals) use the proximal radius for the extra segments.
    limits_deg : dict
        Finger name to ``{"flexion"|"abduction"|"twist": [[lo, hi] per joint]}``, degrees
        from the rest pose; extra proximal joints use the first entry.
    tip_fraction : float
        Length of the last segment where the rig has no end joint, as a fraction of the one before.
    tolerance_mm : float
        Half the deepest penetration the clearance test lets through (the search's resolution).
    smoothing_s : float
        Time scale of the smoothers on a corrected finger, seconds.
    joint_radii_mm : dict
        Joint name (or path) to the radius of the segment it starts, mm; overrides
        ``radii_mm`` for that joint. The jobs fill it from the hand's skinned mesh (``mesh_radii``), names
        given here taking precedence.
    mesh_radii : bool
        Where the animation file has a mesh skinned to the hand, take each segment's radius
        from the vertices it drives (:func:`mesh_radii`); ``radii_mm`` then applies only
        where the mesh has too few of them.
    palm_radius_mm : float
        Radius of the palm's capsules (wrist to each long finger's base), mm: about half an
        adult palm's thickness. Measured, never moved (:mod:`usdhands.algorithms.interaction.palm`);
        where the file has a mesh skinned to the hand, half the palm's thickness measured on it
        (:func:`mesh_radii`) replaces it, and ``joint_radii_mm`` naming the wrist joint overrides both.
    ik : str
        ``"opening"``: each chain opens along one path toward its rest pose, distal joints
        first in overlapping ramps, and the least clear opening is the bound (continuous in
        time, so the smoothest result). ``"ccd"``: cyclic coordinate descent first turns each
        joint, tip to root, about its flexion axis by the least angle that clears its segment
        and the ones after it (the least change), and the path goes through that pose.
    """

    radii_mm: dict = field(default_factory=lambda: {k: tuple(v) for k, v in DEFAULT_RADII_MM.items()})
    limits_deg: dict = field(default_factory=lambda: json.loads(json.dumps(DEFAULT_LIMITS_DEG)))
    tip_fraction: float = 0.8
    tolerance_mm: float = 0.5
    smoothing_s: float = 0.15
    joint_radii_mm: dict = field(default_factory=dict)
    mesh_radii: bool = True
    ik: str = "opening"
    palm_radius_mm: float = 12.0

    @classmethod
    def from_dict(cls, d: dict) -> "InteractionConfig":
        """Build from a (possibly partial) dict: omitted fingers and keys keep their defaults."""
        base = cls()
        radii = dict(base.radii_mm)
        radii.update({k: tuple(v) for k, v in d.get("radii_mm", {}).items()})
        limits = json.loads(json.dumps(base.limits_deg))
        for finger, roles in d.get("limits_deg", {}).items():
            limits[finger].update(roles)
        rest = {k: d[k] for k in ("tip_fraction", "tolerance_mm", "smoothing_s", "mesh_radii", "ik", "palm_radius_mm")
                if k in d}
        return cls(radii_mm=radii, limits_deg=limits, joint_radii_mm=dict(d.get("joint_radii_mm", {})), **rest)

    def with_mesh_radii(self, measured_mm: dict) -> "InteractionConfig":
        """This configuration with radii measured on a mesh (joint name to mm) where it names none."""
        if not self.mesh_radii or not measured_mm:
            return self
        given = self.joint_radii_mm
        kept = {k: v for k, v in measured_mm.items() if k not in given and k.rsplit("/", 1)[-1] not in given}
        return replace(self, joint_radii_mm={**kept, **given})

    def joint_radius_mm(self, name: str, default: float) -> float:
        """The radius ``joint_radii_mm`` gives the joint (by its name or path, or its last path
        component), else ``default``."""
        r = self.joint_radii_mm.get(name)
        return self.joint_radii_mm.get(name.rsplit("/", 1)[-1], default) if r is None else r


def load_interaction_config(path: str | Path) -> InteractionConfig:
    """Read and validate an interaction configuration file (JSON).

    Raises
    ------
    ConfigError
        Missing, not JSON, or not matching the schema (the message names the key).
    """
    path = Path(path)
    # a named pipe or a device refused before it is opened; strict JSON (NaN, nesting, huge integers)
    data = read_json(path, what="configuration file", error=ConfigError)
    error = first_schema_error(data, "interaction_config")
    if error is not None:
        where, message = error
        raise ConfigError(f"invalid interaction configuration at {where}: {message}", path=path)
    return InteractionConfig.from_dict(data)


@dataclass(frozen=True, eq=False)
class FingerChain:
    """One finger of one hand as the correction sees it.

    Parameters
    ----------
    side, finger : str
    joints : tuple of int, length n
        Skeleton indices, proximal to distal.
    tip_offset : (3,) float
        The finger tip in the last joint's local frame, clip units.
    radii : (n,) float
        Capsule radius of each segment (joint k to joint k+1, the last to the tip), clip units.
    axes : (n, 3) int
        For each joint, the Euler-angle index (into the curves' order) of flexion, abduction, twist.
    flexion_sign : (n,) float
        +1 where a positive Euler angle on the flexion axis curls toward the palm, else -1.
    limits : (n, 3, 2) float
        Lower and upper bound of each Euler angle, degrees, in curve-axis order.
    """

    side: str
    finger: str
    joints: tuple
    tip_offset: np.ndarray
    radii: np.ndarray
    axes: np.ndarray
    flexion_sign: np.ndarray
    limits: np.ndarray

    @property
    def name(self) -> str:
        """``"left index"``."""
        return f"{self.side} {self.finger}"


def _per_joint(values: list, n: int) -> list:
    """Values given proximal to distal for the last ``len(values)`` joints, the first repeated before them."""
    values = list(values)
    if n <= len(values):
        return values[len(values) - n:]
    return [values[0]] * (n - len(values)) + values


def _joint_roles(R_world: np.ndarray, bone_world: np.ndarray, across: np.ndarray, palm: np.ndarray,
                 order: str) -> tuple[np.ndarray, float]:
    """Euler indices of (flexion, abduction, twist) and the flexion sign of one joint at rest."""
    local_bone = R_world.T @ bone_world
    local_across = R_world.T @ across
    letters = "XYZ"
    twist = int(np.argmax(np.abs(local_bone)))
    cand = [k for k in range(3) if k != twist]
    flex = max(cand, key=lambda k: abs(local_across[k]))
    abd = [k for k in cand if k != flex][0]
    axis_world = R_world[:, flex]
    sign = float(np.sign(np.dot(np.cross(axis_world, bone_world), palm)) or 1.0)
    idx = [order.index(letters[k]) for k in (flex, abd, twist)]
    return np.array(idx), sign


def finger_chains(skeleton: Skeleton, hand: HandSide, config: InteractionConfig | None = None,
                  order: str = DEFAULT_EULER_ORDER) -> list[FingerChain]:
    """The finger chains of one hand with their capsules, axes and limits.

    Parameters
    ----------
    skeleton : Skeleton
        In the clip's units.
    hand : HandSide
    config : InteractionConfig, optional
    order : str
        Euler order of the finger curves.
    """
    cfg = config or InteractionConfig()
    mm = 0.001 / skeleton.meters_per_unit
    rest = skeleton.rest_world_xforms()
    pos = rest[:, :3, 3]
    chains_joints = {f: [skeleton.index(j) for j in hand.fingers[f]] for f in hand.present_fingers}
    wrist = skeleton.index(hand.wrist)
    bases = {f: pos[js[-3] if len(js) >= 3 else js[0]] for f, js in chains_joints.items()}
    if "index" in bases and "pinky" in bases:
        across = bases["pinky"] - bases["index"]
    elif len(bases) >= 2:
        names = [f for f in FINGERS if f in bases and f != "thumb"] or list(bases)
        across = bases[names[-1]] - bases[names[0]]
    else:
        across = np.cross(pos[wrist] - pos[skeleton.parents[wrist]] if skeleton.parents[wrist] >= 0
                          else np.array([1.0, 0, 0]), [0, 1.0, 0])
    across = across / max(np.linalg.norm(across), 1e-12)
    long_finger = next((f for f in ("middle", "index", "ring", "pinky") if f in bases), None)
    forward = (bases[long_finger] if long_finger else pos[wrist] + across) - pos[wrist]
    palm = np.cross(forward, across)
    palm /= max(np.linalg.norm(palm), 1e-12)
    if "thumb" in chains_joints:
        thumb_base = pos[chains_joints["thumb"][0]]
        if np.dot(thumb_base - pos[wrist], palm) < 0:
            palm = -palm
    out = []
    children = {j: skeleton.children(j) for js in chains_joints.values() for j in js}
    for finger, js in chains_joints.items():
        n = len(js)
        last = js[-1]
        kids = children[last]
        if kids:
            tip = np.asarray(skeleton.rest_translations[kids[0]], dtype=np.float64)
        else:
            tip = np.asarray(skeleton.rest_translations[last], dtype=np.float64) * cfg.tip_fraction
        radii = np.array([cfg.joint_radius_mm(skeleton.joint_names[j], r) * mm
                          for j, r in zip(js, _per_joint(cfg.radii_mm[finger], n))], dtype=np.float64)
        axes, signs, limits = [], [], []
        lim_cfg = cfg.limits_deg[finger]
        per_role = {r: _per_joint(lim_cfg[r], n) for r in ROLES}
        for k, j in enumerate(js):
            child_pos = pos[js[k + 1]] if k + 1 < n else rest[last] @ np.append(tip, 1.0)
            bone = child_pos[:3] - pos[j]
            if np.linalg.norm(bone) < 1e-12:
                bone = forward
            idx, sign = _joint_roles(rest[j, :3, :3] / np.linalg.norm(rest[j, :3, 0]), bone / np.linalg.norm(bone),
                                     across, palm, order)
            box = np.zeros((3, 2))
            for role_i, role in enumerate(ROLES):
                lo, hi = per_role[role][k]
                if role == "flexion" and sign < 0:
                    lo, hi = -hi, -lo
                box[idx[role_i]] = (lo, hi)
            axes.append(idx)
            signs.append(sign)
            limits.append(box)
        out.append(FingerChain(hand.side, finger, tuple(js), tip, radii, np.array(axes), np.array(signs),
                               np.array(limits)))
    return out


#: Fewest vertices a segment must drive (along the middle of its axis) for its radius to be measured.
MESH_RADIUS_MIN_VERTICES = 8


def mesh_radii(skeleton: Skeleton, hand: HandSide, meshes, config: InteractionConfig | None = None) -> dict:
    """Capsule radius of each finger segment measured on the meshes skinned to the hand.

    A vertex belongs to the joint with its largest weight, if that weight is at least 0.5.
    A segment's radius is the median distance from its axis (the joint to the next joint,
    or to the tip) of the vertices its joint drives that lie over the middle 70% of the
    axis (the knuckles' flesh belongs to both neighbours), in the bind pose: for a finger
    modelled as a tube, the tube's radius. Segments with fewer than
    :data:`MESH_RADIUS_MIN_VERTICES` such vertices are left out (the configuration's radius applies).

    The palm's radius (:mod:`~usdhands.algorithms.interaction.palm`: capsules from the wrist to each
    long finger's first joint) is half the palm's thickness: the median distance from the plane of
    the wrist and those joints (fitted, in the bind pose) of the vertices the wrist drives over the
    middle 70% of the way from the wrist to the finger bases, between the outermost bases; it is
    given under the wrist joint's name, as ``joint_radii_mm`` gives it (left out with fewer than
    :data:`MESH_RADIUS_MIN_VERTICES` such vertices: ``palm_radius_mm`` applies).

    Parameters
    ----------
    skeleton : Skeleton
        The meshes' skeleton.
    hand : HandSide
    meshes : sequence of SkinnedMesh
        Meshes bound to ``skeleton`` (others, and meshes without influences, are ignored by the caller).
    config : InteractionConfig, optional
        For the tip of a chain without an end joint.

    Returns
    -------
    dict
        Name of the segment's joint to its radius, mm.
    """
    pts, owner = [], []
    for mesh in meshes:
        if mesh.joint_indices is None or mesh.joint_weights is None or not len(mesh.points):
            continue
        idx = np.asarray(mesh.joint_indices).reshape(len(mesh.points), -1)
        w = np.asarray(mesh.joint_weights, dtype=np.float64).reshape(idx.shape)
        if not idx.size:
            continue
        best = np.argmax(w, axis=1)
        keep = w[np.arange(len(w)), best] >= 0.5
        p = np.asarray(mesh.points, dtype=np.float64)[keep]
        m = np.asarray(mesh.geom_bind_xform, dtype=np.float64)
        pts.append(p @ m[:3, :3].T + m[:3, 3])
        owner.append(idx[np.arange(len(idx)), best][keep])
    if not pts:
        return {}
    pts, owner = np.concatenate(pts), np.concatenate(owner)
    bind = skeleton.bind_xforms if skeleton.bind_xforms is not None else skeleton.rest_world_xforms()
    out = {}
    chains = finger_chains(skeleton, hand, config)
    palm = _palm_half_thickness(pts, owner, bind, skeleton, hand, chains)
    if palm is not None:
        out[skeleton.joint_names[skeleton.index(hand.wrist)]] = palm * skeleton.meters_per_unit * 1000.0
    for chain in chains:
        js = list(chain.joints)
        ends = [bind[j, :3, 3] for j in js] + [bind[js[-1], :3, :3] @ chain.tip_offset + bind[js[-1], :3, 3]]
        for k, j in enumerate(js):
            q = pts[owner == j]
            a, b = ends[k], ends[k + 1]
            ab = b - a
            length2 = float(ab @ ab)
            if len(q) < MESH_RADIUS_MIN_VERTICES or length2 <= 0:
                continue
            t = (q - a) @ ab / length2
            q = q[(t > 0.15) & (t < 0.85)]
            if len(q) < MESH_RADIUS_MIN_VERTICES:
                continue
            t = (q - a) @ ab / length2
            r = float(np.median(np.linalg.norm(q - (a + t[:, None] * ab), axis=1)))
            out[skeleton.joint_names[j]] = r * skeleton.meters_per_unit * 1000.0
    return out


def _palm_half_thickness(pts: np.ndarray, owner: np.ndarray, bind: np.ndarray, skeleton: Skeleton, hand: HandSide,
                         chains: list[FingerChain]) -> float | None:
    """Half the palm's thickness measured on the vertices the wrist drives, clip units (:func:`mesh_radii`);
    None where the hand has fewer than two long fingers or the wrist too few vertices over the palm."""
    wrist = skeleton.index(hand.wrist)
    bases = [c.joints[0] for c in chains if c.finger != "thumb"]
    q = pts[owner == wrist]
    if len(bases) < 2 or len(q) < MESH_RADIUS_MIN_VERTICES:
        return None
    w = bind[wrist, :3, 3]
    b = bind[bases, :3, 3]
    corners = np.vstack([w[None], b])
    centre = corners.mean(axis=0)
    normal = np.linalg.svd(corners - centre)[2][2]  # the plane of the wrist and the finger bases
    forward = b.mean(axis=0) - w
    forward -= normal * (forward @ normal)
    length2 = float(forward @ forward)
    if length2 <= 0:
        return None
    across = np.cross(normal, forward)
    span = (b - w) @ across
    t = (q - w) @ forward / length2
    s = (q - w) @ across
    q = q[(t > 0.15) & (t < 0.85) & (s >= span.min()) & (s <= span.max())]
    if len(q) < MESH_RADIUS_MIN_VERTICES:
        return None
    return float(np.median(np.abs((q - centre) @ normal)))

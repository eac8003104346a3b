"""The sample humanoid: a Mixamo-style rig with full hands and a skinned box mesh.

Units are centimetres (``meters_per_unit = 0.01``), +Y is up, the character faces +Z
and its left arm lies along +X in the rest pose (a T-pose, palms down).

Joint frames follow the Mixamo habit of pointing each joint's local +Y along its bone.
The other axes are chosen so that the main hinge of a joint is its local X axis:

- finger joints (index to pinky): flexion is a positive rotation about local X,
  abduction a rotation about local Z (the palm normal, pointing out of the palm);
- thumb joints: a positive rotation about local X curls the thumb across the palm;
- elbows: flexion is a positive rotation about local X; knees likewise.

So the rest rotations are far from identity, as in rigs exported from DCC tools,
while a finger's flexion is one local Euler curve (``"LeftHandIndex2.x"``).

Joint names are USD joint paths (``"Hips/Spine/Spine1"``); the short names (last path
element) are the Mixamo names without namespace (``"LeftHandIndex1"``).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from usdhands.model.asset import SkinnedMesh
from usdhands.model.handmap import HandMap, HandSide
from usdhands.model.rotations import matrix_to_quat
from usdhands.model.skeleton import Skeleton

__all__ = [
    "FINGER_NAMES", "MESH_NAME", "SKELETON_NAME", "humanoid_skeleton", "humanoid_mesh",
    "humanoid_handmap", "finger_joint_indices", "joint_index", "mirror_name",
]

SKELETON_NAME = "Humanoid"
MESH_NAME = "Body"
FINGER_NAMES = ("Thumb", "Index", "Middle", "Ring", "Pinky")

# Centre joints: (name, parent, world rest position in cm).
_CENTRE = [
    ("Hips", None, (0.0, 100.0, 0.0)),
    ("Spine", "Hips", (0.0, 110.0, 0.5)),
    ("Spine1", "Spine", (0.0, 121.0, 0.5)),
    ("Spine2", "Spine1", (0.0, 133.0, 0.0)),
    ("Neck", "Spine2", (0.0, 149.0, -1.0)),
    ("Head", "Neck", (0.0, 158.0, 1.0)),
    ("HeadTop_End", "Head", (0.0, 175.0, 1.0)),
]

# Left arm, world positions in cm (the right arm mirrors x).
_ARM = [
    ("LeftShoulder", "Spine2", (3.0, 143.0, -0.5)),
    ("LeftArm", "LeftShoulder", (16.0, 144.0, -1.0)),
    ("LeftForeArm", "LeftArm", (45.0, 144.0, -1.0)),
    ("LeftHand", "LeftForeArm", (70.0, 144.0, -1.0)),
]

# Fingers of the left hand: base offset from the wrist and (direction, lengths) of the
# three bones; the fourth joint is the end (tip) joint.
_FINGERS = {
    "Thumb": ((2.5, -1.2, 2.2), [((0.75, -0.25, 0.60), 4.2), ((0.85, -0.15, 0.50), 3.2), ((0.85, -0.15, 0.50), 2.8)]),
    "Index": ((9.4, 0.0, 2.3), [((1.0, 0.0, 0.05), 4.1), ((1.0, 0.0, 0.05), 2.5), ((1.0, 0.0, 0.05), 2.1)]),
    "Middle": ((9.6, 0.0, 0.4), [((1.0, 0.0, 0.0), 4.5), ((1.0, 0.0, 0.0), 2.8), ((1.0, 0.0, 0.0), 2.3)]),
    "Ring": ((9.1, 0.0, -1.5), [((1.0, 0.0, -0.05), 4.2), ((1.0, 0.0, -0.05), 2.7), ((1.0, 0.0, -0.05), 2.2)]),
    "Pinky": ((8.3, -0.3, -3.2), [((1.0, 0.0, -0.12), 3.4), ((1.0, 0.0, -0.12), 2.1), ((1.0, 0.0, -0.12), 1.9)]),
}

_LEG = [
    ("LeftUpLeg", "Hips", (9.0, 93.0, 0.0)),
    ("LeftLeg", "LeftUpLeg", (9.0, 51.0, 0.5)),
    ("LeftFoot", "LeftLeg", (9.0, 8.0, -1.0)),
    ("LeftToeBase", "LeftFoot", (9.0, 1.5, 12.0)),
    ("LeftToe_End", "LeftToeBase", (9.0, 1.5, 19.0)),
]

# Thumb curl direction (the Z axis of the thumb frames), left hand, world rest space.
_THUMB_CURL = (0.0, -0.6, -0.8)


def mirror_name(name: str) -> str:
    """``"LeftHand"`` ↔ ``"RightHand"``; other names unchanged."""
    if name.startswith("Left"):
        return "Right" + name[4:]
    if name.startswith("Right"):
        return "Left" + name[5:]
    return name


def _left_joints() -> list[tuple[str, str, tuple]]:
    out = list(_ARM)
    wrist = np.array(_ARM[-1][2])
    for finger, (base, bones) in _FINGERS.items():
        p = wrist + np.array(base)
        parent = "LeftHand"
        for k in range(4):
            name = f"LeftHand{finger}{k + 1}"
            out.append((name, parent, tuple(p)))
            parent = name
            if k < 3:
                d, length = bones[k]
                d = np.array(d) / np.linalg.norm(d)
                p = p + length * d
    return out


def _joint_table() -> list[tuple[str, str | None, np.ndarray]]:
    """(short name, parent short name, world rest position) in parents-first order."""
    table = [(n, p, np.array(x, float)) for n, p, x in _CENTRE]
    left_arm = _left_joints()
    for side in ("Left", "Right"):
        for n, p, x in left_arm:
            x = np.array(x, float)
            if side == "Right":
                n, p, x = mirror_name(n), mirror_name(p), x * [-1, 1, 1]
            table.append((n, p, x))
    for side in ("Left", "Right"):
        for n, p, x in _LEG:
            x = np.array(x, float)
            if side == "Right":
                n, p, x = mirror_name(n), mirror_name(p), x * [-1, 1, 1]
            table.append((n, p, x))
    return table


def _frame(y_dir: np.ndarray, z_hint: np.ndarray) -> np.ndarray:
    """Rotation matrix (columns X, Y, Z) with Y along ``y_dir`` and Z near ``z_hint``."""
    y = y_dir / np.linalg.norm(y_dir)
    z = z_hint - np.dot(z_hint, y) * y
    z = z / np.linalg.norm(z)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=1)


def _z_hint(name: str) -> np.ndarray:
    """The Z-axis hint of a joint's frame for the left side (mirrored for the right)."""
    short = name.replace("Right", "Left")
    if "Thumb" in short:
        return np.array(_THUMB_CURL)
    if short.startswith("LeftHand"):
        return np.array([0.0, -1.0, 0.0])  # palm normal, out of the palm
    if "Leg" in short:
        return np.array([0.0, 0.0, -1.0])
    if "Foot" in short or "Toe" in short:
        return np.array([0.0, 1.0, 0.0])
    return np.array([0.0, 0.0, 1.0])


def _main_child(name: str, children: dict[str, list[str]]) -> str | None:
    kids = children.get(name, [])
    if not kids:
        return None
    preferred = {"Hips": "Spine", "Spine2": "Neck", "LeftHand": "LeftHandMiddle1", "RightHand": "RightHandMiddle1"}
    return preferred.get(name, kids[0])


def _rest_frames() -> tuple[list[str], list[str | None], np.ndarray, np.ndarray]:
    """Short names, parent short names, world rest rotation matrices (J,3,3), positions (J,3)."""
    table = _joint_table()
    names = [t[0] for t in table]
    parents = [t[1] for t in table]
    pos = {n: x for n, _, x in table}
    children: dict[str, list[str]] = {}
    for n, p, _ in table:
        if p is not None:
            children.setdefault(p, []).append(n)
    rots = {}
    for n, p, x in table:
        child = _main_child(n, children)
        if n == "Hips":
            r = np.eye(3)
        elif child is None:  # end joints take their parent's frame
            r = rots[p]
        else:
            mirror = n.startswith("Right")
            zh = _z_hint(n) * ([-1, 1, 1] if mirror else 1)
            r = _frame(pos[child] - x, zh)
        rots[n] = r
    R = np.stack([rots[n] for n in names])
    P = np.stack([pos[n] for n in names])
    return names, parents, R, P


def _joint_paths(names: list[str], parents: list[str | None]) -> list[str]:
    paths: dict[str, str] = {}
    for n, p in zip(names, parents):
        paths[n] = n if p is None else f"{paths[p]}/{n}"
    return [paths[n] for n in names]


@lru_cache(maxsize=1)
def humanoid_skeleton() -> Skeleton:
    """The sample humanoid's skeleton: 65 joints, centimetres, Y up, T-pose rest.

    Returns
    -------
    Skeleton
        Joint names are USD joint paths (``"Hips/Spine/Spine1/Spine2/LeftShoulder"``);
        ``bind_xforms`` equal the rest pose's world transforms. The same (immutable)
        object on every call, so every generated clip shares it.
    """
    names, parents, R, P = _rest_frames()
    idx = {n: i for i, n in enumerate(names)}
    J = len(names)
    par = np.array([-1 if p is None else idx[p] for p in parents], dtype=np.int64)
    t_local = np.zeros((J, 3))
    r_local = np.zeros((J, 3, 3))
    for j in range(J):
        p = par[j]
        if p < 0:
            t_local[j] = P[j]
            r_local[j] = R[j]
        else:
            t_local[j] = R[p].T @ (P[j] - P[p])
            r_local[j] = R[p].T @ R[j]
    bind = np.tile(np.eye(4), (J, 1, 1))
    bind[:, :3, :3] = R
    bind[:, :3, 3] = P
    q = matrix_to_quat(r_local)
    q = np.where(q[:, 3:4] < 0, -q, q)
    return Skeleton(_joint_paths(names, parents), par, t_local, q, None, bind,
                    meters_per_unit=0.01, up_axis="Y", name=SKELETON_NAME)


def joint_index(skeleton: Skeleton, short: str) -> int:
    """Index of a joint by its short (Mixamo) name."""
    return skeleton.index(short)


def finger_joint_indices(skeleton: Skeleton, side: str, include_ends: bool = False) -> list[int]:
    """Indices of one hand's finger joints (thumb to pinky, proximal to distal).

    Parameters
    ----------
    side : {"left", "right"}
    include_ends : bool
        Whether to include the tip end joints (``LeftHandIndex4``), which carry no DOF.
    """
    if side not in ("left", "right"):
        raise ValueError(f"Expected side 'left' or 'right', got {side!r}")
    prefix = "LeftHand" if side == "left" else "RightHand"
    n = 4 if include_ends else 3
    return [skeleton.index(f"{prefix}{f}{k + 1}") for f in FINGER_NAMES for k in range(n)]


def humanoid_handmap(skeleton: Skeleton | None = None) -> HandMap:
    """The hand map of the sample humanoid (end joints left out, as in :class:`HandSide`)."""
    sk = skeleton or humanoid_skeleton()
    name = lambda short: sk.joint_names[sk.index(short)]
    sides = {}
    for side, pre in (("left", "Left"), ("right", "Right")):
        sides[side] = HandSide(
            side, wrist=name(f"{pre}Hand"), forearm=name(f"{pre}ForeArm"), shoulder=name(f"{pre}Arm"),
            root=name("Hips"),
            fingers={f.lower(): tuple(name(f"{pre}Hand{f}{k + 1}") for k in range(3)) for f in FINGER_NAMES})
    return HandMap(**sides)


# ---------------------------------------------------------------------------- mesh

# (joint, local y from, local y to (None: to the main child), width along local X,
#  depth along local Z); lengths in cm in the joint's frame.
def _parts(names: list[str]) -> list[tuple[str, float, float | None, float, float]]:
    parts = [
        ("Hips", -9.0, 10.0, 30.0, 20.0),
        ("Spine", 0.0, None, 28.0, 19.0),
        ("Spine1", 0.0, None, 30.0, 20.0),
        ("Spine2", 0.0, None, 34.0, 21.0),
        ("Neck", 0.0, None, 10.0, 10.0),
        ("Head", -1.0, 17.0, 15.0, 19.0),
    ]
    for side in ("Left", "Right"):
        parts += [
            (f"{side}Shoulder", 0.0, None, 9.0, 9.0),
            (f"{side}Arm", 0.0, None, 9.0, 9.0),
            (f"{side}ForeArm", 0.0, None, 7.5, 6.5),
            (f"{side}Hand", 0.0, None, 8.5, 3.0),
        ]
        for f in FINGER_NAMES:
            w = 2.0 if f == "Thumb" else 1.7
            for k in range(3):
                parts.append((f"{side}Hand{f}{k + 1}", 0.0, None, w - 0.15 * k, w - 0.2 - 0.15 * k))
        parts += [
            (f"{side}UpLeg", 0.0, None, 15.0, 15.0),
            (f"{side}Leg", 0.0, None, 11.0, 11.0),
            (f"{side}Foot", -3.0, None, 9.0, 8.0),
            (f"{side}ToeBase", 0.0, None, 9.0, 4.0),
        ]
    return [p for p in parts if p[0] in names]


def _distal_influences(short: str, children: list[str]) -> list[tuple[str, float]]:
    """Extra influences of a part's distal vertices: (joint, weight), own joint excluded."""
    side = "Left" if short.startswith("Left") else "Right"
    if short == "Spine2":
        return [("Neck", 0.15), ("LeftShoulder", 0.15), ("RightShoulder", 0.15), ("Spine1", 0.1)]
    if short == "Hips":
        return [("Spine", 0.3)]
    if short.endswith("Hand") and short in ("LeftHand", "RightHand"):
        return [(f"{side}Hand{f}1", 0.12) for f in ("Index", "Middle", "Ring", "Pinky")]
    if len(children) == 1 and not children[0].endswith(("4", "_End")):
        return [(children[0], 0.35)]
    return []


def _proximal_influences(short: str, parent: str | None) -> list[tuple[str, float]]:
    if short == "Hips":
        return [("LeftUpLeg", 0.2), ("RightUpLeg", 0.2)]
    if short in ("LeftArm", "RightArm", "LeftUpLeg", "RightUpLeg", "LeftForeArm", "RightForeArm", "Neck"):
        return [(parent, 0.25)]
    return []


def humanoid_mesh(skeleton: Skeleton | None = None) -> SkinnedMesh:
    """A skinned box-per-bone body for the humanoid.

    Each bone gets a box of 8 vertices along its local +Y axis, in bind (rest world)
    space; proximal vertices are bound to the bone (and some to its parent), distal
    vertices shared with the child bone. The chest and the palms use 5 influences per
    vertex, to exercise writers past glTF's four-per-set limit.

    Returns
    -------
    SkinnedMesh
        Triangles; ``points (V, 3)`` cm, ``normals (V, 3)``, ``uvs (V, 2)``,
        ``joint_indices`` / ``joint_weights (V, 5)`` (unused slots have weight 0).
    """
    sk = skeleton or humanoid_skeleton()
    shorts = list(sk.short_names)
    idx = {n: i for i, n in enumerate(shorts)}
    bind = sk.bind_xforms if sk.bind_xforms is not None else sk.rest_world_xforms()
    world = sk.rest_world_positions()
    parts = _parts(shorts)
    K = 5
    points, normals, uvs, jidx, jw, faces = [], [], [], [], [], []
    corners = np.array([[sx, sy, sz] for sy in (0, 1) for sx in (-1, 1) for sz in (-1, 1)], float)
    # quads of the box by corner index (corner = 4*sy + 2*(sx>0) + (sz>0))
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    nparts = len(parts)
    for b, (short, y0, y1, w, d) in enumerate(parts):
        j = idx[short]
        kids = [shorts[c] for c in sk.children(j)]
        if y1 is None:
            child = _main_child(short, {short: kids})
            m = bind[j]
            y1 = float((m[:3, :3].T @ (world[idx[child]] - m[:3, 3]))[1])
        base = len(points)
        center = np.array([0.0, 0.5 * (y0 + y1), 0.0])
        half = np.array([w / 2, 0.5 * (y1 - y0), d / 2])
        for sx, sy, sz in corners:
            local = np.array([sx * w / 2, y0 if sy == 0 else y1, sz * d / 2])
            points.append(bind[j][:3, :3] @ local + bind[j][:3, 3])
            nl = (local - center) / half ** 2
            n = bind[j][:3, :3] @ nl
            normals.append(n / np.linalg.norm(n))
            uvs.append(((b + 0.25 + 0.5 * (sx > 0) + 0.2 * (sz > 0)) / nparts, float(sy)))
            infl = [(short, 1.0)]
            extra = _distal_influences(short, kids) if sy == 1 else _proximal_influences(
                short, shorts[sk.parents[j]] if sk.parents[j] >= 0 else None)
            extra = [(n_, w_) for n_, w_ in extra if n_ in idx]
            infl[0] = (short, 1.0 - sum(w_ for _, w_ in extra))
            infl += extra
            ji = [idx[n_] for n_, _ in infl] + [0] * (K - len(infl))
            wi = [w_ for _, w_ in infl] + [0.0] * (K - len(infl))
            jidx.append(ji)
            jw.append(wi)
        for q in quads:
            a, bq, c, dq = (base + i for i in q)
            for tri in ((a, bq, c), (a, c, dq)):
                p0, p1, p2 = (points[i] for i in tri)
                n = np.cross(p1 - p0, p2 - p0)
                centre_w = bind[j][:3, :3] @ center + bind[j][:3, 3]
                if np.dot(n, (p0 + p1 + p2) / 3 - centre_w) < 0:
                    tri = (tri[0], tri[2], tri[1])
                faces.append(tri)
    faces = np.array(faces, dtype=np.int32)
    return SkinnedMesh(
        name=MESH_NAME,
        points=np.array(points),
        face_vertex_counts=np.full(len(faces), 3, dtype=np.int32),
        face_vertex_indices=faces.reshape(-1),
        normals=np.array(normals),
        uvs=np.array(uvs),
        joint_indices=np.array(jidx, dtype=np.int32),
        joint_weights=np.array(jw),
        geom_bind_xform=np.eye(4),
        skeleton_index=0,
    )

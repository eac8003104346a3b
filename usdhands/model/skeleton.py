"""The joint hierarchy of a character: names, parents, rest and bind transforms."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from usdhands.model.rotations import check_quat, quat_normalize, trs_to_xform

__all__ = ["Skeleton", "short_joint_name", "display_joint_names", "readonly"]


def readonly(a: np.ndarray, dtype=np.float64) -> np.ndarray:
    """A read-only, C-contiguous copy of ``a`` with the given dtype (a broadcast made a copy in another
    layout, which every later clip copied again)."""
    out = np.array(a, dtype=dtype, copy=True, order="C")
    out.setflags(write=False)
    return out


def short_joint_name(name: str) -> str:
    """Last path element of a USD-style joint path (``"Hips/Spine/Chest"`` → ``"Chest"``)."""
    return name.rsplit("/", 1)[-1]


def display_joint_names(joint_names) -> dict[str, str]:
    """For printing: each joint's short name where it names that joint alone, else its full name.

    A short name is kept when no other joint has the same short name and none is called
    that in full (the names :meth:`Skeleton.index` takes back to the same joint).
    """
    names = list(joint_names)
    counts: dict[str, int] = {}
    for n in names:
        counts[short_joint_name(n)] = counts.get(short_joint_name(n), 0) + 1
    full = set(names)
    out = {}
    for n in names:
        sn = short_joint_name(n)
        out[n] = sn if counts[sn] == 1 and (sn == n or sn not in full) else n
    return out


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy with rest (local) and optional bind (world) transforms.

    Parameters
    ----------
    joint_names : sequence of str, length J
        Joint names; USD-style paths (``"Hips/Spine"``) where the source has them.
        Unique.
    parents : (J,) int
        Parent index of each joint, -1 for roots; parents come before children.
    rest_translations : (J, 3) float
        Local rest translations, asset units.
    rest_rotations : (J, 4) float
        Local rest rotations, unit quaternions xyzw.
    rest_scales : (J, 3) float, optional
        Local rest scales; ones when omitted.
    bind_xforms : (J, 4, 4) float, optional
        World-space bind transforms (column vectors) where the source has them.
    meters_per_unit : float
        Metres per asset unit (0.01 for centimetres).
    up_axis : {"Y", "Z"}
        The asset's up axis.
    name : str
        Name or prim path of the skeleton in its file.
    """

    joint_names: tuple[str, ...]
    parents: np.ndarray
    rest_translations: np.ndarray
    rest_rotations: np.ndarray
    rest_scales: np.ndarray | None = None
    bind_xforms: np.ndarray | None = None
    meters_per_unit: float = 1.0
    up_axis: str = "Y"
    name: str = "Skeleton"
    _index: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.joint_names)
        J = len(names)
        parents = np.asarray(self.parents)
        if parents.shape != (J,):
            raise ValueError(f"Expected parents to have shape ({J},), got {parents.shape}")
        parents = parents.astype(np.int64)
        bad = np.flatnonzero((parents >= np.arange(J)) | (parents < -1))
        if len(bad):
            j = int(bad[0])
            raise ValueError(f"Joint {j} ({names[j]!r}) has parent {parents[j]}; parents must come before children")
        if len(set(names)) != J:
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"Joint names must be unique, repeated: {dup}")
        t = np.asarray(self.rest_translations, dtype=np.float64)
        if t.shape != (J, 3):
            raise ValueError(f"Expected rest_translations to have shape ({J}, 3), got {t.shape}")
        q = check_quat(self.rest_rotations, "rest_rotations")
        if q.shape != (J, 4):
            raise ValueError(f"Expected rest_rotations to have shape ({J}, 4), got {q.shape}")
        q = quat_normalize(q) if J else q
        s = np.ones((J, 3)) if self.rest_scales is None else np.asarray(self.rest_scales, dtype=np.float64)
        if s.shape != (J, 3):
            raise ValueError(f"Expected rest_scales to have shape ({J}, 3), got {s.shape}")
        b = self.bind_xforms
        if b is not None:
            b = np.asarray(b, dtype=np.float64)
            if b.shape != (J, 4, 4):
                raise ValueError(f"Expected bind_xforms to have shape ({J}, 4, 4), got {b.shape}")
            b = readonly(b)
        if self.up_axis not in ("Y", "Z"):
            raise ValueError(f"Expected up_axis 'Y' or 'Z', got {self.up_axis!r}")
        if not (self.meters_per_unit > 0):
            raise ValueError(f"Expected meters_per_unit > 0, got {self.meters_per_unit}")
        set_ = object.__setattr__
        set_(self, "joint_names", names)
        set_(self, "parents", readonly(parents, np.int64))
        set_(self, "rest_translations", readonly(t))
        set_(self, "rest_rotations", readonly(q))
        set_(self, "rest_scales", readonly(s))
        set_(self, "bind_xforms", b)
        set_(self, "meters_per_unit", float(self.meters_per_unit))
        index = {}
        for i, n in enumerate(names):
            index[n] = i
        shorts: dict[str, int] = {}
        for i, n in enumerate(names):
            sn = short_joint_name(n)
            shorts[sn] = -1 if sn in shorts else i  # -1: ambiguous, reachable by full name only
        for sn, i in shorts.items():
            if i >= 0 and sn not in index:
                index[sn] = i
        set_(self, "_index", index)

    @property
    def num_joints(self) -> int:
        """Number of joints J."""
        return len(self.joint_names)

    @property
    def short_names(self) -> tuple[str, ...]:
        """Last path element of every joint name."""
        return tuple(short_joint_name(n) for n in self.joint_names)

    def index(self, name: str) -> int:
        """Index of a joint by full name or, where unambiguous, its short name.

        Raises
        ------
        KeyError
            Naming the joint that was asked for.
        """
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"No joint named {name!r} in skeleton {self.name!r}") from None

    def has_joint(self, name: str) -> bool:
        """Whether :meth:`index` would find ``name``."""
        return name in self._index

    def children(self, j: int) -> list[int]:
        """Indices of the direct children of joint ``j``."""
        return [int(i) for i in np.nonzero(self.parents == j)[0]]

    def chain_to_root(self, j: int) -> list[int]:
        """Indices from joint ``j`` up to its root, ``j`` first."""
        out = []
        while j >= 0:
            out.append(int(j))
            j = int(self.parents[j])
        return out

    def rest_local_xforms(self) -> np.ndarray:
        """Local rest transforms ``(J, 4, 4)``."""
        return trs_to_xform(self.rest_translations, self.rest_rotations, self.rest_scales)

    def rest_world_xforms(self) -> np.ndarray:
        """World rest transforms ``(J, 4, 4)`` by forward kinematics of the rest pose.

        Computed once per skeleton (its arrays are read-only); each call returns a copy.
        """
        rest = self.__dict__.get("_rest_world")
        if rest is None:
            rest = readonly(forward_kinematics(self.parents, self.rest_local_xforms()[None])[0])
            object.__setattr__(self, "_rest_world", rest)
        return rest.copy()

    def rest_world_positions(self) -> np.ndarray:
        """World rest positions ``(J, 3)``, asset units."""
        return self.rest_world_xforms()[:, :3, 3]

    def with_meters_per_unit(self, meters_per_unit: float) -> "Skeleton":
        """The same skeleton expressed in other units (translations rescaled)."""
        f = self.meters_per_unit / float(meters_per_unit)
        bind = None
        if self.bind_xforms is not None:
            bind = np.array(self.bind_xforms)
            bind[:, :3, 3] *= f
        return Skeleton(
            self.joint_names, self.parents, self.rest_translations * f, self.rest_rotations,
            self.rest_scales, bind, meters_per_unit, self.up_axis, self.name,
        )

    def subset(self, joints: list[int]) -> "Skeleton":
        """A skeleton of the given joints (sorted), re-parented to their nearest kept ancestor."""
        keep = sorted(set(int(j) for j in joints))
        remap = {old: new for new, old in enumerate(keep)}
        parents = []
        for j in keep:
            p = int(self.parents[j])
            while p >= 0 and p not in remap:
                p = int(self.parents[p])
            parents.append(remap.get(p, -1))
        bind = None if self.bind_xforms is None else self.bind_xforms[keep]
        return Skeleton(
            [self.joint_names[j] for j in keep], np.array(parents, dtype=np.int64),
            self.rest_translations[keep], self.rest_rotations[keep], self.rest_scales[keep],
            bind, self.meters_per_unit, self.up_axis, self.name,
        )


def forward_kinematics(parents: np.ndarray, local_xforms: np.ndarray) -> np.ndarray:
    """World transforms from local ones.

    Parameters
    ----------
    parents : (J,) int
        Parent indices, -1 for roots, parents before children.
    local_xforms : (T, J, 4, 4) float
        Local transforms per frame.

    Returns
    -------
    (T, J, 4, 4) float
        World transforms.
    """
    local_xforms = np.asarray(local_xforms, dtype=np.float64)
    world = np.empty_like(local_xforms)
    for j, p in enumerate(parents):
        if p < 0:
            world[:, j] = local_xforms[:, j]
        else:
            world[:, j] = world[:, p] @ local_xforms[:, j]
    return world

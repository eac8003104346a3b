"""Which joints of a skeleton are the hands: wrist, arm, root and five finger chains."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["FINGERS", "SIDES", "HandSide", "HandMap"]

FINGERS: tuple[str, ...] = ("thumb", "index", "middle", "ring", "pinky")
SIDES: tuple[str, ...] = ("left", "right")


@dataclass(frozen=True)
class HandSide:
    """The joints of one hand, by name as they stand in the skeleton.

    Parameters
    ----------
    side : {"left", "right"}
    wrist : str
        The hand (wrist) joint, or the joint the fingers hang from on rigs without one.
    forearm : str or None
        The forearm (elbow) joint.
    shoulder : str or None
        The upper-arm (shoulder) joint.
    root : str or None
        The body root (hips).
    fingers : dict of str to tuple of str
        For each of :data:`FINGERS`, the joints that carry the finger's DOFs, proximal
        to distal (metacarpals included where the rig has them, leaf end joints not);
        an absent finger is an empty tuple.
    """

    side: str
    wrist: str
    forearm: str | None = None
    shoulder: str | None = None
    root: str | None = None
    fingers: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.side not in SIDES:
            raise ValueError(f"Expected side 'left' or 'right', got {self.side!r}")
        unknown = set(self.fingers) - set(FINGERS)
        if unknown:
            raise ValueError(f"Unknown finger names {sorted(unknown)}; expected {FINGERS}")
        fingers = {f: tuple(self.fingers.get(f, ())) for f in FINGERS}
        object.__setattr__(self, "fingers", fingers)

    @property
    def finger_joints(self) -> tuple[str, ...]:
        """All finger joints, finger by finger (thumb first), proximal to distal."""
        return tuple(j for f in FINGERS for j in self.fingers[f])

    @property
    def present_fingers(self) -> tuple[str, ...]:
        """Fingers with at least one joint."""
        return tuple(f for f in FINGERS if self.fingers[f])

    def to_dict(self) -> dict:
        """JSON-ready dict (the layout of ``schemas/handmap.schema.json``)."""
        return {
            "wrist": self.wrist,
            "forearm": self.forearm,
            "shoulder": self.shoulder,
            "root": self.root,
            "fingers": {f: list(self.fingers[f]) for f in FINGERS},
        }

    @classmethod
    def from_dict(cls, side: str, d: dict) -> "HandSide":
        """Inverse of :meth:`to_dict`."""
        return cls(side=side, wrist=d["wrist"], forearm=d.get("forearm"),
                   shoulder=d.get("shoulder"), root=d.get("root"),
                   fingers={f: tuple(v) for f, v in d.get("fingers", {}).items()})


@dataclass(frozen=True)
class HandMap:
    """The hands of one skeleton; a side without a hand is ``None``."""

    left: HandSide | None = None
    right: HandSide | None = None

    def __getitem__(self, side: str) -> HandSide | None:
        if side not in SIDES:
            raise KeyError(f"Expected side 'left' or 'right', got {side!r}")
        return self.left if side == "left" else self.right

    @property
    def sides(self) -> tuple[HandSide, ...]:
        """The hands present, left first."""
        return tuple(h for h in (self.left, self.right) if h is not None)

    def to_dict(self) -> dict:
        """JSON-ready dict: ``{"left": {...} or null, "right": {...} or null}``."""
        return {s: (None if self[s] is None else self[s].to_dict()) for s in SIDES}

    @classmethod
    def from_dict(cls, d: dict) -> "HandMap":
        """Inverse of :meth:`to_dict`."""
        return cls(**{s: (None if d.get(s) is None else HandSide.from_dict(s, d[s])) for s in SIDES})

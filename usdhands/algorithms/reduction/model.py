"""The reduction model: rebuild every finger curve from a few controlling curves.

A model (Jörg and O'Sullivan 2009, §4) says, for a set of finger DOF curves
(``"<joint>.<axis>"``, Euler degrees relative to rest, see
:mod:`usdhands.model.finger_dofs`):

- which curves are **constants** (irrelevant: their range was below a threshold;
  they take their mean),
- which curves are **dependent** (redundant): ``a = scale * b + offset``, a linear map
  of one **controlling** curve ``b``; ``scale = ±std(a) / std(b)`` and
  ``offset = mean(a) - scale * mean(b)``, which is the paper's
  ``a = ±(b - mean(b)) / std(b) * std(a) + mean(a)`` written so that it applies to any
  new ``b`` an animator keys,
- and which curves stay free (the controlling curves and the untouched ones).

Controlling curves are never dependent themselves (chains are resolved when the model
is built), so rebuilding is a single pass. The JSON layout is
``schemas/reduction_model.schema.json`` (shipped as
``usdhands/schemas/reduction_model.schema.json``).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from usdhands.errors import ConfigError
from usdhands.input_files import read_json
from usdhands.json_schemas import first_schema_error, load_schema

__all__ = ["Constant", "Relation", "ReductionModel", "MODEL_FORMAT", "MODEL_VERSION", "model_schema"]

MODEL_FORMAT = "usdhands.reduction_model"
MODEL_VERSION = 1
KINDS = ("rmsd1", "rmsd2")


@dataclass(frozen=True)
class Constant:
    """A curve replaced by a constant.

    Parameters
    ----------
    curve : str
        Curve name ``"<joint>.<axis>"``.
    value : float
        Degrees: the mean of the original curve.
    range : float
        Degrees: the original curve's range (max - min), for the record.
    """

    curve: str
    value: float
    range: float = 0.0

    def to_dict(self) -> dict:
        return {"curve": self.curve, "value": float(self.value), "range": float(self.range)}


@dataclass(frozen=True)
class Relation:
    """A dependent curve rebuilt from a controlling curve: ``dep = scale * ctrl + offset``.

    Parameters
    ----------
    dependent, controlling : str
        Curve names.
    kind : {"rmsd1", "rmsd2"}
        ``rmsd1``: positive slope (``scale > 0``); ``rmsd2``: negative slope, the
        controlling curve "inverted" (mirrored across the time axis).
    rmsd : float
        The distance between the two standardised original curves, of that kind. After
        chain resolution it can exceed the step's threshold (paper §5.2).
    scale, offset : float
        The linear map (offset in degrees).
    dependent_mean, dependent_std, controlling_mean, controlling_std : float
        Degrees: statistics of the original curves the map was made from (population
        standard deviation).
    """

    dependent: str
    controlling: str
    kind: str
    rmsd: float
    scale: float
    offset: float
    dependent_mean: float = 0.0
    dependent_std: float = 0.0
    controlling_mean: float = 0.0
    controlling_std: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"Expected kind 'rmsd1' or 'rmsd2', got {self.kind!r}")

    @classmethod
    def from_statistics(cls, dependent: str, controlling: str, kind: str, rmsd: float,
                        dependent_mean: float, dependent_std: float,
                        controlling_mean: float, controlling_std: float) -> "Relation":
        """The relation the paper's formulas give for these means and standard deviations."""
        if not controlling_std > 0:
            raise ValueError(f"Expected a positive controlling_std, got {controlling_std!r}")
        sign = 1.0 if kind == "rmsd1" else -1.0
        scale = sign * dependent_std / controlling_std
        offset = dependent_mean - scale * controlling_mean
        return cls(dependent, controlling, kind, float(rmsd), float(scale), float(offset),
                   float(dependent_mean), float(dependent_std), float(controlling_mean), float(controlling_std))

    def to_dict(self) -> dict:
        return {k: (float(v) if isinstance(v, (int, float, np.floating)) else v) for k, v in asdict(self).items()}


@dataclass(frozen=True)
class ReductionModel:
    """Constants and linear relations that rebuild a set of finger curves.

    Parameters
    ----------
    curves : tuple of str
        Every curve the model covers, in order.
    constants : tuple of Constant
    relations : tuple of Relation
    order : str
        Intrinsic Euler order of the curves (``"XYZ"``).
    condition : str
        The simplification the model was made with (``"range < 5 + rmsd < 0.5"``).
    source : str
        Where it was made from (a file name), for the record.
    means : dict of str to float
        Mean (degrees) of each curve the model was made from, for the curves it knows;
        they pick the Euler branch when curves are read back from rotations
        (:func:`~usdhands.algorithms.reduction.reduce.align_euler_branches`).
    """

    curves: tuple[str, ...]
    constants: tuple[Constant, ...] = ()
    relations: tuple[Relation, ...] = ()
    order: str = "XYZ"
    condition: str = ""
    source: str = ""
    metadata: dict = field(default_factory=dict)
    means: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "curves", tuple(self.curves))
        object.__setattr__(self, "means", {str(k): float(v) for k, v in dict(self.means).items()})
        object.__setattr__(self, "constants", tuple(self.constants))
        object.__setattr__(self, "relations", tuple(self.relations))
        known = set(self.curves)
        if len(known) != len(self.curves):
            dup = sorted({c for c in self.curves if self.curves.count(c) > 1})
            raise ValueError(f"Duplicate curve names {dup}")
        seen: set[str] = set()
        for c in self.constants:
            if c.curve not in known:
                raise ValueError(f"Constant curve {c.curve!r} is not among the model's curves")
            if c.curve in seen:
                raise ValueError(f"Curve {c.curve!r} is rebuilt twice")
            seen.add(c.curve)
        for r in self.relations:
            for name in (r.dependent, r.controlling):
                if name not in known:
                    raise ValueError(f"Relation curve {name!r} is not among the model's curves")
            if r.dependent in seen:
                raise ValueError(f"Curve {r.dependent!r} is rebuilt twice")
            seen.add(r.dependent)
        if not set(self.means) <= known:
            raise ValueError(f"Means of curves {sorted(set(self.means) - known)[:3]} that are not among the model's")
        for r in self.relations:
            if r.controlling in seen:
                raise ValueError(f"Controlling curve {r.controlling!r} is itself rebuilt; chains must be resolved")

    # ------------------------------------------------------------------ queries
    @property
    def dependent_curves(self) -> tuple[str, ...]:
        """Curves rebuilt from a controlling curve."""
        return tuple(r.dependent for r in self.relations)

    @property
    def constant_curves(self) -> tuple[str, ...]:
        """Curves replaced by a constant."""
        return tuple(c.curve for c in self.constants)

    @property
    def free_curves(self) -> tuple[str, ...]:
        """Curves kept as they are: the DOFs left (controlling curves among them)."""
        rebuilt = set(self.dependent_curves) | set(self.constant_curves)
        return tuple(c for c in self.curves if c not in rebuilt)

    @property
    def controlling_curves(self) -> tuple[str, ...]:
        """Free curves that control at least one dependent curve, in curve order."""
        ctrl = {r.controlling for r in self.relations}
        return tuple(c for c in self.curves if c in ctrl)

    @property
    def dofs_left(self) -> int:
        """Number of free curves."""
        return len(self.free_curves)

    def subset(self, curves) -> "ReductionModel":
        """The model restricted to ``curves``: their constants and the relations rebuilding them.

        Parameters
        ----------
        curves : iterable of str
            Curve names to keep (names not in the model are ignored).

        Raises
        ------
        ValueError
            A kept dependent curve's controlling curve is not kept (quoting both).
        """
        keep = set(curves)
        for r in self.relations:
            if r.dependent in keep and r.controlling not in keep:
                raise ValueError(f"Curve {r.dependent!r} is rebuilt from {r.controlling!r}, which is not kept")
        return replace(self, curves=tuple(c for c in self.curves if c in keep),
                       constants=tuple(c for c in self.constants if c.curve in keep),
                       relations=tuple(r for r in self.relations if r.dependent in keep),
                       means={c: v for c, v in self.means.items() if c in keep})

    # ------------------------------------------------------------------ rebuilding
    def apply(self, values: np.ndarray, names: list[str] | tuple[str, ...] | None = None) -> np.ndarray:
        """Rebuild the constant and dependent curves from the free ones.

        Parameters
        ----------
        values : (T, D) float
            Degrees; column ``k`` is curve ``names[k]``. Only the columns of free
            (controlling) curves are read.
        names : sequence of str, length D, optional
            Curve names of the columns (default: :attr:`curves`). Must include every
            curve of the model; extra columns are passed through.

        Returns
        -------
        (T, D) float64
            A new array: constants and dependent curves replaced, the rest copied.
        """
        v = np.asarray(values, dtype=np.float64)
        names = self.curves if names is None else tuple(names)
        if v.ndim != 2 or v.shape[1] != len(names):
            raise ValueError(f"Expected values to have shape (T, {len(names)}), got {v.shape}")
        col = {n: k for k, n in enumerate(names)}
        missing = [c for c in self.curves if c not in col]
        if missing:
            raise ValueError(f"Curves {missing} of the model are not among the given names")
        out = v.copy()
        for c in self.constants:
            out[:, col[c.curve]] = c.value
        if self.relations:
            dep = np.array([col[r.dependent] for r in self.relations])
            ctrl = np.array([col[r.controlling] for r in self.relations])
            scale = np.array([r.scale for r in self.relations])
            offset = np.array([r.offset for r in self.relations])
            out[:, dep] = v[:, ctrl] * scale + offset
        return out

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict:
        """JSON-ready dict in the layout of ``reduction_model.schema.json``."""
        return {
            "format": MODEL_FORMAT,
            "version": MODEL_VERSION,
            "euler_order": self.order,
            "condition": self.condition,
            "source": self.source,
            "curves": list(self.curves),
            "controlling": list(self.controlling_curves),
            "free": list(self.free_curves),
            "constants": [c.to_dict() for c in self.constants],
            "relations": [r.to_dict() for r in self.relations],
            **({"means": dict(self.means)} if self.means else {}),
            "metadata": dict(self.metadata),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "ReductionModel":
        """Inverse of :meth:`to_dict` (no schema check: see :meth:`load`)."""
        return cls(
            curves=tuple(d["curves"]),
            constants=tuple(Constant(c["curve"], float(c["value"]), float(c.get("range", 0.0)))
                            for c in d.get("constants", [])),
            relations=tuple(Relation(**{k: r[k] for k in r}) for r in d.get("relations", [])),
            order=d.get("euler_order", "XYZ"),
            condition=d.get("condition", ""),
            source=d.get("source", ""),
            metadata=dict(d.get("metadata", {})),
            means=dict(d.get("means", {})),
        )

    def save(self, path: str | os.PathLike) -> Path:
        """Write the model as JSON (atomically: a temporary file of a name no other file has, then a rename;
        a fixed ``NAME.tmp`` overwrote, then removed, a user's file of that name)."""
        import secrets

        path = Path(path)
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}")
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # never an existing file; the umask's mode
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(json.dumps(self.to_dict(), indent=2) + "\n")
            os.replace(tmp, path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> "ReductionModel":
        """Read a model JSON file, validated against the schema.

        Raises
        ------
        ConfigError
            Missing file, not JSON, not a valid model (the message names the first
            problem and where it is).
        """

        path = Path(path)
        d = read_json(path, what="reduction model file", error=ConfigError)
        error = first_schema_error(d, "reduction_model")
        if error is not None:
            where, message = error
            raise ConfigError(f"not a valid reduction model: {message}", path=path, location=where)
        try:
            model = cls.from_dict(d)
        except ValueError as e:
            raise ConfigError(f"not a valid reduction model: {e}", path=path) from None
        for r in model.relations:
            if not (math.isfinite(r.scale) and math.isfinite(r.offset)):
                raise ConfigError(f"relation of {r.dependent!r} has a non-finite scale or offset", path=path)
            if not (abs(r.scale) <= MAX_COEFFICIENT and abs(r.offset) <= MAX_COEFFICIENT):
                # a scale of 1e308 overflowed in expand, and the error then named the output
                raise ConfigError(f"relation of {r.dependent!r} has scale {r.scale:g} / offset {r.offset:g} beyond "
                                  f"{MAX_COEFFICIENT:g}", path=path)
        for c in model.constants:  # NaN passed and expand silently kept the input's curve
            if not math.isfinite(c.value):
                raise ConfigError(f"constant {c.curve!r} has a non-finite value {c.value}", path=path)
        for curve, mean in model.means.items():
            if not math.isfinite(float(mean)):
                raise ConfigError(f"mean of {curve!r} is not finite ({mean})", path=path)
        return model


#: Largest |scale| and |offset| (degrees) of a relation read from a file: far past any fit of
#: finger curves, small enough that rebuilt angles stay finite.
MAX_COEFFICIENT = 1e6


def model_schema() -> dict:
    """The JSON schema of a reduction model file (the copy shipped in the package)."""
    return load_schema("reduction_model")

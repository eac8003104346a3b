"""Every weight and threshold of finger-motion synthesis, with the paper's defaults.

The values come from Jörg, Hodgins and Safonova 2012 (seed 000, §3): segments of
0.33 s to 2 s cut where the wrist speed crosses a threshold near zero, the segment
cost of eq. 1 (``wP = 1``, ``wR = 0.5``, length within a factor 1.5, ``k = 5``; other
arm features with ``segment_cost.features``, see
:mod:`~usdhands.algorithms.synthesis.feature_sets`), the
transition cost of eq. 2 (``wJ = 1``, ``wW = 0.5``), the path cost of eq. 3
(``wS = 1``, ``wT = 0.5``, each term divided by its mean over the candidates so the
weights mean what the paper says: see docs/synthesis.md) and seam blending past 5° mean
or 20° maximum difference.
The paper leaves a few values open; ours are marked in the schema
(``schemas/synthesis_config.schema.json``) and in docs/synthesis.md.

A configuration file is JSON with the same nesting as :meth:`SynthesisConfig.to_dict`;
omitted keys keep their defaults.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

from usdhands.errors import ConfigError
from usdhands.input_files import read_json
from usdhands.json_schemas import first_schema_error, load_schema

__all__ = [
    "SegmentationConfig", "SegmentCostConfig", "TransitionConfig", "PathConfig",
    "StitchingConfig", "SynthesisConfig", "load_synthesis_config", "config_schema",
]


@dataclass(frozen=True)
class SegmentationConfig:
    """Segmentation by wrist speed (§3.1)."""

    speed_threshold_cm_s: float = 8.0
    min_segment_s: float = 0.33
    max_segment_s: float = 2.0
    speed_smoothing_s: float = 0.1


@dataclass(frozen=True)
class SegmentCostConfig:
    """Segment cost, eq. 1 (§3.2)."""

    w_position: float = 1.0
    w_rotation: float = 0.5
    length_factor: float = 1.5
    dtw_band: float = 0.3
    k: int = 5
    lower_bound: str = "kim"
    features: str | None = None

    def __post_init__(self) -> None:
        if self.lower_bound not in ("kim", "keogh", "none"):
            raise ValueError(f"Expected lower_bound 'kim', 'keogh' or 'none', got {self.lower_bound!r}")
        if self.features is not None:
            from usdhands.algorithms.synthesis.feature_sets import parse_feature_set

            if not isinstance(self.features, str):
                raise ValueError(f"Expected features to be a feature set such as 'wrist_pos+0.5rot', "
                                 f"got {self.features!r}")
            parse_feature_set(self.features)  # says which term does not parse


@dataclass(frozen=True)
class TransitionConfig:
    """Transition cost, eq. 2 (§3.3)."""

    w_joint: float = 1.0
    w_velocity: float = 0.5


@dataclass(frozen=True)
class PathConfig:
    """Path cost, eq. 3 (§3.4)."""

    w_segment: float = 1.0
    w_transition: float = 0.5
    normalize_terms: bool = True


@dataclass(frozen=True)
class StitchingConfig:
    """Seam offsets and blends (§3.5)."""

    blend_mean_deg: float = 5.0
    blend_max_deg: float = 20.0
    blend_duration_s: float = 0.5
    warp_smoothing_s: float = 0.2
    step_percentile: float = 99.5
    candidate_mix: float = 0.7

    def __post_init__(self) -> None:
        if not 0 <= self.candidate_mix <= 1:
            raise ValueError(f"Expected 0 <= candidate_mix <= 1, got {self.candidate_mix}")
        if not 0 < self.step_percentile <= 100:
            raise ValueError(f"Expected 0 < step_percentile <= 100, got {self.step_percentile}")
        if self.warp_smoothing_s < 0:
            raise ValueError(f"Expected warp_smoothing_s >= 0, got {self.warp_smoothing_s}")


_SECTIONS = {
    "segmentation": SegmentationConfig,
    "segment_cost": SegmentCostConfig,
    "transition": TransitionConfig,
    "path": PathConfig,
    "stitching": StitchingConfig,
}


@dataclass(frozen=True)
class SynthesisConfig:
    """All parameters of synthesis, grouped as in the paper's sections."""

    segmentation: SegmentationConfig = field(default_factory=SegmentationConfig)
    segment_cost: SegmentCostConfig = field(default_factory=SegmentCostConfig)
    transition: TransitionConfig = field(default_factory=TransitionConfig)
    path: PathConfig = field(default_factory=PathConfig)
    stitching: StitchingConfig = field(default_factory=StitchingConfig)

    def __post_init__(self) -> None:
        s = self.segmentation
        if s.max_segment_s < 2 * s.min_segment_s:
            raise ValueError(
                f"Expected max_segment_s >= 2 * min_segment_s so long segments can be split, "
                f"got {s.max_segment_s} and {s.min_segment_s}")

    def to_dict(self) -> dict:
        """JSON-ready nested dict (the layout of a configuration file)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "SynthesisConfig":
        """Build from a (possibly partial) nested dict; unknown keys raise ValueError."""
        if not isinstance(d, dict):
            raise TypeError(f"Expected a dict, got {type(d).__name__}")
        unknown = set(d) - set(_SECTIONS)
        if unknown:
            raise ValueError(f"Unknown configuration sections {sorted(unknown)}; expected {sorted(_SECTIONS)}")
        parts = {}
        for name, kind in _SECTIONS.items():
            sec = d.get(name, {})
            names = {f.name for f in fields(kind)}
            bad = set(sec) - names
            if bad:
                raise ValueError(f"Unknown keys {sorted(bad)} in section {name!r}; expected {sorted(names)}")
            if name == "segment_cost" and sec.get("features") is not None and {"w_position", "w_rotation"} & set(sec):
                raise ValueError("segment_cost.features names the weights of every term ('wrist_pos+0.5rot'): "
                                 "give it without w_position and w_rotation")
            parts[name] = kind(**sec)
        return cls(**parts)

    def with_values(self, **sections: dict) -> "SynthesisConfig":
        """A copy with some values changed: ``cfg.with_values(segment_cost={"k": 3})``."""
        parts = {}
        for name, changes in sections.items():
            if name not in _SECTIONS:
                raise ValueError(f"Unknown configuration section {name!r}; expected {sorted(_SECTIONS)}")
            parts[name] = replace(getattr(self, name), **changes)
        return replace(self, **parts)


def config_schema() -> dict:
    """The JSON schema of a configuration file (shipped in ``usdhands/schemas``)."""
    return load_schema("synthesis_config")


def load_synthesis_config(path: str | Path) -> SynthesisConfig:
    """Read and validate a configuration file.

    Raises
    ------
    ConfigError
        The file is missing, not JSON, or does not match the schema (the message
        names the offending key).
    """

    path = Path(path)
    data = read_json(path, what="configuration file", error=ConfigError)  # NaN, 5000-digit numbers refused
    error = first_schema_error(data, "synthesis_config")
    if error is not None:
        where, message = error
        raise ConfigError(f"invalid synthesis configuration at {where}: {message}", path=path)
    try:
        return SynthesisConfig.from_dict(data)
    except ValueError as e:
        raise ConfigError(str(e), path=path) from None

"""Checks of option values shared by the jobs: frame rates, seeds, comma-separated lists.

Each returns the value it was given (normalised) or raises a one-line UsdHandsError.
"""

from __future__ import annotations

from typing import Iterable

#: Highest frame rate a --fps option takes (motion capture runs at 120-480).
MAX_FPS = 1000.0


def check_fps(value: float | None, option: str = "--fps") -> float | None:
    """``value`` if it is a usable frame rate (or None), else a one-line UsdHandsError.

    0, negative, NaN and infinite rates were silently ignored, blamed on the input file
    ("malformed glTF"), raised tracebacks or ran out of memory (1e9).
    """
    if value is None:
        return None
    from usdhands.errors import UsdHandsError

    if not (value > 0 and value <= MAX_FPS):  # also refuses NaN
        raise UsdHandsError(f"{option} must be a frame rate above 0 and at most {MAX_FPS:g}, got {value:g}")
    return float(value)


def check_seed(value: int) -> int:
    """``value`` if it is a usable random seed (numpy takes integers >= 0), else a one-line UsdHandsError."""
    if value < 0:
        from usdhands.errors import UsdHandsError

        raise UsdHandsError(f"--seed must be 0 or more, got {value}")
    return value


def parse_list(text: str | None, allowed: Iterable[str] | None = None) -> list[str]:
    """Split ``"a,b"`` into ``["a", "b"]``, checking against ``allowed``."""
    if not text:
        return []
    items = [t.strip() for t in text.split(",") if t.strip()]
    if allowed is not None:
        allowed = list(allowed)
        bad = [i for i in items if i not in allowed]
        if bad:
            from usdhands.errors import UsdHandsError

            raise UsdHandsError(f"unknown value(s) {bad}; expected some of {allowed}")
    return items

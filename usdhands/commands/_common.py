"""Helpers shared by the subcommands: progress on stderr, tables, JSON output."""

from __future__ import annotations

import json
import sys
import time
from typing import Iterable, Sequence


class Progress:
    """A one-line progress display on stderr, shown only on a terminal or when forced.

    Use as a callback ``progress(done, total, label)``.
    """

    def __init__(self, label: str, *, enabled: bool | None = None, stream=None):
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self.label = label
        self._last = 0.0

    def __call__(self, done: int, total: int, what: str = "") -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if done < total and now - self._last < 0.1:
            return
        self._last = now
        pct = 100.0 * done / total if total else 100.0
        end = "\n" if done >= total else ""
        self.stream.write(f"\r{self.label}: {done}/{total} ({pct:3.0f}%) {what[:40]:<40}{end}")
        self.stream.flush()


def print_table(rows: Sequence[Sequence], headers: Sequence[str], stream=None) -> None:
    """Print rows as an aligned plain-text table."""
    stream = stream or sys.stdout
    cells = [[str(h) for h in headers]] + [[_fmt(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    for k, r in enumerate(cells):
        stream.write("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() + "\n")
        if k == 0:
            stream.write("  ".join("-" * w for w in widths) + "\n")


def _fmt(c) -> str:
    if isinstance(c, float):
        return f"{c:.4g}"
    return str(c)


def print_json(obj, stream=None) -> None:
    """Print ``obj`` as indented JSON."""
    stream = stream or sys.stdout
    json.dump(obj, stream, indent=2)
    stream.write("\n")


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

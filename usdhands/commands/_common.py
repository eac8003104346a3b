"""Helpers shared by the subcommands: progress on stderr, tables, JSON output."""

from __future__ import annotations

import contextlib
import json
import logging
import sys
import time
from typing import Iterable, Iterator, Sequence


_quiet = False


def set_quiet(quiet: bool) -> None:
    """``-q``: no progress display at all (the command line sets it on every run)."""
    global _quiet
    _quiet = bool(quiet)


def _bars_wanted(stream) -> bool:
    return not _quiet and hasattr(stream, "isatty") and stream.isatty()


class Progress:
    """A progress bar on stderr (tqdm) for the library's ``progress(done, total, label)`` callbacks.

    Drawn only when the stream is a terminal and ``-q`` was not given (or when forced with
    ``enabled``). Without a bar, ``-v`` logs each step instead (at most one line a second).
    The bar disappears when ``done`` reaches ``total``.
    """

    def __init__(self, label: str, *, enabled: bool | None = None, stream=None):
        self.stream = stream or sys.stderr
        self.enabled = _bars_wanted(self.stream) if enabled is None else enabled
        self.label = label
        self._bar = None
        self._logged = 0.0

    def __call__(self, done: int, total: int, what: str = "") -> None:
        if not self.enabled:
            self._log(done, total, what)
            return
        if self._bar is None:
            from tqdm import tqdm

            self._bar = tqdm(total=total, initial=done, postfix=what[:40], desc=self.label, file=self.stream,
                             leave=False, dynamic_ncols=True,
                             bar_format="{desc}: {n}/{total} {bar} {elapsed}<{remaining} {postfix}")
        bar = self._bar
        if bar.total != total:
            bar.total = total
        bar.set_postfix_str(what[:40], refresh=False)
        bar.update(done - bar.n)
        if done >= total:
            bar.close()
            self._bar = None

    def _log(self, done: int, total: int, what: str) -> None:
        if _quiet or not _log.isEnabledFor(logging.INFO):
            return
        now = time.monotonic()
        if done < total and now - self._logged < 1.0:
            return
        self._logged = now
        _log.info("%s: %d/%d %s", self.label, done, total, what)


_log = logging.getLogger("usdhands")


@contextlib.contextmanager
def compile_progress(stream=None) -> Iterator[None]:
    """Inside the block, a bar "compiling kernels, once" while numba compiles (first run only).

    Hears :func:`usdhands.jit.compile_listener`; numba itself is not imported here.
    """
    from usdhands.jit import compile_listener

    stream = stream or sys.stderr
    bar = None

    def on_compile(name: str) -> None:
        nonlocal bar
        if bar is None:
            if not _bars_wanted(stream):
                _log.info("compiling kernels, once (%s)", name)
                return
            from tqdm import tqdm

            bar = tqdm(desc="compiling kernels, once", unit="kernels", initial=1, postfix=name, file=stream,
                       leave=False, bar_format="{desc}: {n} {unit} {elapsed} {postfix}")
            return
        bar.set_postfix_str(name, refresh=False)
        bar.update(1)

    try:
        with compile_listener(on_compile):
            yield
    finally:
        if bar is not None:
            bar.close()


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

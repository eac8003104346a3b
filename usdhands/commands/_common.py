"""Helpers shared by the subcommands: progress on stderr, tables, JSON output."""

from __future__ import annotations

import contextlib
import json
import logging
import sys
import time
from pathlib import Path
from typing import Iterator, Sequence

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


def add_layer_argument(parser, what: str = "the input") -> None:
    """Add ``--as-layer`` (alias ``--layer``) (a sparse USD override layer instead of a full copy) to a subcommand."""
    parser.add_argument("--as-layer", "--layer", dest="layer", action="store_true",
                        help=f"USD: write a sparse override layer over {what} instead of a full copy")


def add_prop_arguments(p, required: bool, margin: bool = True) -> None:
    """``--props``, ``--margin`` (unless ``margin`` is False), ``--self``, ``--attach``, ``--prop-units``,
    ``--prop-up``, ``--interaction-config``."""
    p.add_argument("--props", type=Path, nargs="+", required=required, default=[], metavar="PROP",
                   help="props the hands touch: mesh files (.obj .stl .ply .off .glb .gltf) or USD files with Mesh prims")
    if margin:
        p.add_argument("--margin", type=float, default=0.0, metavar="MM",
                       help="clearance to keep between fingers and props, millimetres (default 0: touching)")
    p.add_argument("--self", dest="self_collision", action="store_true",
                   help="also keep the fingers out of the character's own body (torso, head, upper arms, thighs)")
    p.add_argument("--attach", action="append", default=[], metavar="PROP=JOINT[:FROM-TO]",
                   help="the prop moves with JOINT (a hand), from frame FROM to TO inclusive (default all frames); "
                        "PROP is the prop file's name or stem")
    p.add_argument("--prop-units", type=float, default=None, metavar="M",
                   help="metres per unit of the prop files (default: what the file says; OBJ, STL, PLY, OFF: the clip's)")
    p.add_argument("--prop-up", choices=("Y", "Z"), default=None,
                   help="up axis of the prop files (default: what the file says; OBJ, STL, PLY, OFF: Y)")
    p.add_argument("--interaction-config", type=Path, default=None, metavar="JSON",
                   help="finger radii, joint limits and smoothing (schemas/interaction_config.schema.json)")

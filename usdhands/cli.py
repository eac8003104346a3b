"""The ``usdhands`` command line.

Each subcommand lives in its own module under :mod:`usdhands.commands` and defines
``register(subparsers)``, which adds its parser and sets ``func`` (a function of the
parsed arguments returning an exit status). Modules are found automatically.

User mistakes and bad assets print one line ``usdhands: error: ...`` and exit with
status 2; no traceback. ``-v/--verbose`` and ``-q/--quiet`` are taken before or after the
subcommand. Progress bars (on stderr, only on a terminal, none with ``-q``) are drawn
here and in the commands from the library's progress callbacks; the library prints nothing.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import pkgutil
import sys

from usdhands import __version__
from usdhands.errors import UsdHandsError

EXIT_USER_ERROR = 2


class _Parser(argparse.ArgumentParser):
    """An argument parser whose every (sub)command takes ``-v/--verbose`` and ``-q/--quiet``.

    Subcommand parsers are made with the top parser's class, so ``usdhands synthesize X -o
    Y -v`` works like ``usdhands -v synthesize ...``. The defaults are suppressed so that a
    subcommand's parser does not reset what was given before the subcommand.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                          help="log details to stderr")
        self.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                          help="no progress display on stderr")


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every subcommand registered."""
    import usdhands.commands as commands

    parser = _Parser(
        prog="usdhands",
        description="Finger animation for skeletal characters in USD, glTF and BVH files.",
    )
    parser.add_argument("--version", action="version", version=f"usdhands {__version__}")
    parser.set_defaults(verbose=False, quiet=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"usdhands.commands.{info.name}")
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    from usdhands.commands._common import set_quiet

    parser = build_parser()
    args = parser.parse_args(argv)
    set_quiet(args.quiet)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return EXIT_USER_ERROR
    with _logging_to_stderr(logging.INFO if args.verbose else logging.WARNING):
        return _run(args)


@contextlib.contextmanager
def _logging_to_stderr(level: int):
    """The library's loggers (``usdhands.*``) print ``usdhands: message`` lines on the current
    stderr at ``level`` and above while a command runs (also when called in-process, where
    the root logger may already have handlers); restored afterwards."""
    log = logging.getLogger("usdhands")
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("usdhands: %(message)s"))
    saved = log.level, log.propagate
    log.addHandler(handler)
    log.setLevel(level)
    log.propagate = False
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.setLevel(saved[0])
        log.propagate = saved[1]


def _run(args) -> int:
    from usdhands.commands._common import compile_progress

    try:
        with compile_progress():
            return int(args.func(args) or 0)
    except UsdHandsError as e:
        print(f"usdhands: error: {e}", file=sys.stderr)
        return EXIT_USER_ERROR
    except BrokenPipeError:  # output piped into head and the like
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print("usdhands: interrupted", file=sys.stderr)
        return 130


def entry_point() -> None:
    """Console-script entry point."""
    sys.exit(main())


if __name__ == "__main__":
    entry_point()

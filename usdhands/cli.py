"""The ``usdhands`` command line.

Each subcommand lives in its own module under :mod:`usdhands.commands` and defines
``register(subparsers)``, which adds its parser and sets ``func`` (a function of the
parsed arguments returning an exit status). Modules are found automatically.

User mistakes and bad assets print one line ``usdhands: error: ...`` and exit with
status 2; no traceback. ``-v/--verbose`` and ``-q/--quiet`` are taken before or after the
subcommand. Progress bars (on stderr, only on a terminal, none with ``-q``) are drawn
here and in the commands from the library's progress callbacks; the library prints nothing.

The one error line holds for misused options too (argparse's usage text is kept for
``--help``), for control characters in file names (escaped, so the message stays one
line), for numpy's RuntimeWarnings (silenced: a value they flag is refused by a check of
its own), and for an operating-system error no check foresaw (the file it names and the
reason). SIGTERM is handled like SIGINT: outputs being written are
removed, one line, exit status 143.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import importlib
import logging
import os
import pkgutil
import signal
import sys
import warnings

from usdhands import __version__
from usdhands.errors import UsdHandsError, one_line

EXIT_USER_ERROR = 2
#: Exit status after SIGTERM (128 + 15, as a shell reports a process it terminated).
EXIT_TERMINATED = 143


class UsageError(Exception):
    """A command line argparse refuses; the CLI prints it as one ``usdhands: error:`` line."""


class Terminated(KeyboardInterrupt):
    """Raised by the SIGTERM handler: unwinds like Ctrl-C, so every ``atomic_output`` removes its temporary file."""


class _SignalHandler:
    """SIGTERM raises :class:`Terminated`, SIGINT ``KeyboardInterrupt``; each signal is recorded, so
    that one whose exception C code replaced on its way up is still known (numpy's ``tofile``
    turns an exception raised while it writes into ``TypeError: expected str, bytes or
    os.PathLike object``: 18 of 3,000 timer signals)."""

    def __init__(self):
        self.received: list[int] = []

    def __call__(self, signum, frame):
        self.received.append(signum)
        raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


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

    def error(self, message: str):
        """Raise :class:`UsageError` instead of printing the usage text (kept for ``--help``)."""
        raise UsageError(f"{self.prog}: {message}" if self.prog != "usdhands" else message)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The full argument parser with every subcommand registered; with ``command`` (a subcommand's
    name, as :func:`named_command` finds it), that subcommand's parser only: the other commands'
    modules are not imported (``handmap`` and ``inspect`` import NumPy, ~45 ms of a command's start)."""
    parser = _Parser(
        prog="usdhands",
        description="Finger animation for skeletal characters in USD, glTF and BVH files.",
    )
    parser.add_argument("--version", action="version", version=f"usdhands {__version__}")
    parser.set_defaults(verbose=False, quiet=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in _command_modules():
        if command is None or _command_name(name) == command:
            importlib.import_module(f"usdhands.commands.{name}").register(sub)
    return parser


@functools.lru_cache(maxsize=1)
def _command_modules() -> tuple[str, ...]:
    """The modules of :mod:`usdhands.commands` that register a subcommand, by name, sorted (listed once a
    process: :func:`named_command` and :func:`build_parser` both ask)."""
    import usdhands.commands as commands

    return tuple(sorted(info.name for info in pkgutil.iter_modules(commands.__path__) if not info.name.startswith("_")))


def _command_name(module: str) -> str:
    """The subcommand a module of :mod:`usdhands.commands` registers (``usd_plugin``: ``usd-plugin``)."""
    return module.replace("_", "-")


def named_command(argv: list[str]) -> str | None:
    """The subcommand a command line names: its first word not starting with ``-`` (the top level's
    options take no value), when that is a subcommand; None else (no command, ``--help``, ``--version``,
    a misspelled command: the full parser, whose usage and errors list every command)."""
    word = next((w for w in argv if not w.startswith("-")), None)
    return word if word in {_command_name(name) for name in _command_modules()} else None


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    from usdhands.commands._common import set_quiet

    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(named_command(argv))
    try:
        args = parser.parse_args(argv)
    except UsageError as e:
        print(f"usdhands: error: {one_line(str(e))} (see --help)", file=sys.stderr)
        return EXIT_USER_ERROR
    set_quiet(args.quiet)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return EXIT_USER_ERROR
    with _logging_to_stderr(logging.INFO if args.verbose else logging.WARNING) as held:
        code = _run(args)
        if code in (EXIT_USER_ERROR, EXIT_TERMINATED, 130):
            held.clear()  # a bad input is one line: the error, not what the reader warned on the way
        return code


class _HeldWarnings(logging.Handler):
    """Holds the records of a command at default verbosity; they are printed when it ends
    (:meth:`flush`) unless it failed (:meth:`clear`), so a bad input stays one stderr line."""

    def __init__(self, stream):
        super().__init__()
        self.stream = stream
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)

    def clear(self) -> None:
        self.records = []

    def flush(self) -> None:
        for record in self.records:
            self.stream.write(self.format(record) + "\n")
        self.records = []
        self.stream.flush()


@contextlib.contextmanager
def _logging_to_stderr(level: int):
    """The library's loggers (``usdhands.*``) print ``usdhands: message`` lines on the current
    stderr at ``level`` and above while a command runs (also when called in-process, where
    the root logger may already have handlers); restored afterwards.

    With ``-v`` (INFO) the lines stream as they come; at the default level the warnings are
    held and printed when the command ends, and dropped when it fails with a user error
    (the yielded handler's ``clear``)."""
    log = logging.getLogger("usdhands")
    held = _HeldWarnings(sys.stderr)
    handler = logging.StreamHandler(sys.stderr) if level < logging.WARNING else held
    handler.setFormatter(logging.Formatter("usdhands: %(message)s"))
    saved = log.level, log.propagate
    log.addHandler(handler)
    log.setLevel(level)
    log.propagate = False
    try:
        yield held
    finally:
        log.removeHandler(handler)
        log.setLevel(saved[0])
        log.propagate = saved[1]
        held.flush()


def _run(args) -> int:
    from usdhands.commands._common import compile_progress

    handler = _SignalHandler()
    previous = {}
    if _main_thread():
        previous[signal.SIGTERM] = signal.signal(signal.SIGTERM, handler)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # an ignored SIGINT stays ignored
            previous[signal.SIGINT] = signal.signal(signal.SIGINT, handler)
    try:
        try:
            with compile_progress(), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # numpy's overflow/invalid: checks refuse the values
                return int(args.func(args) or 0)
        except Exception:
            if handler.received:  # the signal's exception was replaced on its way up: it is still the signal
                raise Terminated() if handler.received[0] == signal.SIGTERM else KeyboardInterrupt() from None
            raise
    except UsdHandsError as e:
        print(f"usdhands: error: {one_line(str(e))}", file=sys.stderr)
        return EXIT_USER_ERROR
    except BrokenPipeError:  # output piped into head and the like
        sys.stderr.close()
        return 0
    except Terminated:
        print("usdhands: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        print("usdhands: interrupted", file=sys.stderr)
        return 130
    except OSError as e:  # one no check foresaw (a name too long, a folder made read-only meanwhile)
        where = e.filename if e.filename is not None else "usdhands"
        print(f"usdhands: error: {one_line(str(where))}: {e.strerror or e}", file=sys.stderr)
        return EXIT_USER_ERROR
    finally:
        for sig, before in previous.items():
            signal.signal(sig, before)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


#: Variables OpenBLAS (NumPy's and SciPy's linear algebra) reads for its thread count: where the
#: caller set none of them, a ``usdhands`` process uses one thread (:func:`one_blas_thread_by_default`).
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread_by_default() -> bool:
    """Set ``OPENBLAS_NUM_THREADS=1`` unless the caller set one of :data:`BLAS_THREAD_VARIABLES`,
    before NumPy is imported; True if it was set here.

    usdhands' linear algebra is many small products (4 x 4 transforms, a prop's vertices, a
    clip's curves), on which OpenBLAS's extra threads find no work but spin after each call: a
    fresh ``usdhands synthesize`` of the sample conversation took 0.36-0.40 s of CPU for 0.29-0.30 s
    of wall time with OpenBLAS's default (a thread per core), and 0.27-0.32 s with one thread, in the
    same wall time and with the same output bytes. On a farm that runs a command per core, that
    is a quarter of the CPU back. The variable is inherited by what the process starts (``batch``'s
    workers). Set ``OPENBLAS_NUM_THREADS`` (or ``OMP_NUM_THREADS``) to use more.
    """
    if "numpy" in sys.modules or any(name in os.environ for name in BLAS_THREAD_VARIABLES):
        return False  # too late (OpenBLAS read its variables when NumPy loaded it), or the caller's choice
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    return True


def entry_point() -> None:
    """Console-script entry point (and ``python -m usdhands``).

    OpenBLAS runs on one thread unless the caller says otherwise (:func:`one_blas_thread_by_default`).
    The process then exits without Python's last garbage collections over what it loaded
    (``gc.freeze``; exit handlers, flushed streams and the exit status as before): with
    Dask loaded, as after ``batch --scheduler``, they took ~0.14 of a 0.15 s exit.
    """
    import gc

    one_blas_thread_by_default()
    code = main()
    gc.freeze()
    sys.exit(code)


if __name__ == "__main__":
    entry_point()

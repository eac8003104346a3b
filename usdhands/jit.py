"""numba's ``njit`` with the compiled kernels cached in the user's cache folder.

numba's own ``cache=True`` writes ``.nbi``/``.nbc`` files into the ``__pycache__`` beside
the source, which is inside the installed package: that fails on a read-only install,
and after ``pip uninstall`` the left-over folder loads as an empty namespace package
(``pip install .`` then ``pip install -e .`` broke ``usdhands``). Every kernel of the
package is compiled through :func:`njit` here instead, which caches into
:func:`kernel_cache_dir`:

- ``$USDHANDS_CACHE_DIR/kernels`` when that variable is set;
- else ``$NUMBA_CACHE_DIR`` when the user set numba's own variable;
- else the platform's user cache folder: ``$XDG_CACHE_HOME/usdhands/kernels``
  (``~/.cache/usdhands/kernels``) on Linux, ``~/Library/Caches/usdhands/kernels`` on
  macOS, ``%LOCALAPPDATA%\\usdhands\\Cache\\kernels`` on Windows.

When that folder cannot be written the kernels are compiled in memory on each run
(slower, never written elsewhere). Only this package's kernels are affected: numba's
setting is changed just while each kernel is decorated, then restored.

First-run compilation takes tens of seconds; :func:`compile_listener` lets a caller
(the command line's progress bar) hear about each kernel numba compiles, while the
library itself prints nothing.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading
from pathlib import Path
from typing import Callable, Iterator

__all__ = ["njit", "kernel_cache_dir", "user_cache_dir", "compile_listener", "kernel_threads",
           "set_kernel_threads", "kernels_running"]  # and prange, numba's own

_writable: dict[Path, bool] = {}


def user_cache_dir() -> Path:
    """The usdhands folder in the platform's per-user cache location (not created)."""
    if os.environ.get("USDHANDS_CACHE_DIR"):
        return Path(os.environ["USDHANDS_CACHE_DIR"]).expanduser()
    home = Path.home()
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or home / "AppData" / "Local")
        return base / "usdhands" / "Cache"
    if sys.platform == "darwin":
        return home / "Library" / "Caches" / "usdhands"
    return Path(os.environ.get("XDG_CACHE_HOME") or home / ".cache") / "usdhands"


def kernel_cache_dir() -> Path:
    """The folder compiled kernels are cached in (see the module docstring for the order)."""
    if not os.environ.get("USDHANDS_CACHE_DIR") and os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"]).expanduser()
    return user_cache_dir() / "kernels"


def _can_write(folder: Path) -> bool:
    if folder not in _writable:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            tempfile.TemporaryFile(dir=folder).close()
            _writable[folder] = True
        except OSError:
            _writable[folder] = False
    return _writable[folder]


def njit(*args, cache: bool = True, **kwargs):
    """``numba.njit`` with ``cache=True`` meaning the user cache folder, never the package.

    Used exactly like ``numba.njit``: ``@njit``, ``@njit(parallel=True)``.
    """
    numba = _numba()
    from numba.core import config

    _install_listener()

    def decorate(fn):
        _kernels.add(id(fn))  # the function stays alive with its dispatcher
        dispatcher = numba.njit(cache=False, **kwargs)(fn)
        _dispatchers.append(dispatcher)
        folder = kernel_cache_dir()
        if cache and _can_write(folder):
            saved = config.CACHE_DIR
            config.CACHE_DIR = str(folder)  # read once, when the kernel's cache locator is made
            try:
                dispatcher.enable_caching()
            finally:
                config.CACHE_DIR = saved
        return dispatcher

    if args and callable(args[0]):
        return decorate(args[0])
    if args:  # an explicit signature: njit("f8(f8)")
        raise TypeError("usdhands.jit.njit takes keyword options only")
    return decorate


def __getattr__(name: str):
    # ``prange`` must be numba's own object for numba to see a parallel loop; numba is
    # imported only when a kernel module asks for it
    if name == "prange":
        return _numba().prange
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def kernel_threads() -> int:
    """How many threads numba's parallel kernels use when called from this thread."""
    return int(_numba().get_num_threads())


def set_kernel_threads(n: int) -> None:
    """Parallel kernels called from **this thread** use at most ``n`` threads (numba's
    ``set_num_threads``: per thread, no environment variable, nothing else changed).

    For batch workers, which run one clip per core: the kernels' own threads would fight
    over the same cores. Library code running in a caller's process must not call it.

    Where numba is not imported yet, it is not imported for this (a worker that runs only
    the kernels compiled ahead of time never pays for numba's start): the setting is kept for
    this thread and made when the package first imports numba in it (:func:`njit`, :func:`kernel_threads`).
    """
    if "numba" not in sys.modules:
        _pending_threads[threading.get_ident()] = int(n)
        return
    _set_threads(_numba(), n)


def _set_threads(numba, n: int) -> None:
    numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))


def _numba():
    """numba, imported; with the kernel threads this thread asked for before (:func:`set_kernel_threads`)."""
    import numba

    pending = _pending_threads.pop(threading.get_ident(), None)
    if pending is not None:
        _set_threads(numba, pending)
    return numba


def kernels_running() -> bool:
    """Whether one of this package's kernels has been compiled or loaded from the cache in this process.

    numba's own start-up (its import and first kernel: about 0.55 s of CPU here, measured)
    is then paid, and a further cached kernel loads in a few milliseconds: the point from
    which an optional compiled twin of a NumPy function costs nothing to start.
    """
    return any(d.signatures for d in _dispatchers)


_listeners: list[Callable[[str], None]] = []
_pending_threads: dict[int, int] = {}  # thread id -> kernel threads asked for before numba was imported
_dispatchers: list = []  # every dispatcher njit made
_installed = False
_kernels: set[int] = set()  # id() of the Python functions compiled through njit here


def _install_listener() -> None:
    """Hear numba's compile events (once per process; numba is imported by then)."""
    global _installed
    if _installed:
        return
    from numba.core import event

    class _Listener(event.Listener):
        def on_start(self, ev):
            dispatcher = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
            fn = getattr(dispatcher, "py_func", None)
            if id(fn) not in _kernels:  # numba's own helpers compiled along the way
                return
            for listener in list(_listeners):
                listener(fn.__name__)

        def on_end(self, ev):
            pass

    event.register("numba:compile", _Listener())
    _installed = True


@contextlib.contextmanager
def compile_listener(on_compile: Callable[[str], None]) -> Iterator[None]:
    """Call ``on_compile(kernel_name)`` each time numba starts compiling one of our kernels, inside the block.

    Loading a kernel from the cache is not a compilation: on every run after the first,
    ``on_compile`` is not called. Does not import numba (a command that uses no kernel
    does not pay for it). The callback runs in the compiling thread and must not raise.
    """
    _listeners.append(on_compile)
    if "numba" in sys.modules:
        _install_listener()
    try:
        yield
    finally:
        _listeners.remove(on_compile)

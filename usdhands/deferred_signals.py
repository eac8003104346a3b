"""SIGTERM and SIGINT held back while a few file-system steps run whole.

The command line turns SIGTERM and SIGINT into exceptions that unwind every write and
remove its temporary files. A signal that comes between making a temporary file or
folder and recording its name (or in the middle of removing one) would still leave it
behind: :class:`DeferredSignals` records such a signal instead and raises it once the
steps are done (:meth:`DeferredSignals.replay`). Used by the formats' ``atomic_output``
and by the finger database's folder writer; any layer may import it.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator

__all__ = ["DeferredSignals", "signals_deferred"]

#: the signals the command line cleans up after
CLEANUP_SIGNALS = (signal.SIGTERM, signal.SIGINT)


class DeferredSignals:
    """SIGTERM/SIGINT recorded instead of handled until :meth:`replay` (main thread only; elsewhere a no-op).

    Blocking the signals (pthread_sigmask) did not close the window: USD's worker threads
    take the signal and Python runs its handler in the main thread all the same.
    """

    def __init__(self):
        self.saved: dict = {}
        self.pending: list[int] = []
        if threading.current_thread() is threading.main_thread():
            for sig in CLEANUP_SIGNALS:
                self.saved[sig] = signal.signal(sig, lambda signum, frame: self.pending.append(signum))

    def restore(self) -> None:
        for sig, handler in self.saved.items():
            signal.signal(sig, handler)
        self.saved = {}

    def replay(self) -> None:
        """Restore the handlers and run the one of each signal that came meanwhile (it raises)."""
        saved = dict(self.saved)
        self.restore()
        for sig in self.pending:
            handler = saved.get(sig)
            if callable(handler):
                handler(sig, None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(sig)


@contextlib.contextmanager
def signals_deferred() -> Iterator[None]:
    """Run the ``with`` block whole; a SIGTERM/SIGINT that came meanwhile is raised at its end."""
    deferred = DeferredSignals()
    try:
        yield
    finally:
        deferred.replay()

"""A pipeline's own batch job for the tests: ``convert``, except that a clip whose name starts
with ``die`` ends its worker process at once (``os._exit``), as a crash in native code would."""

from __future__ import annotations

import os
from pathlib import Path


def convert_or_die(source, output, options):
    if Path(source).name.startswith("die"):
        os._exit(70)
    from usdhands.jobs.conversion import convert

    return convert(source, output, options)


def worker_state() -> dict:
    """In a pool worker: whether it had imported numba, its kernel threads, whether the search kernel is
    loaded, and what its parent process (the forkserver it was forked from) has mapped: numba (llvmlite)
    and numba's threading layers."""
    import sys

    from usdhands.algorithms.synthesis import segment_cost
    from usdhands.jit import kernel_threads

    had_numba = "numba" in sys.modules
    with open(f"/proc/{os.getppid()}/maps") as f:
        parent = f.read()
    return {"had_numba": had_numba, "kernel_threads": kernel_threads(), "search_kernel": segment_cost._kernel_loaded(),
            "parent_has_numba": "llvmlite" in parent,
            "parent_started_threads": any(layer in parent for layer in ("omppool", "tbbpool", "workqueue"))}


def processor_known() -> list:
    """In a worker forked from the warm forkserver: whether ``platform.uname().processor`` (what a Dask
    worker reports when it registers) was already asked before this process started, and whether the
    process has another thread than its main one."""
    import platform
    import threading

    return ["processor" in vars(platform.uname()), threading.active_count()]

"""The Dask worker plugin of ``batch``: a worker in a process of its own runs kernels on one thread.

Imported only when ``batch`` sends clips to Dask (``distributed`` is an optional dependency).
"""

from __future__ import annotations

import os
import socket

from distributed.diagnostics.plugin import WorkerPlugin


class OwnProcessWorker(WorkerPlugin):
    """Calls :func:`usdhands.jobs.batch.become_worker_process` on every worker (those that join
    or restart later too) whose process is not the process that made the plugin.

    A ``LocalCluster(processes=False)`` runs its workers as threads of the caller's process:
    there the plugin does nothing, so the caller's process is never changed.

    ``freeze_at_exit``: the worker processes also skip Python's last garbage collections when they
    exit (:func:`usdhands.jobs.batch.freeze_at_exit`); for the LocalCluster batch makes, whose
    close waits for them (not for a farm's workers, which batch does not start).
    """

    name = "usdhands-own-process-worker"

    def __init__(self, freeze_at_exit: bool = False) -> None:
        self.caller = (socket.gethostname(), os.getpid())
        self.freeze_at_exit = freeze_at_exit

    def setup(self, worker) -> None:
        if (socket.gethostname(), os.getpid()) != self.caller:
            from usdhands.jobs.batch import become_worker_process, freeze_at_exit

            become_worker_process()
            if self.freeze_at_exit:
                freeze_at_exit()

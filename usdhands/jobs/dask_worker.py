"""The Dask worker plugin of ``batch``: a worker in a process of its own runs kernels on one thread.

Imported only when ``batch`` sends clips to Dask (``distributed`` is an optional dependency).
"""

from __future__ import annotations

import contextlib
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

    ``warm``: ``(job, job_options, clips_each)``: then every worker, in its process or not, also
    imports the job and loads its database (:func:`usdhands.jobs.batch._warm_worker`) before its
    first task. Given to a LocalCluster's workers when they are made, the plugin runs before the
    worker registers with the scheduler; registered on a running cluster, before the first task
    is sent. A warm-up that fails is left to each clip (it records the error).
    """

    name = "usdhands-own-process-worker"

    def __init__(self, freeze_at_exit: bool = False, warm: tuple | None = None) -> None:
        self.caller = (socket.gethostname(), os.getpid())
        self.freeze_at_exit = freeze_at_exit
        self.warm = warm

    def setup(self, worker) -> None:
        from usdhands.jobs.batch import _warm_worker, become_worker_process, freeze_at_exit

        if (socket.gethostname(), os.getpid()) != self.caller:
            become_worker_process()
            if self.freeze_at_exit:
                freeze_at_exit()
        if self.warm is not None:
            with contextlib.suppress(Exception):  # a worker whose plugin raised would not start
                _warm_worker(*self.warm)

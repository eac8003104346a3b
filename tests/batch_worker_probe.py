"""A pipeline's own batch job for the tests: ``convert``, then ``<output>.worker.json`` beside the
output, saying how the Dask worker that ran it is set up (its periodic callbacks, the settings
that batch's LocalCluster changes, as that worker's process sees them, the malloc trim threshold
in its environment, its worker plugins and whether batch set it up as a process of its own)."""

from __future__ import annotations

import json
import os
from pathlib import Path

SETTINGS = ("distributed.worker.profile.enabled", "distributed.admin.tick.interval",
            "distributed.admin.system-monitor.interval", "distributed.worker.memory.monitor-interval")


def convert_and_describe_worker(source, output, options):
    import dask
    from distributed import get_worker

    from usdhands.jobs import batch
    from usdhands.jobs.conversion import convert

    result = convert(source, output, options)
    worker = get_worker()
    Path(str(output) + ".worker.json").write_text(json.dumps({
        "pid": os.getpid(), "callbacks": sorted(worker.periodic_callbacks),
        "settings": {key: dask.config.get(key) for key in SETTINGS},
        "malloc_trim_threshold": os.environ.get("MALLOC_TRIM_THRESHOLD_"),
        "plugins": sorted(worker.plugins), "own_process": batch._own_worker_process}))
    return result

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

"""The jobs on an open ``Usd.Stage`` (see :mod:`usdhands.pipeline.stage_hooks`, where they live).

``synthesize_stage``, ``correct_stage``, ``reduce_stage`` and ``check_stage`` read the stage as it composes now,
author into its current edit target (or a layer the caller names) and save nothing.
"""

from usdhands.pipeline.stage_hooks import (
    StageEdit, check_stage, correct_stage, read_stage_clip, reduce_stage, synthesize_stage,
)

__all__ = ["StageEdit", "synthesize_stage", "correct_stage", "reduce_stage", "check_stage", "read_stage_clip"]

"""Jobs: one function per capability, the layer the command line, the batch runner and pipelines call.

Each job takes input paths, an output path and a frozen options dataclass (its defaults are
the command line's), raises :class:`usdhands.UsdHandsError` subclasses for bad input, never
prints and never exits, reports progress through an optional ``progress(done, total, what)``
callback, and returns a frozen result whose ``to_json()`` is the command's ``--json`` report.

=================  ====================================================  =====================
job                call                                                  options / result
=================  ====================================================  =====================
synthesize         ``synthesize(source, output, options)``               SynthesizeOptions/Result
splice             ``splice(body, hands, output, options)``              SpliceOptions/Result
reduce             ``reduce(source, output=None, options, model_output)``  ReduceOptions/Result
expand             ``expand(source, model, output, options)``            ExpandOptions/Result
convert            ``convert(source, output, options)``                  ConvertOptions/Result
check              ``check(paths, options)`` (writes nothing)            CheckOptions/Result
correct            ``correct(source, output, options)``                  CorrectOptions/Result
evaluate           ``evaluate(inputs, options)`` (writes only plots)     EvaluateOptions/Result
=================  ====================================================  =====================

Adding a job (the pattern): a module named for what it does (``usdhands/jobs/correction.py``: a
module named like the function would be shadowed by it) with ``<Name>Options``
(frozen dataclass, CLI defaults), ``<Name>Result`` (frozen dataclass with ``to_json()``) and
``<name>(inputs..., output, options, progress=None)``; its names in :data:`JOBS` below (and in
``usdhands/__init__.py``'s ``_LAZY_JOBS``); the
command ``usdhands/commands/<name>.py`` builds the options from its arguments, calls the job
and prints the result. Heavy imports stay inside the job function so ``import usdhands``
stays fast.

Everything here is imported on first use: ``usdhands.jobs.synthesize`` loads only
:mod:`usdhands.jobs.synthesis`.
"""

from __future__ import annotations

import importlib

#: exported name -> module under usdhands.jobs that defines it
JOBS = {
    "synthesize": "synthesis", "SynthesizeOptions": "synthesis", "SynthesizeResult": "synthesis",
    "splice": "splicing", "SpliceOptions": "splicing", "SpliceResult": "splicing",
    "reduce": "reduction", "ReduceOptions": "reduction", "ReduceResult": "reduction",
    "expand": "expansion", "ExpandOptions": "expansion", "ExpandResult": "expansion",
    "convert": "conversion", "ConvertOptions": "conversion", "ConvertResult": "conversion",
    "check": "validation", "CheckOptions": "validation", "CheckResult": "validation",
    "correct": "correction", "CorrectOptions": "correction", "CorrectResult": "correction",
    "evaluate": "evaluation", "EvaluateOptions": "evaluation", "EvaluateResult": "evaluation",
}

__all__ = sorted(JOBS)


def __getattr__(name: str):
    module = JOBS.get(name)
    if module is None:
        raise AttributeError(f"module 'usdhands.jobs' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"usdhands.jobs.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(JOBS))

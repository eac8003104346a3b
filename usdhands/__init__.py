"""usdhands: finger animation for skeletal characters in USD, glTF and BVH files.

The everyday API::

    import usdhands
    clip = usdhands.read_clip("take.usda")          # a Clip: time-major arrays, xyzw quaternions
    hands = usdhands.detect_hands(clip.skeleton)    # a HandMap
    usdhands.write_clip("take.usda", clip, "take_out.usda")

The jobs, one call per capability (see :mod:`usdhands.jobs`)::

    result = usdhands.synthesize("take.usda", "take_fingers.usda", usdhands.SynthesizeOptions(k=8))
    print(result.to_json())

Every name here is loaded on first use (``import usdhands`` imports neither numpy nor the
model): the readers and the model above, ``usdhands.synthesize``, ``splice``, ``reduce``,
``expand``, ``convert``, ``check``, ``correct``, ``evaluate`` and their ``...Options`` /
``...Result`` classes, and :mod:`usdhands.usd`, the same jobs on an open ``Usd.Stage``.

Importing usdhands imports neither ``pxr`` nor ``pygltflib``; a format's library is
imported when a file of that format is first read or written.
"""

__version__ = "0.1.0"

from usdhands.errors import UsdHandsError  # noqa: E402

#: names loaded on first use (module __getattr__), so that ``import usdhands`` stays fast (neither
#: numpy nor the model: ``import usdhands.cli`` 0.080 -> 0.006 s)
_LAZY = {
    **dict.fromkeys(("read_asset", "read_clip", "write_asset", "write_clip"), "usdhands.formats.io"),
    **dict.fromkeys(("FINGERS", "SIDES", "Clip", "FingerCurves", "HandMap", "HandSide", "Skeleton",
                     "apply_finger_curves", "finger_curves"), "usdhands.model"),
    **dict.fromkeys(("detect_hands", "load_handmap"), "usdhands.model.hand_detection"),
}
_LAZY_JOBS = (
    "synthesize", "SynthesizeOptions", "SynthesizeResult", "splice", "SpliceOptions", "SpliceResult",
    "reduce", "ReduceOptions", "ReduceResult", "expand", "ExpandOptions", "ExpandResult",
    "convert", "ConvertOptions", "ConvertResult", "check", "CheckOptions", "CheckResult",
    "correct", "CorrectOptions", "CorrectResult", "evaluate", "EvaluateOptions", "EvaluateResult",
)


def __getattr__(name: str):
    import importlib

    if name == "usd":  # the USD stage hooks (imports pxr)
        import usdhands.usd

        return usdhands.usd
    if name in _LAZY or name in _LAZY_JOBS:
        value = getattr(importlib.import_module(_LAZY.get(name, "usdhands.jobs")), name)
        globals()[name] = value
        return value
    try:  # a subpackage (usdhands.model, usdhands.formats...), as when the names above loaded it
        return importlib.import_module(f"{__name__}.{name}")
    except ModuleNotFoundError as e:
        if e.name != f"{__name__}.{name}":
            raise
    raise AttributeError(f"module 'usdhands' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY) | set(_LAZY_JOBS))


__all__ = [
    "__version__", "UsdHandsError", "read_asset", "read_clip", "write_asset", "write_clip", "Clip",
    "Skeleton", "HandMap", "HandSide", "FINGERS", "SIDES", "FingerCurves", "finger_curves",
    "apply_finger_curves", "detect_hands", "load_handmap", *_LAZY_JOBS,
]

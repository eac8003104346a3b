"""The expand job: rebuild a full hand from the controlling curves of a reduction model.

Reads the finger curves the model names from the input, keeps the free (controlling)
curves, sets the constants and rebuilds every dependent curve as ``scale * controlling +
offset``; writes the result into a copy of the input. Applied to the animation the reduce
job wrote, it reproduces it; applied to a clip where an animator keyed only the
controlling curves, it fills in the rest.

::

    import usdhands
    result = usdhands.expand("keyed.usda", "hand_model.json", "full.usda")
    print(result.dependent, "curves rebuilt")
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from usdhands.errors import JointMismatchError, UsdHandsError
from usdhands.jobs.outputs import MAIN_INPUT, check_paths, layer_options


@dataclass(frozen=True)
class ExpandOptions:
    """Options of :func:`expand`; the defaults are the command line's.

    Attributes
    ----------
    animation : str or None
        Animation name or index in the file (default the first).
    as_layer : bool
        USD: write a sparse override layer over the input instead of a full copy.
    """

    animation: str | None = None
    as_layer: bool = False


@dataclass(frozen=True)
class ExpandResult:
    """What :func:`expand` did: counts of the model's curves and the file written."""

    source: Path
    model: Path
    output: Path
    frames: int
    curves: int
    controlling: tuple[str, ...]
    free: int
    dependent: int
    constants: int
    notes: tuple[str, ...] = ()

    def to_json(self) -> dict:
        """The ``usdhands expand --json`` summary."""
        return {"file": str(self.source), "model": str(self.model), "output": str(self.output),
                "frames": self.frames, "curves": self.curves, "controlling": list(self.controlling),
                "free": self.free, "dependent": self.dependent, "constants": self.constants}


def expand(source: str | os.PathLike, model: str | os.PathLike, output: str | os.PathLike,
           options: ExpandOptions = ExpandOptions(),
           progress: Callable[[int, int, str], None] | None = None) -> ExpandResult:
    """Rebuild every finger curve of ``source`` from ``model`` (a reduction model JSON) and write ``output``.

    Joints of the model the file lacks are skipped (said in ``result.notes``) unless a
    curve the file keeps depends on them.

    Raises
    ------
    UsdHandsError
        Unreadable input or model, joints the model needs missing, a bad output.
    """
    from usdhands.algorithms.reduction.model import ReductionModel
    from usdhands.algorithms.reduction.reduce import curve_names, expand_clip
    from usdhands.formats.io import read_clip, write_clip

    source, model_path, output = Path(source), Path(model), Path(output)
    check_paths({MAIN_INPUT: source, "--model": model_path}, {"-o": output})
    write_opts = layer_options(options.as_layer, source, output)
    if progress:
        progress(0, 2, "reading")
    reduction = ReductionModel.load(model_path)
    clip = read_clip(source, animation=options.animation)
    joints, absent = [], []
    for name in model_joints(reduction):
        try:
            joints.append(clip.skeleton.index(name))
        except KeyError:
            absent.append(name)
    notes: list[str] = []
    if absent:
        reduction = _without_joints(reduction, absent, source, model_path, notes)
        joints = [clip.skeleton.index(name) for name in model_joints(reduction)]
    names = set(curve_names(clip.skeleton, joints, reduction.order))
    missing = [c for c in reduction.curves if c not in names]
    if missing:  # only when the model's axis letters do not match its Euler order
        raise UsdHandsError(f"curves {missing[:3]} of the model do not match its Euler order {reduction.order}",
                            path=model_path)
    if progress:
        progress(1, 2, "writing")
    from usdhands.model.provenance import provenance_record

    record = provenance_record("reduction", database=model_path, parameters={
        "controlling": list(reduction.controlling_curves), "curves": len(reduction.curves)})
    out = write_clip(source, expand_clip(clip, joints, reduction), output, provenance=record, **write_opts)
    if progress:
        progress(2, 2, "done")
    return ExpandResult(source, model_path, Path(out), int(clip.num_frames), len(reduction.curves),
                        tuple(reduction.controlling_curves), len(reduction.free_curves), len(reduction.relations),
                        len(reduction.constants), tuple(notes))


def model_joints(model) -> list[str]:
    """The joints a model's curves belong to, in curve order (``"LeftHandIndex2.y"`` → ``LeftHandIndex2``)."""
    joints: list[str] = []
    for c in model.curves:
        j = c.rsplit(".", 1)[0]
        if j not in joints:
            joints.append(j)
    return joints


def _names(items: list[str], most: int = 6) -> str:
    return ", ".join(items[:most]) + (f", ... ({len(items)} in all)" if len(items) > most else "")


def _without_joints(model, absent: list[str], source: Path, model_path: Path, notes: list[str]):
    """The model without the curves of joints the file lacks; an error when a controlling curve is among them."""
    gone = {c for c in model.curves if c.rsplit(".", 1)[0] in absent}
    if len(gone) == len(model.curves):
        raise JointMismatchError(f"none of the joints of the reduction model {model_path.name} is in the file "
                                 f"(the model has {_names(absent)})", path=source)
    lost = [r for r in model.relations if r.controlling in gone and r.dependent not in gone]
    if lost:
        ctrl = [j for j in absent if any(r.controlling.rsplit(".", 1)[0] == j for r in lost)]
        raise JointMismatchError(f"controlling joint{'s' if len(ctrl) > 1 else ''} {_names(ctrl)} of the reduction "
                                 f"model {model_path.name} {'are' if len(ctrl) > 1 else 'is'} not in the file "
                                 f"(needed to rebuild {_names([r.dependent for r in lost])})", path=source)
    notes.append(f"joints of the reduction model {model_path.name} that {source.name} lacks are "
                 f"skipped: {_names(absent)}")
    return model.subset(c for c in model.curves if c not in gone)

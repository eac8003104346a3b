"""The reduce job: find irrelevant and redundant finger DOFs (Jörg and O'Sullivan 2009).

Curves with a small range become constants, curves that are a linear function of another
curve are rebuilt from it; the steps run in order and accumulate like the paper's four
steps. The result holds the DOFs left after each step with the reconstruction error (the
paper's table 5), the constants (tables 1 and 3) and the relations (tables 2 and 4).
Optionally writes the simplified animation into a copy of the input, the model the expand
job rebuilds a hand from, and PNG plots of the paper's figures.

::

    import usdhands
    result = usdhands.reduce("take.usda", "take_reduced.usda", usdhands.ReduceOptions(steps="range<5,rmsd<0.5"),
                             model_output="hand_model.json")
    print([(s.condition, s.dofs_left) for s in result.reduction.steps])
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from usdhands.algorithms.reduction.reduce import DEFAULT_STEPS, RangeRule
from usdhands.errors import UsdHandsError
from usdhands.jobs.outputs import MAIN_INPUT, check_paths, layer_options

__all__ = ["DEFAULT_STEPS", "RangeRule", "ReduceOptions", "ReduceResult", "reduce", "load_finger_curves"]



@dataclass(frozen=True)
class ReduceOptions:
    """Options of :func:`reduce`; the defaults are the command line's.

    Attributes
    ----------
    steps : str
        Comma-separated steps ``range<N`` (degrees), ``rmsd<N``, ``rmsd1<N``, ``rmsd2<N``.
    step : int or None
        Which step's result the output clip, the model and the JSON relations use (1-based; default the last).
    hands : tuple of str
        Hands to reduce (``"left"``, ``"right"``); empty: every hand found.
    animation : str or None
        Animation name or index in the file (default the first).
    handmap : Path or None
        Hand map JSON overriding detection.
    order : str
        Euler order of the finger curves (a permutation of XYZ).
    across_hands : bool
        Also relate curves of different hands (the paper compared all 50 curves).
    as_layer : bool
        USD: write the output as a sparse override layer over the input.
    plot : Path or None
        Folder for histograms, scatter plots and original-vs-rebuilt curves (PNG).
    """

    steps: str = DEFAULT_STEPS
    step: int | None = None
    hands: tuple[str, ...] = ()
    animation: str | None = None
    handmap: Path | None = None
    order: str = "XYZ"
    across_hands: bool = False
    as_layer: bool = False
    plot: Path | None = None


@dataclass(frozen=True)
class ReduceResult:
    """What :func:`reduce` found and wrote.

    Attributes
    ----------
    source : Path
    frames : int
    fps : float
    curve_names : tuple of str
        The finger curves, ``"<joint>.<axis>"``, left hand first.
    sides : tuple of str
        The side of each curve.
    reduction : ReductionResult
        The algorithm's result: ``steps`` (condition, dofs_left, rms/max error in degrees, model).
    step : int
        The step used (1-based).
    paper_names : dict
        Curve name -> the paper's name for it (where the hand has one).
    written : tuple of Path
        Files written (output clip, model, plots).
    """

    source: Path
    frames: int
    fps: float
    curve_names: tuple[str, ...]
    sides: tuple[str, ...]
    reduction: object
    step: int
    paper_names: dict
    written: tuple[Path, ...] = ()

    @property
    def chosen(self):
        """The step result used for the output, the model and the JSON relations."""
        return self.reduction.steps[self.step - 1]

    def to_json(self) -> dict:
        """The ``usdhands reduce --json`` report."""
        paper = self.paper_names
        report = self.reduction.to_dict(step=self.step - 1)
        report = {"file": str(self.source), "frames": self.frames, "fps": self.fps, **report}
        for r in report["relations"]:
            r["dependent_paper"] = paper.get(r["dependent"])
            r["controlling_paper"] = paper.get(r["controlling"])
        for c in report["constants"]:
            c["curve_paper"] = paper.get(c["curve"])
        if self.written:
            report["written"] = [str(w) for w in self.written]
        return report


def reduce(source: str | os.PathLike, output: str | os.PathLike | None = None,
           options: ReduceOptions = ReduceOptions(), *, model_output: str | os.PathLike | None = None,
           progress: Callable[[int, int, str], None] | None = None) -> ReduceResult:
    """Reduce the finger curves of ``source``; write the simplified clip to ``output`` when given.

    Parameters
    ----------
    source : path
        Animation file with a hand with finger joints and at least 2 frames.
    output : path, optional
        Copy of the input with every finger curve rebuilt from the chosen step's model.
    options : ReduceOptions
    model_output : path, optional
        Save the chosen step's reduction model as JSON (for :func:`usdhands.expand`).
    progress : callable, optional
        ``progress(done, total, what)``.

    Raises
    ------
    UsdHandsError
        Unreadable input, no hand with fingers, bad steps or step, a bad output path.
    """
    from usdhands.algorithms.reduction.reduce import parse_steps
    from usdhands.jobs.inputs import check_plot_folder

    source = Path(source)
    output = None if output is None else Path(output)
    model_output = None if model_output is None else Path(model_output)
    progress = progress or (lambda done, total, what="": None)
    parse_steps(options.steps)  # a bad step refused before any work
    write_opts = layer_options(options.as_layer, source, output) if output is not None else {}
    if options.as_layer and output is None:
        raise UsdHandsError("--as-layer needs -o OUT")
    from usdhands.jobs.plots.reduction import FILES

    check_paths({MAIN_INPUT: source, "--handmap": options.handmap}, {"-o": output, "--model": model_output})
    check_plot_folder(options.plot, FILES, {MAIN_INPUT: source, "--handmap": options.handmap})
    progress(0, 3, "reading")
    clip, handmap, curves, sides = load_finger_curves(source, options.animation, options.handmap, options.hands,
                                                      options.order)
    progress(1, 3, "reducing")
    result, k, paper, names = reduce_finger_curves(clip, handmap, curves, sides, options, source)
    chosen = result.steps[k - 1]

    if output is not None or model_output is not None or options.plot is not None:
        progress(2, 3, "writing")
    written = []
    if output is not None:
        from usdhands.algorithms.reduction.reduce import expand_clip
        from usdhands.formats.io import write_clip

        # what the expand job gives for this clip and model (the curves read for the model: the
        # same as these unless rotations jump between frames)
        out_clip = expand_clip(clip, curves.joints, chosen.model)
        from usdhands.model.provenance import provenance_record

        record = provenance_record("reduction", database=model_output, parameters={
            "step": k, "controlling": list(chosen.model.controlling_curves), "curves": len(chosen.model.curves)})
        written.append(write_clip(source, out_clip, output, provenance=record, **write_opts))
    if model_output is not None:
        model = chosen.model
        model = dataclasses.replace(model, metadata={
            **model.metadata, "paper_names": {c: paper[c] for c in model.curves if c in paper},
            "frames": int(clip.num_frames), "fps": float(clip.fps)})
        from usdhands.formats.registry import atomic_output

        with atomic_output(model_output) as tmp:  # an unwritable folder named in one line; SIGTERM cleaned up
            model.save(tmp)
        written.append(Path(model_output))
    if options.plot is not None:
        from usdhands.jobs.plots.reduction import plot_reduction

        written += plot_reduction(result, curves.values, options.plot, step=k - 1, paper_names=paper,
                                  fps=clip.fps)
    progress(3, 3, "done")
    return ReduceResult(source, int(clip.num_frames), float(clip.fps), tuple(names), tuple(sides), result, k, paper,
                        tuple(Path(w) for w in written))


def load_finger_curves(path: Path, animation, handmap_path, hands_arg, order: str):
    """Read a clip and the finger curves of the chosen hands (``hands_arg``: ``"left,right"``, a tuple of sides, or None: all).

    Returns ``(clip, handmap, curves, sides)``: ``curves`` a FingerCurves over the chosen
    hands' finger joints (left first), kept continuous through gimbal regions
    (:func:`~usdhands.algorithms.reduction.reduce.continuous_euler_curves`); ``sides`` the side
    of each curve. Curve names: :func:`~usdhands.algorithms.reduction.reduce.curve_names` (not
    ``curves.names``, which repeat when two joints share a short name).
    """
    from usdhands.formats.hands import hands_for
    from usdhands.formats.io import read_clip
    from usdhands.jobs.option_checks import parse_list
    from usdhands.model.handmap import SIDES

    _check_order(order)
    try:
        chosen = parse_list(hands_arg, SIDES) if isinstance(hands_arg, str) or hands_arg is None \
            else parse_list(",".join(hands_arg), SIDES)
    except UsdHandsError as e:
        raise UsdHandsError(f"--hands: {e.message}") from None
    clip = read_clip(path, animation=animation)
    handmap = hands_for(path, clip.skeleton, handmap_path)[0] if clip.num_frames >= 2 else None
    curves, sides = finger_curves_for(clip, handmap, chosen, order, path)
    return clip, handmap, curves, sides


def finger_curves_for(clip, handmap, hands, order: str, path):
    """The finger curves of ``clip``'s chosen ``hands`` (sides; empty: every hand with fingers).

    Returns ``(curves, sides)`` as :func:`load_finger_curves`; ``path`` names the clip in errors.
    """
    from usdhands.algorithms.reduction.reduce import continuous_euler_curves
    from usdhands.model.finger_dofs import finger_curves
    from usdhands.model.handmap import SIDES

    _check_order(order)
    if clip.num_frames < 2:
        raise UsdHandsError(f"the animation has {clip.num_frames} frame(s); finger curves need at least 2",
                            path=path)
    wanted = list(hands) or [h.side for h in handmap.sides if h.finger_joints]
    if not wanted:
        raise UsdHandsError("no hand with finger joints", path=path)
    joints, sides = [], []
    for side in SIDES:
        if side not in wanted:
            continue
        hand = handmap[side]
        if hand is None or not hand.finger_joints:
            found = ", ".join(h.side for h in handmap.sides if h.finger_joints) or "none"
            raise UsdHandsError(f"no {side} hand with fingers (hands found: {found})", path=path)
        for name in hand.finger_joints:
            joints.append(clip.skeleton.index(name))
            sides += [side] * 3
    curves = finger_curves(clip, joints, order.upper())
    curves = curves.with_values(continuous_euler_curves(curves.values))
    return curves, sides


def reduce_finger_curves(clip, handmap, curves, sides, options: ReduceOptions, source: Path):
    """Run the reduction steps of ``options`` on ``curves``: ``(reduction result, step used, paper names, curve names)``."""
    from usdhands.algorithms.reduction.reduce import curve_names, paper_style_names, parse_steps, reduce_curves

    steps = parse_steps(options.steps)
    names = curve_names(clip.skeleton, curves.joints, curves.order)
    result = reduce_curves(curves.values, names, steps,
                           groups=sides, across_groups=options.across_hands, order=curves.order,
                           source=source.name)
    k = len(result.steps) if options.step is None else options.step
    if not 1 <= k <= len(result.steps):
        raise UsdHandsError(f"--step {options.step} is out of range: {len(result.steps)} step(s) given")
    return result, k, paper_style_names(handmap, curves.order, clip.skeleton), names


def _check_order(order: str) -> None:
    o = order.upper()
    if len(o) != 3 or set(o) != set("XYZ"):
        raise UsdHandsError(f"bad --order {order!r}: expected a permutation of XYZ such as XYZ or ZYX")

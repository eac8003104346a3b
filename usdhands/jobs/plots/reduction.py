"""Plots of a finger DOF reduction, after the figures of Jörg and O'Sullivan 2009.

- ``reduction_ranges.png``: histogram of the curves' ranges with the range thresholds (figure 4);
- ``reduction_rmsd1.png``, ``reduction_rmsd2.png``: histograms of the pair distances with the
  rmsd thresholds (figures 6 and 7);
- ``reduction_scatter.png``: related pairs, one point per frame, successive frames joined,
  with the linear map of the model (figures 2 and 5);
- ``reduction_curves.png``: original against rebuilt dependent curves (figures 8 and 9).

matplotlib is imported inside :func:`plot_reduction` with the Agg backend.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Every file name a run may write into the plot folder (checked against the inputs first).
FILES = ("reduction_ranges.png", "reduction_rmsd1.png", "reduction_rmsd2.png", "reduction_scatter.png",
         "reduction_curves.png")

__all__ = ["plot_reduction"]


def plot_reduction(result, values: np.ndarray, out_dir: str | Path, *, step: int = -1,
                   paper_names: dict | None = None, fps: float = 30.0, max_panels: int = 4) -> list[Path]:
    """Draw the figures of a reduction into ``out_dir``.

    Parameters
    ----------
    result : ReductionResult
    values : (T, D) float
        Degrees: the original curves the result was made from.
    out_dir : path-like
        Created if absent.
    step : int
        Index of the step whose relations are drawn (default the last).
    paper_names : dict, optional
        Curve name to paper-style name, used in labels.
    fps : float
        Frames per second (time axis of the curve plot).
    max_panels : int
        At most this many pairs and curves are drawn.

    Returns
    -------
    list of Path
        The files written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from usdhands.algorithms.reduction.reduce import RangeRule, RmsdRule

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    names = list(result.names)
    col = {n: k for k, n in enumerate(names)}
    paper_names = paper_names or {}

    def label(c: str) -> str:
        return f"{c} ({paper_names[c]})" if c in paper_names else c

    rules = [s.rule for s in result.steps]
    written: list[Path] = []
    dpi = 80

    # figure 4: ranges (log axis: the thresholds of 1 and 5 degrees sit among ranges up to 100s)
    fig, ax = plt.subplots(figsize=(6, 3.2), dpi=dpi)
    rng = result.range
    floor = 1e-3
    top = max(float(rng.max()), 10.0)
    bins = np.geomspace(floor, top * 1.01, 31)
    ax.hist(np.maximum(rng, floor * 1.0001), bins=bins, color="#4c72b0", edgecolor="white")
    ax.set_xscale("log")
    for thr in sorted({r.threshold for r in rules if isinstance(r, RangeRule)}):
        ax.axvline(thr, color="#c44e52", ls="--", lw=1)
        ax.text(thr, ax.get_ylim()[1] * 0.95, f" {thr:g}", color="#c44e52", va="top", fontsize=8)
    still = int(np.sum(rng < floor))
    ax.set_xlabel("range of the curve (degrees, log scale)" + (f"; {still} never moving, drawn at {floor:g}"
                                                                 if still else ""), fontsize=8)
    ax.set_ylabel("curves")
    ax.set_title(f"Ranges of the {len(names)} finger curves", fontsize=10)
    written.append(_save(fig, out_dir / "reduction_ranges.png"))

    # figures 6 and 7: pair distances
    for kind, title in (("rmsd1", "positive slope"), ("rmsd2", "negative slope")):
        fig, ax = plt.subplots(figsize=(6, 3.2), dpi=dpi)
        vals = result.pair_values(kind)
        ax.hist(vals, bins=np.linspace(0, 2, 41), color="#55a868", edgecolor="white")
        for thr in sorted({r.threshold for r in rules if isinstance(r, RmsdRule) and kind in r.kinds}):
            ax.axvline(thr, color="#c44e52", ls="--", lw=1)
            ax.text(thr, ax.get_ylim()[1] * 0.95, f" {thr:g}", color="#c44e52", va="top", fontsize=8)
        ax.set_xlabel(f"{kind} of the standardised pair")
        ax.set_ylabel("pairs")
        ax.set_title(f"{kind} of {len(vals)} pairs ({title})", fontsize=10)
        written.append(_save(fig, out_dir / f"reduction_{kind}.png"))

    chosen = result.steps[step]
    relations = sorted(chosen.model.relations, key=lambda r: r.rmsd)[:max_panels]

    # figures 2 and 5: scatter plots of related pairs
    n = max(len(relations), 1)
    cols = min(n, 2)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(3.3 * cols, 3.0 * rows), dpi=dpi, squeeze=False)
    for ax in axes.flat:
        ax.set_visible(False)
    for ax, r in zip(axes.flat, relations):
        ax.set_visible(True)
        x, y = values[:, col[r.controlling]], values[:, col[r.dependent]]
        ax.plot(x, y, color="#8172b3", lw=0.4, alpha=0.6)
        ax.plot(x, y, ".", color="#4c72b0", ms=2)
        xs = np.array([x.min(), x.max()])
        ax.plot(xs, r.scale * xs + r.offset, color="#c44e52", lw=1)
        ax.set_xlabel(label(r.controlling), fontsize=7)
        ax.set_ylabel(label(r.dependent), fontsize=7)
        ax.set_title(f"{r.kind} = {r.rmsd:.2f}", fontsize=8)
        ax.tick_params(labelsize=7)
    if not relations:
        axes.flat[0].set_visible(True)
        axes.flat[0].text(0.5, 0.5, "no relations at this step", ha="center", va="center")
        axes.flat[0].set_axis_off()
    fig.suptitle(f"Related pairs, {chosen.condition} (degrees)", fontsize=9)
    written.append(_save(fig, out_dir / "reduction_scatter.png"))

    # figures 8 and 9: original against rebuilt
    deps = sorted(chosen.model.relations, key=lambda r: -r.dependent_std)[:max_panels]
    deps = deps or []
    n = max(len(deps), 1)
    fig, axes = plt.subplots(n, 1, figsize=(6.5, 1.9 * n + 0.4), dpi=dpi, squeeze=False, sharex=True)
    t = np.arange(values.shape[0]) / float(fps)
    rebuilt = chosen.model.apply(values, names)
    for ax, r in zip(axes[:, 0], deps):
        k = col[r.dependent]
        ax.plot(t, values[:, k], color="#4c72b0", lw=1, label="original")
        ax.plot(t, rebuilt[:, k], color="#c44e52", lw=1, ls="--", label=f"from {label(r.controlling)}")
        ax.set_ylabel(label(r.dependent), fontsize=7)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6, loc="upper right")
    if not deps:
        axes[0, 0].text(0.5, 0.5, "no dependent curves at this step", ha="center", va="center",
                        transform=axes[0, 0].transAxes)
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(f"Original and rebuilt curves (degrees), {chosen.condition}", fontsize=9)
    written.append(_save(fig, out_dir / "reduction_curves.png"))
    return written


def _save(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path

"""Plots for ``usdhands splice``: the cost matrices with band and path (the paper's figure 2)."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

#: Every file name a run may write into the plot folder (checked against the inputs first).
FILES = ("splice_left.png", "splice_right.png")


def plot_alignment(alignment, path: str | Path, *, title: str = "", constraints: Sequence = (),
                   truth: np.ndarray | None = None, hand_label: str = "hand frame", dpi: int = 64) -> Path:
    """Draw both passes of one hand's alignment into a PNG.

    Left: the first-pass cost (eq. 6) inside its band; middle: the second-pass cost
    (eq. 9, degrees) inside the narrow band around the first path; right: the hand
    frame used for each body frame. Band edges are white lines, the optimal paths
    red, user constraints yellow crosses (with their tolerance as a bar).

    Parameters
    ----------
    alignment : usdhands.algorithms.splicing.splice.SideAlignment
    path : path-like
        The PNG to write.
    constraints : sequence of Constraint
        Drawn on the matrices.
    truth : (n,) float, optional
        A known correct alignment, drawn dashed (for examples built with a known warp).
    hand_label : str
        Axis label of the hand frames (say so when HANDS was resampled).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    fig, axes = plt.subplots(1, 3, figsize=(13.5, 4.4), dpi=dpi)
    passes = ((alignment.first, "first pass: signs of derivatives (eq. 6)", "viridis"),
              (alignment.second, "second pass: hand angle (eq. 9), degrees", "magma"))
    for ax, (res, label, cmap) in zip(axes[:2], passes):
        m = res.cost_matrix()
        im = ax.imshow(m.T, origin="lower", aspect="auto", cmap=cmap, interpolation="nearest")
        rows = np.arange(res.band.n)
        ax.plot(rows, res.band.lo, color="white", lw=0.8)
        ax.plot(rows, res.band.hi, color="white", lw=0.8)
        ax.plot(res.path[:, 0], res.path[:, 1], color="red", lw=1.2)
        for c in constraints:
            ax.errorbar([c.body], [c.hand], yerr=[[c.tolerance], [c.tolerance]], fmt="x", color="yellow",
                        ms=8, mew=2, capsize=3)
        ax.set_xlabel("body frame")
        ax.set_ylabel(hand_label)
        ax.set_title(label, fontsize=10)
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02)
    ax = axes[2]
    n = alignment.alignment.shape[0]
    ax.plot(np.arange(n), alignment.alignment, color="red", lw=1.2, label="alignment (median)")
    if truth is not None:
        ax.plot(np.arange(n), truth, "k--", lw=1.0, label="known warp")
    if len(alignment.phases):
        ax.plot(alignment.phases[:, 0], alignment.phases[:, 1], "o", ms=3, color="tab:blue",
                label="phase boundaries")
    ax.set_xlabel("body frame")
    ax.set_ylabel(f"{hand_label} used")
    ax.set_title("merged alignment", fontsize=10)
    ax.legend(fontsize=8, loc="upper left")
    if title:
        fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path

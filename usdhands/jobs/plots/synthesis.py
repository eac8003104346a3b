"""PNG plots for ``synthesize`` and ``evaluate`` (matplotlib, Agg backend, imported on use)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Every file name a run may write into the plot folder (checked against the inputs first).
FILES = tuple(f"{side}_{what}.png" for side in ("left", "right") for what in ("segments", "graph", "fingers"))


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_segmentation(res, fps: float, threshold: float, path: Path, title: str = "") -> Path:
    """Wrist speed with the threshold and the segment boundaries (the paper's figure 4)."""
    plt = _plt()
    t = np.arange(len(res.speed)) / fps
    fig, ax = plt.subplots(figsize=(8, 2.6), dpi=90)
    ax.plot(t, res.speed, lw=1, color="k", label="wrist speed")
    ax.axhline(threshold, color="tab:orange", lw=0.8, ls="--", label=f"threshold {threshold:g} cm/s")
    for b in res.bounds[1:-1]:
        ax.axvline(b / fps, color="tab:blue", lw=0.8)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("cm/s")
    ax.set_title(title or f"{res.side} hand: {len(res.bounds) - 1} segments", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_graph(res, labels: list, path: Path, max_rows: int = 14, title: str = "", max_cols: int = 8) -> Path:
    """The layered graph: rows = input segments, nodes = k candidates with cS, chosen path in red (figure 3).

    At most ``max_rows`` rows and ``max_cols`` candidates per row are drawn (the
    cheapest; a chosen node further down its row takes the last place, marked with
    its rank), so a large ``k`` still gives a readable picture.
    """
    plt = _plt()
    N, k = res.candidates.shape
    rows = min(N, max_rows)
    cols = min(k, max_cols)
    shown = []
    for i in range(rows):
        c = list(range(cols))
        if res.path[i] not in c:
            c[-1] = int(res.path[i])
        shown.append(c)
    fig, ax = plt.subplots(figsize=(1.6 * cols + 1, 0.55 * rows + 0.8), dpi=90)
    for i in range(rows):
        for x, j in enumerate(shown[i]):
            if res.candidates[i, j] < 0:
                continue
            on = res.path[i] == j
            ax.add_patch(plt.Rectangle((x - 0.42, -i - 0.3), 0.84, 0.6, fill=True,
                                       fc="mistyrose" if on else "white", ec="red" if on else "0.6", lw=1.5 if on else 0.6))
            lab = labels[res.candidates[i, j]] or ""
            rank = f" (#{j + 1})" if j >= cols else ""
            ax.text(x, -i, f"{lab[:10]}\n{res.segment_costs[i, j]:.0f}{rank}", ha="center", va="center", fontsize=6)
        if i + 1 < rows:
            ax.annotate("", xy=(shown[i + 1].index(int(res.path[i + 1])), -i - 1 + 0.3),
                        xytext=(shown[i].index(int(res.path[i])), -i - 0.3),
                        arrowprops=dict(arrowstyle="->", color="red", lw=1.2))
    ax.set_xlim(-0.6, cols - 0.4)
    ax.set_ylim(-rows + 0.4, 0.6)
    ax.axis("off")
    more = f" (first {rows} of {N})" if N > rows else ""
    some = f", the {cols} cheapest drawn" if k > cols else ""
    ax.set_title(title or f"{res.side} hand: k={k} candidates per segment{more}{some}; label and segment cost",
                 fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_finger_curves(times: np.ndarray, before: np.ndarray, after: np.ndarray, names: list[str], path: Path,
                       bounds_s: np.ndarray | None = None, title: str = "") -> Path:
    """Finger curves of the input (dashed) and the result (solid)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 3), dpi=90)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for c in range(after.shape[1]):
        col = colors[c % len(colors)]
        ax.plot(times, before[:, c], ls="--", lw=0.7, color=col)
        ax.plot(times, after[:, c], lw=1.1, color=col, label=names[c])
    if bounds_s is not None:
        for b in bounds_s:
            ax.axvline(b, color="0.8", lw=0.6, zorder=0)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("degrees")
    ax.set_title(title or "finger curves: input dashed, synthesized solid", fontsize=9)
    ax.legend(fontsize=6, ncol=4, loc="upper right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_predictors(result: dict, path: Path) -> Path:
    """Share of correctly typed neighbours per predictor (the paper's figure 7)."""
    plt = _plt()
    names = list(result["predictors"])
    vals = [100 * result["predictors"][n] for n in names]
    fig, ax = plt.subplots(figsize=(7, 0.32 * len(names) + 1.2), dpi=90)
    y = np.arange(len(names))[::-1]
    ax.barh(y, vals, color=["tab:red" if n == result["best"] else "tab:blue" for n in names])
    for yy, v in zip(y, vals):
        ax.text(v + 0.5, yy, f"{v:.0f}%", va="center", fontsize=7)
    if "chance" in result:
        ax.axvline(100 * result["chance"], color="0.4", ls="--", lw=0.8, label=f"chance {100 * result['chance']:.0f}%")
        ax.legend(fontsize=7, loc="lower right")
    ax.set_yticks(y, names, fontsize=8)
    ax.set_xlim(0, 105)
    ax.set_xlabel(f"% of the k={result['k']} closest segments of the right type")
    ax.set_title(f"leave-one-out over {result['segments']} segments", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_confusion(result: dict, path: Path) -> Path:
    """Class confusion matrix in percent (the paper's figure 8)."""
    plt = _plt()
    labels = result["confusion"]["labels"]
    m = 100 * np.asarray(result["confusion"]["matrix"])
    fig, ax = plt.subplots(figsize=(0.6 * len(labels) + 2, 0.55 * len(labels) + 1.5), dpi=90)
    ax.imshow(m, cmap="Blues", vmin=0, vmax=100)
    for i in range(len(labels)):
        for j in range(len(labels)):
            ax.text(j, i, f"{m[i, j]:.0f}", ha="center", va="center", fontsize=7,
                    color="white" if m[i, j] > 60 else "black")
    ax.set_xticks(range(len(labels)), labels, rotation=45, ha="right", fontsize=7)
    ax.set_yticks(range(len(labels)), labels, fontsize=7)
    ax.set_xlabel("type of the closest segments")
    ax.set_ylabel("true type")
    ax.set_title(f"confusion, {result['confusion']['predictor']} (%)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_kfold_errors(result: dict, path: Path) -> Path:
    """K-fold finger error per method, overall and on the most expressive quarter of the frames."""
    plt = _plt()
    names = list(result["methods"])
    overall = [result["methods"][n]["error_deg"] for n in names]
    expressive = [result["methods"][n]["expressive_error_deg"] for n in names]
    fig, ax = plt.subplots(figsize=(7, 0.4 * len(names) + 1.4), dpi=90)
    y = np.arange(len(names))[::-1]
    ax.barh(y + 0.2, overall, height=0.4, color="tab:blue", label="all frames")
    ax.barh(y - 0.2, expressive, height=0.4, color="tab:orange", label="most expressive quarter")
    for yy, a, b in zip(y, overall, expressive):
        ax.text(a, yy + 0.2, f" {a:.1f}", va="center", fontsize=7)
        ax.text(b, yy - 0.2, f" {b:.1f}", va="center", fontsize=7)
    ax.set_yticks(y, names, fontsize=8)
    ax.set_xlabel("mean finger-joint angle error (deg)")
    ax.set_title(f"{result['folds']}-fold held-out synthesis, {result['windows']} windows", fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_worst_window(result: dict, path: Path) -> Path:
    """Real against synthesized curves of the window where synthesis errs most (its three widest DOFs)."""
    plt = _plt()
    w = result["worst_window"]
    truth, syn = np.asarray(w["truth"]), np.asarray(w["synthesis"])
    fig, ax = plt.subplots(figsize=(7, 3), dpi=90)
    t = np.arange(truth.shape[1]) if truth.size else np.zeros(0)
    for i, name in enumerate(w["dofs"]):
        color = f"C{i}"
        ax.plot(t, truth[i], color=color, ls="--", lw=1, label=f"{name} real")
        ax.plot(t, syn[i], color=color, lw=1.2, label=f"{name} synthesized")
    ax.set_xlabel(f"frame in window (frames {w['frames'][0]}..{w['frames'][1]} of the take)")
    ax.set_ylabel("degrees")
    ax.set_title(f"worst window: {w['clip']} {w['side']}, fold {w['fold']}, error {w['error_deg']:.1f} deg", fontsize=9)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path

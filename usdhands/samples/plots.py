"""Pictures of the generated gestures (for the docs): body at the hold, wrist paths, hand shapes."""

from __future__ import annotations

import os

import numpy as np

from usdhands.samples.gestures import GESTURE_TYPES, gesture_take

__all__ = ["hold_frame", "plot_gestures"]


def hold_frame(clip, side: str = "Right") -> int:
    """The frame of least wrist speed in the middle half of a take (inside the hold)."""
    w = clip.world_positions_cm()[:, clip.skeleton.index(f"{side}Hand")]
    sp = np.linalg.norm(np.diff(w, axis=0), axis=1)
    T = len(sp)
    return int(np.argmin(sp[T // 4:3 * T // 4]) + T // 4)


def plot_gestures(path: str | os.PathLike, takes: tuple[int, ...] = (0, 1, 2, 3), seed: int = 0) -> None:
    """Write a PNG: per type, the body at the hold (front and side) with the right wrist's
    path over several takes, and the right hand's shape at the hold (palm view).

    Parameters
    ----------
    path : path of the PNG
    takes : which takes to draw the wrist paths of (the first is drawn as a body)
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(3, len(GESTURE_TYPES), figsize=(16, 7.2),
                            gridspec_kw={"height_ratios": [1.25, 1.25, 0.9]})
    colors = plt.cm.viridis(np.linspace(0, 0.85, len(takes)))
    for gi, g in enumerate(GESTURE_TYPES):
        clips = [gesture_take(g, k, seed) for k in takes]
        c = clips[0]
        sk = c.skeleton
        f = hold_frame(c)
        w = c.world_positions_cm()
        r = sk.index("RightHand")
        for row, (a, b, xlim) in enumerate([(0, 1, (-75, 75)), (2, 1, (-40, 70))]):
            ax = axs[row, gi]
            for j, p in enumerate(sk.parents):
                if p >= 0:
                    ax.plot([w[f, j, a], w[f, p, a]], [w[f, j, b], w[f, p, b]], "-", color="0.35", lw=0.8)
            for cc, col in zip(clips, colors):
                ww = cc.world_positions_cm()[:, r]
                ax.plot(ww[:, a], ww[:, b], "-", color=col, lw=1.0)
            ax.set_xlim(*xlim)
            ax.set_ylim(60, 185)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(g.replace("_", " "), fontsize=11)
            if gi == 0:
                ax.set_ylabel("front" if row == 0 else "side (facing right)")
        # the hand in its own frame: palm view
        ax = axs[2, gi]
        X = c.world_xforms()[f]
        inv = np.linalg.inv(X[r])
        P = (inv @ np.concatenate([X[:, :3, 3], np.ones((sk.num_joints, 1))], axis=1).T).T[:, :3]
        for j, n in enumerate(sk.short_names):
            if n.startswith("RightHand") and n != "RightHand":
                p = sk.parents[j]
                ax.plot([-P[j, 0], -P[p, 0]], [P[j, 1], P[p, 1]], "-o", color="k", ms=1.5, lw=1.0)
        ax.set_xlim(-10, 10)
        ax.set_ylim(-2, 20)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        if gi == 0:
            ax.set_ylabel("right hand")
    fig.suptitle("Generated gesture database: body at the hold of take 0, right-wrist paths of takes "
                 f"{', '.join(map(str, takes))}, hand shape at the hold", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=60)
    plt.close(fig)

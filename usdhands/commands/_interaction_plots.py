"""Pictures of a correction: penetration depth over time, and the worst frame before and after."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_correction(folder: Path, before, after, handmap, colliders, report, config) -> list[Path]:
    """Write ``penetration_depth.png`` and ``worst_frame.png`` into ``folder``; returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.spatial import ConvexHull, QhullError

    from usdhands.algorithms.interaction.colliders import MeshCollider
    from usdhands.algorithms.interaction.correction import chain_posers
    from usdhands.formats.registry import atomic_output

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    t = before.times - before.start_time
    fig, ax = plt.subplots(figsize=(8, 3.2))
    ax.plot(t, report.penetration_before_mm, color="tab:red", label="before")
    ax.plot(t, report.penetration_after_mm, color="tab:green", label="after")
    ax.axhline(0.5, color="grey", lw=0.8, ls="--", label="0.5 mm")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("deepest finger penetration (mm)")
    ax.legend(loc="upper right")
    fig.tight_layout()
    out = folder / "penetration_depth.png"
    with atomic_output(out) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    paths.append(out)

    worst = int(np.argmax(report.penetration_before_mm))
    fig = plt.figure(figsize=(9, 4.5))
    up = 1 if before.skeleton.up_axis == "Y" else 2
    side_axis = 0
    for col, (clip, title) in enumerate(((before, "before"), (after, "after"))):
        ax = fig.add_subplot(1, 2, col + 1)
        posers = chain_posers(clip, handmap, config)
        centre = None
        for poser in posers:
            pts = poser.given_points[worst]
            r = float(poser.chain.radii.mean())
            if centre is None:
                centre = pts.mean(axis=0)
            ax.plot(pts[:, side_axis], pts[:, up], "-o", color="tab:blue", lw=r * 72 * 0.9 / _scale(clip), ms=2,
                    alpha=0.7, solid_capstyle="round")
        for c in colliders.items:
            if isinstance(c, MeshCollider):
                v = c.proximity.vertices @ c.world[worst, :3, :3].T + c.world[worst, :3, 3]
                flat = v[:, [side_axis, up]]
                try:
                    hull = ConvexHull(flat)
                    ax.fill(flat[hull.vertices, 0], flat[hull.vertices, 1], color="tab:brown", alpha=0.3, lw=0)
                except QhullError:  # a flat prop seen edge-on
                    ax.plot(flat[:, 0], flat[:, 1], ",", color="tab:brown")
        depth = (report.penetration_before_mm if col == 0 else report.penetration_after_mm)[worst]
        ax.set_title(f"{title}: frame {worst}, {depth:.2f} mm deep")
        ax.set_aspect("equal")
        if centre is not None:
            span = 12.0 * 0.01 / clip.skeleton.meters_per_unit
            ax.set_xlim(centre[side_axis] - span, centre[side_axis] + span)
            ax.set_ylim(centre[up] - span, centre[up] + span)
        ax.set_xlabel("x (clip units)")
        ax.set_ylabel("up (clip units)")
    fig.tight_layout()
    out = folder / "worst_frame.png"
    with atomic_output(out) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    paths.append(out)
    return paths


def _scale(clip) -> float:
    """Data units per inch of the worst-frame panels (24 cm over about 4 inches)."""
    return 24.0 * 0.01 / clip.skeleton.meters_per_unit / 4.0

"""Pictures of a correction: penetration depth over time, and the worst frame before and after."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Every file name a run may write into the plot folder (checked against the inputs first).
FILES = ("penetration_depth.png", "worst_frame.png")


def plot_correction(folder: Path, before, after, handmap, colliders, report, config) -> list[Path]:
    """Write ``penetration_depth.png`` and ``worst_frame.png`` into ``folder``; returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.spatial import ConvexHull, QhullError

    from usdhands.algorithms.interaction.colliders import MeshCollider
    from usdhands.algorithms.interaction.correction import chain_posers

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
    paths.append(_save(fig, folder / "penetration_depth.png"))

    worst = int(np.argmax(report.penetration_before_mm))
    fig = plt.figure(figsize=(9, 4.5))
    span = 12.0 * 0.01 / before.skeleton.meters_per_unit
    focus = [p for p in chain_posers(before, handmap, config) if p.chain.name in report.chains_corrected]
    focus = focus or chain_posers(before, handmap, config)
    pts = np.concatenate([p.given_points[worst] for p in focus])
    centre = pts.mean(axis=0)
    normal = np.zeros(3)  # look along the fingers' flexion axis: the normal of each finger's curl plane
    for p in focus:
        q = p.given_points[worst] - p.given_points[worst].mean(axis=0)
        n = np.linalg.svd(q)[2][-1]
        normal += n * np.sign(n[np.argmax(np.abs(n))])
    flat_axis = int(np.argmax(np.abs(normal)))
    u, v = [a for a in range(3) if a != flat_axis]
    names = "XYZ"
    for col, (clip, title) in enumerate(((before, "before"), (after, "after"))):
        ax = fig.add_subplot(1, 2, col + 1)
        for c in colliders.items:
            if not isinstance(c, MeshCollider):
                continue
            verts = c.proximity.vertices @ c.world[worst, :3, :3].T + c.world[worst, :3, 3]
            near = np.all(np.abs(verts - centre) < 2 * span, axis=1)
            if near.sum() < 3:
                continue
            flat = verts[near][:, [u, v]]
            try:
                hull = ConvexHull(flat)
                ax.fill(flat[hull.vertices, 0], flat[hull.vertices, 1], color="tab:brown", alpha=0.25, lw=0)
            except QhullError:  # a flat prop seen edge-on
                ax.plot(flat[:, 0], flat[:, 1], ",", color="tab:brown")
        for poser in chain_posers(clip, handmap, config):
            if poser.chain.name not in [p.chain.name for p in focus]:
                continue
            q = poser.given_points[worst]
            r = float(poser.chain.radii.mean())
            ax.plot(q[:, u], q[:, v], "-o", color="tab:blue", lw=2 * r / span * 4.0 * 72 / 2, ms=2,
                    alpha=0.6, solid_capstyle="round")
        depth = (report.penetration_before_mm if col == 0 else report.penetration_after_mm)[worst]
        ax.set_title(f"{title}: frame {worst}, {depth:.2f} mm deep")
        ax.set_aspect("equal")
        ax.set_xlim(centre[u] - span, centre[u] + span)
        ax.set_ylim(centre[v] - span, centre[v] + span)
        ax.set_xlabel(f"{names[u]} (clip units)")
        ax.set_ylabel(f"{names[v]} (clip units)")
    paths.append(_save(fig, folder / "worst_frame.png"))
    return paths


def _save(fig, path: Path) -> Path:
    """Write ``fig`` as a PNG atomically and close it."""
    import matplotlib.pyplot as plt

    from usdhands.formats.registry import atomic_output

    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return path

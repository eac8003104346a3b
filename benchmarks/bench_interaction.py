"""Benchmark: ``usdhands correct`` on 60 s at 30 fps, both hands, the 24,544-triangle mug in the
left hand's path (tests/interaction_data.py: the left arm sweeps, all fingers curl every 3 s).

Measured in the same run:

- ``usdhands``: ``correct_clip`` end to end (broad phase, detection, RTS smoothing, bisection
  for the bound, bounded smoothing, re-test), without and with the before/after measure;
- baseline: the naive detection a first implementation would write: every frame, every
  finger capsule, points every 1 mm along the axis, ``trimesh.proximity.signed_distance``
  on each (timed on a sample of frames, scaled to the clip). It only detects; it corrects nothing.

And ``synthesize --props`` against plain synthesis of the same 60 s clip (the bundled
database; library calls: synthesis with the proximity cuts and the collision term, then the
correction of the result; the synthesize job end to end, in both engine states: without
numba, as one command and a batch worker run it (the kernels compiled ahead of time where the
install built them, else NumPy), and with numba's kernels loaded; and the ``usdhands synthesize``
command in fresh processes, as a user runs it), target within 2x.

Run: ``python benchmarks/bench_interaction.py [--seconds S] [--naive-frames N] [--no-synthesis] [--fresh N]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from interaction_data import grasping_clip, grasping_mug_position  # noqa: E402

from usdhands.algorithms.interaction.colliders import Colliders, mesh_collider  # noqa: E402
from usdhands.algorithms.interaction.correction import chain_posers, correct_clip  # noqa: E402
from usdhands.algorithms.interaction.finger_geometry import InteractionConfig  # noqa: E402
from usdhands.formats.props import read_props  # noqa: E402
from usdhands.model.finger_dofs import finger_curves  # noqa: E402
from usdhands.model.prop import PropMesh  # noqa: E402
from usdhands.samples.humanoid import humanoid_handmap  # noqa: E402

MUG = ROOT.parent / "shared" / "assets" / "mujoco_mug" / "mug.obj"


def naive_detection(clip, posers, mesh, frames) -> float:
    """Seconds for trimesh signed_distance at 1 mm axis samples of every capsule on ``frames``."""
    import trimesh

    mm = 0.001 / clip.skeleton.meters_per_unit
    start = time.perf_counter()
    for poser in posers:
        n = len(poser.chain.joints)
        angles = finger_curves(clip, poser.chain.joints).values.reshape(clip.num_frames, n, 3)
        a, b = poser.capsules(frames, angles[frames])
        for k in range(n):
            length = np.linalg.norm(b[:, k] - a[:, k], axis=1).max()
            t = np.linspace(0, 1, int(np.ceil(length / mm)) + 1)
            pts = a[:, k, None] + t[None, :, None] * (b[:, k] - a[:, k])[:, None]
            trimesh.proximity.signed_distance(mesh, pts.reshape(-1, 3))
    return time.perf_counter() - start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--naive-frames", type=int, default=30, help="frames the naive baseline is timed on")
    ap.add_argument("--no-synthesis", action="store_true", help="skip the synthesize --props comparison")
    ap.add_argument("--repeat", type=int, default=5, help="alternating runs of each synthesize job timed (medians)")
    ap.add_argument("--fresh", type=int, default=7,
                    help="fresh usdhands processes of each kind timed, alternating (medians; 0: none)")
    args = ap.parse_args()
    import trimesh

    from usdhands.algorithms.synthesis import segment_cost

    # no synthesis here loads numba, as one command does not, until the last row loads it (without the
    # kernels compiled ahead of time the process would load it after 20 M NumPy cells, mid-comparison)
    segment_cost.NUMPY_SEARCH_PROCESS_CELLS = float("inf")

    clip = grasping_clip(args.seconds)
    hm = humanoid_handmap(clip.skeleton)
    (mug,) = read_props(MUG, meters_per_unit=clip.skeleton.meters_per_unit, up_axis="Y",
                        prop_meters_per_unit=0.01)
    mug = PropMesh(mug.name, np.asarray(mug.vertices) + grasping_mug_position(), mug.faces)
    t0, c0 = time.perf_counter(), time.process_time()
    cols = Colliders([mesh_collider(mug, clip.times)])
    out, report = correct_clip(clip, hm, cols, measure=False)
    correct_s, correct_cpu = time.perf_counter() - t0, time.process_time() - c0
    correct_queries = exact_queries(cols)
    t0 = time.perf_counter()
    cols = Colliders([mesh_collider(mug, clip.times)])
    out, report = correct_clip(clip, hm, cols)
    measured_s = time.perf_counter() - t0
    measured_queries = exact_queries(cols)
    posers = chain_posers(clip, hm, InteractionConfig())
    mesh = trimesh.Trimesh(np.asarray(mug.vertices), np.asarray(mug.faces), process=False)
    sample = np.linspace(0, clip.num_frames - 1, args.naive_frames).round().astype(int)
    naive_s = naive_detection(clip, posers, mesh, sample) * clip.num_frames / len(sample)
    d = report.to_dict()
    print(f"clip: {clip.num_frames} frames at {clip.fps:g} fps, both hands ({len(posers)} finger chains), "
          f"mug {len(mug.faces)} triangles")
    print(f"penetration before: max {d['penetration_before_mm']['max']:.2f} mm, mean "
          f"{d['penetration_before_mm']['mean']:.2f} mm, {d['penetration_before_mm']['frames']} frames")
    print(f"penetration after:  max {d['penetration_after_mm']['max']:.3f} mm, mean "
          f"{d['penetration_after_mm']['mean']:.3f} mm, {d['penetration_after_mm']['frames']} frames")
    print(f"frames corrected {d['frames_corrected']}, jitter {d['jitter_before']:.1f} -> {d['jitter_after']:.1f} "
          f"deg/s^2, max change {d['max_change_deg']:.1f} deg")
    print(f"usdhands correct (collider build + correction incl. smoothing): {correct_s:.2f} s wall, "
          f"{correct_cpu:.2f} s CPU, {correct_queries} exact distance queries  (target < 2 s)")
    print(f"  with the before/after measure: {measured_s:.2f} s, {measured_queries} queries")
    print(f"naive trimesh signed_distance detection, 1 mm axis samples, scaled from {len(sample)} frames: "
          f"{naive_s:.1f} s")
    print(f"ratio naive / usdhands: {naive_s / correct_s:.0f}x  (target >= 100x)")
    if not args.no_synthesis:
        plain, parts = synthesis_times(clip, hm, mug)
        total = {k: sum(v[k] for v in parts.values()) for k in ("wall", "cpu")}
        print(f"synthesize (library): plain {plain['wall']:.2f} s wall / {plain['cpu']:.2f} s CPU, with props "
              f"{total['wall']:.2f} / {total['cpu']:.2f} (CPU: input posed, colliders and terms set up "
              f"{parts['setup']['cpu']:.2f}, synthesis with the cuts and the collision term "
              f"{parts['synthesis']['cpu']:.2f}, correction of the result with its report "
              f"{parts['correction']['cpu']:.2f}), ratio {total['wall'] / plain['wall']:.2f}x wall, "
              f"{total['cpu'] / plain['cpu']:.2f}x CPU  (target <= 2x)")
        print(f"  exact distance queries: set up {parts['setup']['queries']}, synthesis {parts['synthesis']['queries']}, "
              f"correction {parts['correction']['queries']}, total "
              f"{sum(v['queries'] for v in parts.values())}")
        r = parts["correction"]["report"]
        d = r.to_dict()
        print(f"  the synthesized result, penetration before its correction: max {d['penetration_before_mm']['max']:.2f} "
              f"mm, mean {d['penetration_before_mm']['mean']:.2f} mm, {d['penetration_before_mm']['frames']} frames; "
              f"after: max {d['penetration_after_mm']['max']:.3f} mm, mean {d['penetration_after_mm']['mean']:.3f} mm, "
              f"{d['penetration_after_mm']['frames']} frames; jitter {d['jitter_before']:.1f} -> {d['jitter_after']:.1f} "
              f"deg/s^2; chains corrected: {', '.join(r.chains_corrected) or 'none'}")
        for state, (plain_job, props_job) in synthesize_job_times(clip, mug, args.repeat).items():
            print(f"synthesize job end to end (read .glb, synthesize, write .glb), {state}: plain "
                  f"{plain_job['wall']:.2f} s wall / {plain_job['cpu']:.2f} s CPU, --props {props_job['wall']:.2f} / "
                  f"{props_job['cpu']:.2f}, ratio {props_job['wall'] / plain_job['wall']:.2f}x wall, "
                  f"{props_job['cpu'] / plain_job['cpu']:.2f}x CPU (medians of {args.repeat} alternating runs, "
                  f"load {os.getloadavg()[0]:.1f})")
        if args.fresh:
            plain_cmd, props_cmd = fresh_command_times(clip, mug, args.fresh)
            print(f"usdhands synthesize in a fresh process (read .glb, synthesize, write .glb), as a user runs it: "
                  f"plain {plain_cmd['wall']:.3f} s wall / {plain_cmd['cpu']:.3f} s CPU, --props mug.obj "
                  f"{props_cmd['wall']:.3f} / {props_cmd['cpu']:.3f}, ratio {props_cmd['wall'] / plain_cmd['wall']:.2f}x "
                  f"wall, {props_cmd['cpu'] / plain_cmd['cpu']:.2f}x CPU (medians of {args.fresh} alternating "
                  f"processes, load {os.getloadavg()[0]:.1f})  (target <= 2x)")


def write_inputs(clip, mug, folder: Path) -> tuple[Path, Path]:
    """The clip as ``grasping.glb`` and the mug as ``mug.obj`` in ``folder``, as a user would give them: the
    .glb is read back in metres, an OBJ is taken in the clip's units (so the mug is written in metres)."""
    import trimesh

    from usdhands.formats.io import write_asset
    from usdhands.model.asset import Asset

    src, prop = folder / "grasping.glb", folder / "mug.obj"
    write_asset(Asset("grasping", (clip.skeleton,), (clip,)), src)
    trimesh.Trimesh(np.asarray(mug.vertices) * clip.skeleton.meters_per_unit, np.asarray(mug.faces),
                    process=False).export(prop)
    return src, prop


def fresh_command_times(clip, mug, repeat: int) -> tuple[dict, dict]:
    """Wall and CPU seconds (medians of ``repeat`` processes alternating the two) of ``python -m usdhands
    synthesize`` of the clip written as .glb, without and with the mug as an OBJ prop: what a user waits
    for, imports and all (each command run once first, untimed: bytecode and kernel caches warm)."""
    import resource
    import subprocess
    import tempfile

    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    with tempfile.TemporaryDirectory() as tmp:
        src, prop = write_inputs(clip, mug, Path(tmp))
        base = [sys.executable, "-m", "usdhands", "synthesize", str(src), "-q"]
        cmds = {"plain": base + ["-o", str(Path(tmp) / "plain.glb")],
                "props": base + ["--props", str(prop), "-o", str(Path(tmp) / "props.glb")]}
        runs = {k: [] for k in cmds}
        for i in range(repeat + 1):
            for k, cmd in cmds.items():
                before = resource.getrusage(resource.RUSAGE_CHILDREN)
                t0 = time.perf_counter()
                subprocess.run(cmd, env=env, check=True, stdout=subprocess.DEVNULL)
                wall = time.perf_counter() - t0
                after = resource.getrusage(resource.RUSAGE_CHILDREN)
                if i:  # the first of each is not timed
                    runs[k].append({"wall": wall, "cpu": after.ru_utime - before.ru_utime + after.ru_stime
                                    - before.ru_stime})
    return tuple({m: float(np.median([r[m] for r in runs[k]])) for m in ("wall", "cpu")} for k in cmds)


def exact_queries(colliders) -> int:
    """Points measured exactly so far by the mesh colliders of ``colliders``."""
    return sum(getattr(c, "exact_queries", 0) for c in colliders.items)


def _timed(fn, repeat: int = 1) -> tuple[dict, object]:
    """``({"wall", "cpu"}, result)``: the best of ``repeat`` calls of ``fn`` (seconds)."""
    best, out = None, None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        t = {"wall": time.perf_counter() - t0, "cpu": time.process_time() - c0}
        best = t if best is None or t["cpu"] < best["cpu"] else best
    return best, out


def synthesize_job_times(clip, mug, repeat: int = 5) -> dict:
    """Seconds (wall and CPU, medians of ``repeat`` runs alternating the two) of the synthesize job on the
    clip written as .glb, without and with the mug as an OBJ prop, ``{state: (plain, props)}``: first
    without numba, as one ``usdhands synthesize`` of a clip and a batch worker run it (the search and the
    interaction's kernels compiled ahead of time where the install built them, else the NumPy twins),
    then with numba's search kernel loaded (a process that searched beyond the compiled search's size).

    Both jobs of a pair run in the same state: a process loads the kernel once it has searched
    ``NUMPY_SEARCH_PROCESS_CELLS`` in NumPy, so timing all plain runs and then all ``--props`` runs
    compared a NumPy search with a compiled one (the benchmark did so before session 7)."""
    import tempfile

    from usdhands.algorithms.synthesis import segment_cost
    from usdhands.jobs.synthesis import SynthesizeOptions, synthesize

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        src, prop = write_inputs(clip, mug, Path(tmp))
        jobs = {"plain": lambda: synthesize(src, Path(tmp) / "plain.glb"),
                "props": lambda: synthesize(src, Path(tmp) / "props.glb", SynthesizeOptions(props=(prop,)))}
        for state in ("no numba (one command, batch worker)", "numba's kernels loaded"):
            if state.startswith("numba"):
                segment_cost.load_search_kernel()
            for job in jobs.values():
                job()  # the database, the first query's set-up, outside the timing
            runs = {k: [] for k in jobs}
            for _ in range(repeat):
                for k, job in jobs.items():
                    runs[k].append(_timed(job)[0])
            out[state] = tuple({m: float(np.median([t[m] for t in runs[k]])) for m in ("wall", "cpu")} for k in jobs)
        return out


def synthesis_times(clip, hm, mug) -> tuple[dict, dict]:
    """Seconds (wall and CPU) of plain synthesis and of the parts of synthesis with the mug, as the
    synthesize job runs them (the input posed once; hooks; the final correction with its report)."""
    from types import SimpleNamespace

    from usdhands.algorithms.synthesis.config import SynthesisConfig
    from usdhands.algorithms.synthesis.database import load_database
    from usdhands.algorithms.synthesis.synthesize import synthesize_clip
    from usdhands.jobs.inputs import bundled_database_path
    from usdhands.jobs.props import synthesis_interaction

    db = load_database(bundled_database_path())
    cfg = SynthesisConfig()
    synthesize_clip(clip.slice(0, 60), hm, db, cfg)  # compile the kernels outside the timing
    plain, _ = _timed(lambda: synthesize_clip(clip, hm, db, cfg))
    args = SimpleNamespace(attach=[], self_collision=False, margin=0.0, collision_weight=1.0, file="bench")
    parts = {}

    def setup():
        world = clip.world_xforms()
        return world, synthesis_interaction(args, clip, hm, db, cfg, [(Path("mug.obj"), mug)], InteractionConfig(),
                                            world=world)

    parts["setup"], (world, (factory, cols)) = _timed(setup)
    parts["setup"]["queries"] = exact_queries(cols)
    parts["synthesis"], result = _timed(lambda: synthesize_clip(clip, hm, db, cfg, interaction=factory))
    parts["synthesis"]["queries"] = exact_queries(cols) - parts["setup"]["queries"]
    parts["correction"], (_, report) = _timed(lambda: correct_clip(result.clip, hm, cols, world=world))
    parts["correction"]["queries"] = exact_queries(cols) - parts["setup"]["queries"] - parts["synthesis"]["queries"]
    parts["correction"]["report"] = report
    return plain, parts


if __name__ == "__main__":
    main()

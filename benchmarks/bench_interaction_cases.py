"""Penetration and jitter before and after ``correct_clip`` on every interaction case we have.

- ``bench``: the benchmark's 60 s sweep over the 24,544-triangle mug (tests/interaction_data.py);
- ``cup_grasp``, ``table_rest``, ``scratch_head`` (``--self`` and the table): the samples, as
  ``usdhands samples`` writes them (built in memory here);
- ``leap_typing``: ``../shared/assets/leap_hands/gesture-typing.bvh`` (a captured right hand,
  read in millimetres) over a box placed in the hand's path, its top 6 mm above the lowest
  fingertip's skin, so the typing fingers go into it.

Per case: penetration before/after (mm, max), jitter before/after (mean absolute finger
angular acceleration, deg/s^2), frames corrected, unresolved chain frames, the largest and the
mean change of a corrected finger's joint rotations (degrees), seconds.

Run: ``python benchmarks/bench_interaction_cases.py [--cases bench,cup_grasp,...]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from interaction_data import grasping_clip, grasping_mug_position  # noqa: E402

from usdhands.algorithms.interaction.body import body_collider  # noqa: E402
from usdhands.algorithms.interaction.colliders import Colliders, attached_xforms, mesh_collider  # noqa: E402
from usdhands.algorithms.interaction.correction import chain_posers, correct_clip  # noqa: E402
from usdhands.algorithms.interaction.finger_geometry import InteractionConfig  # noqa: E402
from usdhands.model.finger_dofs import finger_curves  # noqa: E402
from usdhands.model.prop import PropMesh  # noqa: E402
from usdhands.model.rotations import quat_angle_deg  # noqa: E402

ASSETS = ROOT.parent / "shared" / "assets"


def _prop(mesh, name: str) -> PropMesh:
    return PropMesh(name, np.asarray(mesh.vertices), np.asarray(mesh.faces))


def case_bench():
    from usdhands.formats.props import read_props
    from usdhands.samples.humanoid import humanoid_handmap

    clip = grasping_clip(60.0)
    (mug,) = read_props(ASSETS / "mujoco_mug" / "mug.obj", meters_per_unit=clip.skeleton.meters_per_unit,
                        up_axis="Y", prop_meters_per_unit=0.01)
    mug = PropMesh(mug.name, np.asarray(mug.vertices) + grasping_mug_position(), mug.faces)
    return clip, humanoid_handmap(clip.skeleton), lambda: Colliders([mesh_collider(mug, clip.times)])


def case_cup_grasp():
    from usdhands.samples.humanoid import humanoid_handmap
    from usdhands.samples.interaction import CUP_HELD, cup_grasp_clip, cup_on_table_mesh, table_mesh

    clip = cup_grasp_clip()
    cup, table = _prop(cup_on_table_mesh(), "cup"), _prop(table_mesh(), "table")

    def colliders():
        hand = clip.world_xforms()[:, clip.skeleton.index("RightHand")]
        held = attached_xforms(cup.xforms_at(clip.times), hand, *CUP_HELD)
        return Colliders([mesh_collider(cup, clip.times, world=held), mesh_collider(table, clip.times)])

    return clip, humanoid_handmap(clip.skeleton), colliders


def case_table_rest():
    from usdhands.samples.humanoid import humanoid_handmap
    from usdhands.samples.interaction import table_mesh, table_rest_clip

    clip = table_rest_clip()
    table = _prop(table_mesh(), "table")
    return clip, humanoid_handmap(clip.skeleton), lambda: Colliders([mesh_collider(table, clip.times)])


def case_scratch_head():
    from usdhands.samples.humanoid import humanoid_handmap
    from usdhands.samples.interaction import scratch_head_clip, table_mesh

    clip = scratch_head_clip()
    hm = humanoid_handmap(clip.skeleton)
    table = _prop(table_mesh(), "table")
    return clip, hm, lambda: Colliders([mesh_collider(table, clip.times), body_collider(clip, hm)])


def case_leap_typing():
    import trimesh

    from usdhands.formats.io import read_clip
    from usdhands.model.hand_detection import detect_hands

    path = ASSETS / "leap_hands" / "gesture-typing.bvh"
    clip = read_clip(path, units="mm")
    hm = detect_hands(clip.skeleton)
    mm = 0.001 / clip.skeleton.meters_per_unit
    cfg = InteractionConfig()
    lowest, where = np.inf, None
    for poser in chain_posers(clip, hm, cfg):
        n = len(poser.chain.joints)
        angles = finger_curves(clip, poser.chain.joints).values.reshape(clip.num_frames, n, 3)
        _, b = poser.capsules(np.arange(clip.num_frames), angles)
        skin = b[:, -1, 1] - poser.chain.radii[-1]
        if skin.min() < lowest:
            lowest, where = float(skin.min()), b[int(np.argmin(skin)), -1]
    top = lowest + 6.0 * mm
    size = np.array([300.0, 100.0, 300.0]) * mm
    box = trimesh.creation.box(extents=size)
    box.apply_translation([where[0], top - size[1] / 2, where[2]])
    prop = PropMesh("keyboard", box.vertices, box.faces)
    return clip, hm, lambda: Colliders([mesh_collider(prop, clip.times)])


CASES = {"bench": case_bench, "cup_grasp": case_cup_grasp, "table_rest": case_table_rest,
         "scratch_head": case_scratch_head, "leap_typing": case_leap_typing}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--smoothing-s", type=float, default=None, help="InteractionConfig.smoothing_s (default its own)")
    ap.add_argument("--tolerance-mm", type=float, default=None, help="InteractionConfig.tolerance_mm (default its own)")
    ap.add_argument("--ik", choices=("opening", "ccd"), default="opening", help="InteractionConfig.ik")
    args = ap.parse_args()
    config = InteractionConfig(**({} if args.smoothing_s is None else {"smoothing_s": args.smoothing_s}),
                               **({} if args.tolerance_mm is None else {"tolerance_mm": args.tolerance_mm}),
                               ik=args.ik)
    print(f"{'case':14s} {'frames':>6s} {'pen before':>10s} {'pen after':>9s} {'jitter before':>13s} "
          f"{'jitter after':>12s} {'corrected':>9s} {'unresolved':>10s} {'max chg':>7s} {'s':>6s}")
    for name in args.cases.split(","):
        clip, hm, colliders = CASES[name]()
        t0 = time.perf_counter()
        out, report = correct_clip(clip, hm, colliders(), config=config)
        seconds = time.perf_counter() - t0
        touched = [j for p in chain_posers(clip, hm, config) if p.chain.name in report.chains_corrected
                   for j in p.chain.joints]
        mean_change = float(quat_angle_deg(clip.rotations[:, touched], out.rotations[:, touched]).mean()) if touched else 0.0
        d = report.to_dict()
        print(f"{name:14s} {clip.num_frames:6d} {d['penetration_before_mm']['max']:10.2f} "
              f"{d['penetration_after_mm']['max']:9.3f} {d['jitter_before']:13.1f} {d['jitter_after']:12.1f} "
              f"{d['frames_corrected']:9d} {len(report.unresolved):10d} {d['max_change_deg']:7.1f} {mean_change:8.2f} {seconds:6.2f}")


if __name__ == "__main__":
    main()

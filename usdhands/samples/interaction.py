"""Interaction samples: hands that touch a cup, the head and a table (``usdhands correct`` and
``synthesize --props`` inputs).

Three clips of the sample humanoid with full finger motion, authored like the gestures
(:mod:`usdhands.samples.motion`), centimetres, Y up (written as glTF: metres); the props
stand where the clips need them (``props/table.obj``, ``props/cup_on_table.obj``, written
in world metres like the glTF clips):

- ``cup_grasp``: the right hand reaches for the cup on the table, grasps it (the fingers
  close a little too far, as a capture would: a few millimetres into the cup), lifts it,
  puts it down, lets go. The cup is held from :data:`CUP_HELD` (frames), so
  ``--attach cup_on_table=RightHand:FROM-TO`` carries it.
- ``scratch_head``: the right hand scratches the right side of the head; the fingertips
  dig into the head (``--self`` keeps them at the skin).
- ``table_rest``: the left hand rests on the table, the relaxed fingertips a little below
  the table top; then it taps twice.

Every clip also comes body-only (fingers frozen at rest) for ``synthesize --props``.
"""

from __future__ import annotations

import numpy as np
import trimesh

from usdhands.model.clip import Clip
from usdhands.samples.hand_poses import _pose, relaxed_pose
from usdhands.samples.humanoid import humanoid_skeleton
from usdhands.samples.motion import BodyIdle, HandKey, HandTrack, build_clip, rest_key
from usdhands.samples.props import cup_mesh

__all__ = ["TABLE_TOP_CM", "CUP_BASE_CM", "CUP_HELD", "interaction_clips", "table_mesh", "cup_on_table_mesh",
           "mesh_obj_text"]

#: Height of the table top above the floor, cm (the hips are at 100).
TABLE_TOP_CM = 100.0
#: Where the cup stands on the table (centre of its base), world cm.
CUP_BASE_CM = np.array([-21.0, TABLE_TOP_CM, 32.0])
#: Frames (inclusive) during which the right hand holds the cup in ``cup_grasp``.
CUP_HELD = (48, 102)

_HIPS = np.array([0.0, 100.0, 0.0])


def _h(world: np.ndarray) -> np.ndarray:
    """World cm to the hips frame the tracks are authored in."""
    return np.asarray(world, dtype=np.float64) - _HIPS


def _k(t, pos_world, fingers_dir, palm, pose, stop=True) -> HandKey:
    return HandKey(float(t), _h(pos_world), np.asarray(fingers_dir, float), np.asarray(palm, float),
                   np.asarray(pose, float), stop, 0.0)


def _grasp_pose(extra: float) -> np.ndarray:
    """Fingers wrapped around the cup's 8 cm body, ``extra`` degrees past contact."""
    c = lambda a, b, d: (a + extra, b + extra, d + 0.5 * extra)  # noqa: E731
    return _pose({"Index": c(38, 40, 20), "Middle": c(40, 42, 22), "Ring": c(42, 44, 22), "Pinky": c(44, 46, 24)},
                 {"Index": 2, "Ring": 2, "Pinky": 4}, (20, 10, 30, 25 + extra, 20 + extra))


def _open_pose() -> np.ndarray:
    return _pose({"Index": (5, 8, 4), "Middle": (6, 8, 4), "Ring": (8, 10, 5), "Pinky": (10, 12, 6)},
                 {"Index": 6, "Ring": 5, "Pinky": 10}, (15, 10, 20, 5, 5))


def cup_grasp_clip(seed: int = 0) -> Clip:
    """Reach, grasp, lift, put down, let go: about 5 s at 30 fps."""
    rng = np.random.default_rng([seed, 1010])
    relaxed = relaxed_pose()
    side = CUP_BASE_CM + [-8.5, 7.0, -5.0]  # the wrist beside the cup, palm toward it
    fd, palm = (0.25, 0.0, 1.0), (1.0, 0.0, -0.1)
    keys = [rest_key(0.0, "right", relaxed), rest_key(0.4, "right", relaxed),
            _k(0.8, np.array([-34.0, 118.0, -3.0]), (0.1, 0.8, 1.0), (0.9, -0.3, 0.0), _open_pose(), stop=False),
            _k(1.1, side + [-6.0, 8.0, -6.0], fd, palm, _open_pose(), stop=False),
            _k(1.5, side, fd, palm, _open_pose()),
            _k(1.6, side, fd, palm, _grasp_pose(9.0)),  # closed, a little too far (frame 48)
            _k(2.3, side + [0.0, 15.0, 0.0], fd, palm, _grasp_pose(9.0)),  # lifted
            _k(2.8, side + [0.0, 15.0, 0.0], fd, palm, _grasp_pose(9.0)),
            _k(3.4, side, fd, palm, _grasp_pose(9.0)),  # put down (frame 102)
            _k(3.8, side, fd, palm, _open_pose()),
            _k(4.3, side + [-6.0, 8.0, -6.0], fd, palm, _open_pose(), stop=False),
            _k(4.6, np.array([-34.0, 118.0, -3.0]), (0.1, 0.8, 1.0), (0.9, -0.3, 0.0), _open_pose(), stop=False),
            rest_key(5.2, "right", relaxed)]
    tracks = [HandTrack("right", keys), HandTrack("left", [rest_key(0.0, "left", relaxed),
                                                           rest_key(5.2, "left", relaxed)])]
    return build_clip(humanoid_skeleton(), tracks, 5.2, BodyIdle.random(rng), name="cup_grasp")


def scratch_head_clip(seed: int = 0) -> Clip:
    """The right hand scratches the side of the head: about 4 s."""
    rng = np.random.default_rng([seed, 2020])
    relaxed = relaxed_pose()
    at = np.array([-18.0, 170.0, 2.0])
    fd, palm = (0.35, 1.0, 0.1), (1.0, -0.1, 0.0)
    scratch = _pose({"Index": (30, 45, 30), "Middle": (32, 45, 30), "Ring": (34, 45, 30), "Pinky": (36, 45, 30)},
                    {"Index": 3, "Ring": 3, "Pinky": 6}, (10, 0, 10, 10, 10))
    keys = [rest_key(0.0, "right", relaxed), rest_key(0.3, "right", relaxed),
            _k(1.1, at, fd, palm, scratch), _k(2.9, at + [0.0, 1.0, 0.0], fd, palm, scratch),
            _k(3.3, at + [-9.0, -3.0, 2.0], fd, palm, relaxed),  # away from the head before dropping
            rest_key(4.0, "right", relaxed)]

    def scratching(times: np.ndarray) -> np.ndarray:
        on = np.clip((times - 1.1) / 0.2, 0, 1) * np.clip((2.9 - times) / 0.2, 0, 1)
        wave = 12.0 * np.sin(2 * np.pi * 3.5 * times) * on
        out = np.zeros((len(times), 15, 3))
        out[:, 3:, 0] = wave[:, None]  # every long-finger joint flexes back and forth
        return out

    tracks = [HandTrack("right", keys, [scratching]),
              HandTrack("left", [rest_key(0.0, "left", relaxed), rest_key(4.0, "left", relaxed)])]
    return build_clip(humanoid_skeleton(), tracks, 4.0, BodyIdle.random(rng), name="scratch_head")


def table_rest_clip(seed: int = 0) -> Clip:
    """The left hand rests on the table, taps twice, rests: about 4 s."""
    rng = np.random.default_rng([seed, 3030])
    relaxed = relaxed_pose()
    on = np.array([22.0, TABLE_TOP_CM + 7.0, 32.0])
    fd, palm = (0.0, -0.2, 1.0), (0.0, -1.0, -0.2)
    resting = _pose({"Index": (24, 34, 16), "Middle": (26, 36, 16), "Ring": (28, 38, 18), "Pinky": (30, 40, 18)},
                    {"Index": 4, "Ring": 4, "Pinky": 8}, (15, 5, 20, 10, 10))
    lift = _pose({"Index": (-8, 8, 4), "Middle": (-6, 8, 4), "Ring": (-4, 8, 4), "Pinky": (-2, 8, 4)},
                 {"Index": 4, "Ring": 4, "Pinky": 8}, (15, 5, 20, 10, 10))
    keys = [rest_key(0.0, "left", relaxed), rest_key(0.3, "left", relaxed),
            _k(0.8, np.array([28.0, 114.0, 0.0]), (0.0, 0.6, 1.0), (0.0, -1.0, 0.6), relaxed, stop=False),
            _k(1.2, on + [0.0, 4.0, -4.0], fd, palm, relaxed, stop=False), _k(1.5, on, fd, palm, resting),
            _k(2.0, on, fd, palm, lift), _k(2.2, on, fd, palm, resting), _k(2.5, on, fd, palm, lift),
            _k(2.7, on, fd, palm, resting), _k(3.2, on, fd, palm, resting),
            _k(3.5, np.array([28.0, 114.0, 0.0]), (0.0, 0.6, 1.0), (0.0, -1.0, 0.6), relaxed, stop=False),
            rest_key(4.0, "left", relaxed)]
    tracks = [HandTrack("left", keys), HandTrack("right", [rest_key(0.0, "right", relaxed),
                                                           rest_key(4.0, "right", relaxed)])]
    return build_clip(humanoid_skeleton(), tracks, 4.0, BodyIdle.random(rng), name="table_rest")


def interaction_clips(seed: int = 0) -> dict[str, Clip]:
    """The three interaction clips by name."""
    return {"cup_grasp": cup_grasp_clip(seed), "scratch_head": scratch_head_clip(seed),
            "table_rest": table_rest_clip(seed)}


def table_mesh() -> trimesh.Trimesh:
    """A table top: 100 x 3 x 50 cm, its top at :data:`TABLE_TOP_CM`, 20 to 70 cm in front of the character (world cm)."""
    box = trimesh.creation.box(extents=(100.0, 3.0, 50.0))
    box.apply_translation([0.0, TABLE_TOP_CM - 1.5, 45.0])
    return box


def cup_on_table_mesh() -> trimesh.Trimesh:
    """The sample cup standing on the table at :data:`CUP_BASE_CM`, its handle toward +X, away from
    the right hand that reaches for it from -X (world cm)."""
    cup = cup_mesh()
    return trimesh.Trimesh(np.asarray(cup.vertices) + CUP_BASE_CM, np.asarray(cup.faces), process=False)


def mesh_obj_text(mesh: trimesh.Trimesh, title: str, scale: float = 1.0) -> str:
    """Wavefront OBJ text of a mesh scaled by ``scale`` (0.01: cm to metres; one object, triangles)."""
    units = "metres" if scale == 0.01 else "centimetres" if scale == 1.0 else f"{scale:g} x centimetres"
    lines = [f"# usdhands sample prop: {title}, world {units}, +Y up", f"o {title.split()[0]}"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in np.asarray(mesh.vertices) * scale]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(mesh.faces)]
    return "\n".join(lines) + "\n"

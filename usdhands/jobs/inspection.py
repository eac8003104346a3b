"""The inspect job: the skeletons, joints, animations, meshes and hands of a file.

::

    from usdhands.jobs.inspection import inspect_file

    report = inspect_file("take.glb").to_json()
    print([s["num_joints"] for s in report["skeletons"]], report["hands"]["left"]["wrist"])
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class InspectOptions:
    """Options of :func:`inspect_file`.

    Attributes
    ----------
    handmap : Path or None
        Hand map JSON overriding detection.
    """

    handmap: Path | None = None


@dataclass(frozen=True)
class InspectResult:
    """What a file holds: ``report`` as ``usdhands inspect --json`` prints it (``file``,
    ``skeletons`` with their joints and hands, ``animations``, ``meshes``, ``hands`` of the
    first skeleton with any)."""

    report: dict

    def to_json(self) -> dict:
        return self.report


def inspect_file(path: str | os.PathLike, options: InspectOptions = InspectOptions()) -> InspectResult:
    """Read ``path`` and report what it holds; a skeleton whose hands cannot be found reports none.

    Raises
    ------
    UsdHandsError
        The file (or the hand map) cannot be read.
    """
    from usdhands.errors import NoHandsError
    from usdhands.formats.hands import hands_for
    from usdhands.formats.io import read_asset
    from usdhands.jobs.outputs import MAIN_INPUT, check_paths
    from usdhands.model.handmap import HandMap

    path = Path(path)
    check_paths({MAIN_INPUT: path, "--handmap": options.handmap})
    asset = read_asset(path)
    skeletons = []
    hands = HandMap()
    for sk in asset.skeletons:
        try:
            hm = hands_for(path, sk, options.handmap)[0]
        except NoHandsError:
            hm = HandMap()
        if hands.left is None and hands.right is None:
            hands = hm
        skeletons.append({
            "name": sk.name,
            "joints": list(sk.joint_names),
            "num_joints": sk.num_joints,
            "meters_per_unit": sk.meters_per_unit,
            "up_axis": sk.up_axis,
            "hands": hm.to_dict(),
        })
    animations = []
    for clip in asset.clips:
        animations.append({
            "name": clip.name,
            "skeleton": asset.skeletons.index(clip.skeleton) if clip.skeleton in asset.skeletons else None,
            "frames": clip.num_frames,
            "fps": clip.fps,
            "duration": clip.duration,
        })
    meshes = [{"name": m.name, "points": int(len(m.points)), "faces": int(len(m.face_vertex_counts)),
               "influences": None if m.joint_indices is None else int(m.joint_indices.shape[1])}
              for m in asset.meshes]
    return InspectResult({"file": str(path), "skeletons": skeletons, "animations": animations, "meshes": meshes,
                          "hands": hands.to_dict()})

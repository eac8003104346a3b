"""Open a source file and its conversions in Blender (``bpy``) and compare what Blender shows.

Blender is the tool users open usdhands' outputs in: this script imports each file with
Blender's own importers (glTF-IO, the USD importer) and compares, against the source,
the world positions of the bones (matched by name) and the bounding box of every
evaluated mesh (skinned, and rigid parts following a bone) at a few frames, and counts
what Blender imported: mesh vertices, materials, image textures, shape keys and actions.

bpy is not a test dependency: its wheel (``pip install bpy``, 77 s and 968 MB here for
bpy 5.0.1) pins numpy 1.26, which would downgrade the project's numpy. Run it from a
separate environment, giving it files converted by usdhands::

    python3 -m venv /tmp/bpyenv && /tmp/bpyenv/bin/pip install bpy
    usdhands convert ../shared/assets/robot_expressive/RobotExpressive.glb /tmp/robot.usda
    usdhands convert /tmp/robot.usda /tmp/robot_back.glb
    /tmp/bpyenv/bin/python benchmarks/blender_check.py [--fps 24] \\
        ../shared/assets/robot_expressive/RobotExpressive.glb /tmp/robot.usda /tmp/robot_back.glb

``--fps`` is the animation's frame rate (default 24, RobotExpressive's and CesiumMan's).

Without bpy it says so and exits 0. Figures: docs/format-usd.md, "In Blender".
"""

from __future__ import annotations

import sys
from pathlib import Path

try:
    import bpy
    from mathutils import Vector
except ImportError:  # not in the project's environment: see the module docs
    print("blender_check: bpy is not installed here; skipped (see the module docs)")
    sys.exit(0)

FRAMES = (1, 10, 20)
#: glTF-IO's bone orientation. Its default, ``BLENDER``, turns each bone toward its child and
#: misplaces meshes parented to a bone when the skin is bound in another pose than the nodes'
#: rest (RobotExpressive's head, torso and limbs 51-65 cm from where the glTF's own node
#: transforms put them, at every frame); ``TEMPERANCE`` keeps them there, and the bones'
#: heads (what is compared) are the joints' positions under every heuristic (0.0004 cm).
BONE_HEURISTIC = "TEMPERANCE"


def load(path: Path, fps: int) -> None:
    """Empty the scene and import ``path`` with Blender's importer for its extension.

    The scene rate is set to ``fps`` first: Blender's glTF importer turns key seconds into
    frames at the scene rate, its USD importer takes time codes as frames, so the two
    agree at a frame only when the scene runs at the USD file's timeCodesPerSecond.
    """
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.render.fps = fps
    bpy.context.scene.render.fps_base = 1.0
    if path.suffix.lower() in (".glb", ".gltf"):
        bpy.ops.import_scene.gltf(filepath=str(path), bone_heuristic=BONE_HEURISTIC)
    else:
        bpy.ops.wm.usd_import(filepath=str(path))


def bone_positions() -> dict[str, Vector]:
    """Bone name -> world position of its head (metres)."""
    out = {}
    for obj in bpy.context.scene.objects:
        if obj.type == "ARMATURE":
            for pb in obj.pose.bones:
                out[_key(pb.name)] = obj.matrix_world @ pb.head
    return out


def _key(name: str) -> str:
    """Names as USD prims hold them (``Hand.R_0`` and ``Hand_R_0``, ``thumb-tip`` and ``thumb_tip`` match)."""
    return "".join(c if c.isalnum() else "_" for c in name)


def _file_meshes() -> list:
    """The mesh objects the file holds (not the Icosphere glTF-IO makes as every bone's display shape)."""
    shapes = {pb.custom_shape.name for o in bpy.context.scene.objects if o.type == "ARMATURE"
              for pb in o.pose.bones if pb.custom_shape}
    return [o for o in bpy.context.scene.objects if o.type == "MESH" and o.name not in shapes]


def counts() -> dict[str, int]:
    """What the import holds: mesh vertices, materials used by meshes, image textures, shape keys
    (without the basis), actions."""
    meshes = _file_meshes()
    materials = {s.material.name for o in meshes for s in o.material_slots if s.material}
    keys = sum(len(o.data.shape_keys.key_blocks) - 1 for o in meshes if o.data.shape_keys)
    return {"verts": sum(len(o.data.vertices) for o in meshes), "mats": len(materials),
            "images": sum(1 for i in bpy.data.images if i.source == "FILE"), "keys": keys,
            "actions": len(bpy.data.actions)}


def skinned_bbox() -> tuple[Vector, Vector] | None:
    """World bounding box of every evaluated mesh (skinning applied; rigid parts where their bone puts them)."""
    deps = bpy.context.evaluated_depsgraph_get()
    pts = []
    for obj in _file_meshes():
        ev = obj.evaluated_get(deps)
        mesh = ev.to_mesh()
        pts += [ev.matrix_world @ v.co for v in mesh.vertices]
        ev.to_mesh_clear()
    if not pts:
        return None
    return Vector(map(min, *pts)), Vector(map(max, *pts))


def snapshot(path: Path, fps: int) -> dict:
    load(path, fps)
    out = {"counts": counts()}
    for f in FRAMES:
        bpy.context.scene.frame_set(f)
        out[f] = (bone_positions(), skinned_bbox())
    return out


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__)
        return 2
    fps = 24
    if argv[0] == "--fps":
        fps, argv = int(argv[1]), argv[2:]
    source, *converted = (Path(a) for a in argv)
    ref = snapshot(source, fps)
    print(f"{source.name:28s} {ref['counts']}")
    print(f"{'file':28s} {'frame':>5s} {'bones':>5s} {'max bone cm':>11s} {'mesh bbox cm':>12s}")
    for path in converted:
        got = snapshot(path, fps)
        print(f"{path.name:28s} {got['counts']}")
        for f in FRAMES:
            (rb, rbox), (gb, gbox) = ref[f], got[f]
            common = sorted(set(rb) & set(gb))
            worst = max(((rb[n] - gb[n]).length for n in common), default=float("nan")) * 100
            box = float("nan")
            if rbox and gbox:
                box = max(abs(a - b) for k in (0, 1) for a, b in zip(rbox[k], gbox[k])) * 100
            print(f"{path.name:28s} {f:5d} {len(common):5d} {worst:11.4f} {box:12.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]))

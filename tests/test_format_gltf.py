"""glTF 2.0 reader and writers: files built here with known values, and real third-party files."""

from __future__ import annotations

import base64
import json
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from scipy.spatial.transform import Rotation
from conftest import require_validator

from usdhands.errors import AssetReadError, InvalidAnimationError, JointMismatchError, OutputPathError
from usdhands.formats.gltf import HANDLER
from usdhands.formats.gltf_read import detect_fps, sample_channel
from usdhands.formats.io import read_asset, read_clip, write_asset, write_clip
from usdhands.model.asset import Asset, SkinnedMesh
from usdhands.model.clip import Clip
from usdhands.model.rotations import quat_angle_deg, quat_multiply, trs_to_xform
from usdhands.model.skeleton import Skeleton

VALIDATOR = Path(__file__).resolve().parent / "gltf_validator" / "node_modules" / "gltf-validator"

# --------------------------------------------------------------------------- helpers


def qz(deg):
    return Rotation.from_euler("z", deg, degrees=True).as_quat()


def qy(deg):
    return Rotation.from_euler("y", deg, degrees=True).as_quat()


class _Blob:
    """Builds the binary buffer of a test file, 4-byte aligned views."""

    def __init__(self, gltf):
        self.gltf = gltf
        self.data = bytearray()

    def view(self, arr) -> int:
        self.data += b"\0" * (-len(self.data) % 4)
        raw = np.ascontiguousarray(arr).tobytes()
        self.gltf.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(self.data), byteLength=len(raw)))
        self.data += raw
        return len(self.gltf.bufferViews) - 1

    def accessor(self, arr, type_, comp=pygltflib.FLOAT, normalized=None, min_max=False) -> int:
        arr = np.asarray(arr)
        acc = pygltflib.Accessor(bufferView=self.view(arr), componentType=comp, count=arr.shape[0], type=type_,
                                 normalized=normalized)
        if min_max:
            acc.min = arr.reshape(arr.shape[0], -1).min(0).tolist()
            acc.max = arr.reshape(arr.shape[0], -1).max(0).tolist()
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1


def build_test_gltf(folder: Path, kind: str, *, nan: bool = False) -> Path:
    """A 4-joint skin (hips → arm → hand → tip) with one animation of known values.

    Channels: hips translation LINEAR (0,1,2 s), hips scale LINEAR through a sparse
    accessor, arm rotation STEP stored as normalized int16, arm translation
    CUBICSPLINE with tangents, hand rotation CUBICSPLINE; a morph-weights channel and
    a channel on the (non-joint) mesh node that the reader must ignore. ``tip`` is a
    matrix node. One skinned triangle with UVs. ``kind``: "glb", "embedded" (data
    URI) or "external" (.bin beside the .gltf).
    """
    g = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"))
    g.buffers = [pygltflib.Buffer()]
    b = _Blob(g)
    tip_matrix = trs_to_xform([0, 0.5, 0], [0, 0, 0, 1], [2, 2, 2])
    g.nodes = [
        pygltflib.Node(name="hips", translation=[0, 1, 0], children=[1]),
        pygltflib.Node(name="arm", translation=[0, 0.5, 0], children=[2]),
        pygltflib.Node(name="hand", translation=[0, 0.5, 0], children=[3]),
        pygltflib.Node(name="", matrix=tip_matrix.T.reshape(-1).tolist()),  # unnamed matrix node
        pygltflib.Node(name="body", mesh=0, skin=0),
    ]
    world = np.array([trs_to_xform([0, 1, 0], [0, 0, 0, 1]), trs_to_xform([0, 1.5, 0], [0, 0, 0, 1]),
                      trs_to_xform([0, 2.0, 0], [0, 0, 0, 1]), trs_to_xform([0, 2.5, 0], [0, 0, 0, 1]) @
                      np.diag([2.0, 2, 2, 1])])
    ibm = np.linalg.inv(world).transpose(0, 2, 1).reshape(4, 16).astype(np.float32)
    g.skins = [pygltflib.Skin(joints=[0, 1, 2, 3], inverseBindMatrices=b.accessor(ibm, "MAT4"), skeleton=0)]
    pos = np.array([[0, 1, 0], [1, 1, 0], [0, 2, 0]], np.float32)
    uv = np.array([[0, 0], [1, 0.25], [0, 1]], np.float32)
    joints = np.array([[0, 1, 0, 0], [1, 0, 0, 0], [2, 3, 0, 0]], np.uint8)
    weights = np.array([[1, 0, 0, 0], [0.5, 0.5, 0, 0], [0.75, 0.25, 0, 0]], np.float32)
    attrs = pygltflib.Attributes(POSITION=b.accessor(pos, "VEC3", min_max=True), TEXCOORD_0=b.accessor(uv, "VEC2"),
                                 JOINTS_0=b.accessor(joints, "VEC4", pygltflib.UNSIGNED_BYTE),
                                 WEIGHTS_0=b.accessor(weights, "VEC4"))
    target = pygltflib.Attributes(POSITION=b.accessor(np.tile(np.float32([0, 0, 0.1]), (3, 1)), "VEC3",
                                                      min_max=True))
    g.meshes = [pygltflib.Mesh(name="body", primitives=[pygltflib.Primitive(attributes=attrs, targets=[target])],
                               weights=[0.0])]
    g.scenes = [pygltflib.Scene(nodes=[0, 4])]
    g.scene = 0

    t3 = b.accessor(np.array([[0], [1], [2]], np.float32), "SCALAR", min_max=True)
    t2 = b.accessor(np.array([[0], [2]], np.float32), "SCALAR", min_max=True)
    t2b = b.accessor(np.array([[0], [1]], np.float32), "SCALAR", min_max=True)
    hips_t = np.array([[0, 1, 0], [1, 1, 0], [1, 3, 0]], np.float32)
    if nan:
        hips_t[1, 0] = np.nan
    # sparse: base of ones, key 1 replaced by (2, 2, 2)
    scale_acc = b.accessor(np.ones((3, 3), np.float32), "VEC3")
    g.accessors[scale_acc].sparse = pygltflib.Sparse(
        count=1, indices=pygltflib.AccessorSparseIndices(bufferView=b.view(np.array([1], np.uint16)),
                                                         componentType=pygltflib.UNSIGNED_SHORT),
        values=pygltflib.AccessorSparseValues(bufferView=b.view(np.full((1, 3), 2.0, np.float32))))
    arm_q = np.round(np.array([[0, 0, 0, 1], qz(90)]) * 32767).astype(np.int16)
    arm_cubic_t = np.array([[0, 0, 0], [0, 0.5, 0], [1, 0, 0],      # key 0: in, value, out tangent
                            [0, 0, 0], [1, 0.5, 0], [0, 0, 0]], np.float32)
    hand_cubic_q = np.array([[0, 0, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0],
                             [0, 0, 0, 0], qy(90), [0, 0, 0, 0]], np.float32)
    samplers = [
        pygltflib.AnimationSampler(input=t3, output=b.accessor(hips_t, "VEC3"), interpolation="LINEAR"),
        pygltflib.AnimationSampler(input=t3, output=scale_acc, interpolation="LINEAR"),
        pygltflib.AnimationSampler(input=t2b, output=b.accessor(arm_q, "VEC4", pygltflib.SHORT, normalized=True),
                                   interpolation="STEP"),
        pygltflib.AnimationSampler(input=t2, output=b.accessor(arm_cubic_t, "VEC3"), interpolation="CUBICSPLINE"),
        pygltflib.AnimationSampler(input=t2, output=b.accessor(hand_cubic_q, "VEC4"), interpolation="CUBICSPLINE"),
        pygltflib.AnimationSampler(input=t2, output=b.accessor(np.array([[0], [1]], np.float32), "SCALAR")),
        pygltflib.AnimationSampler(input=t2, output=b.accessor(np.array([[0, 0, 0], [5, 5, 5]], np.float32), "VEC3")),
    ]
    tgt = pygltflib.AnimationChannelTarget
    channels = [pygltflib.AnimationChannel(sampler=0, target=tgt(node=0, path="translation")),
                pygltflib.AnimationChannel(sampler=1, target=tgt(node=0, path="scale")),
                pygltflib.AnimationChannel(sampler=2, target=tgt(node=1, path="rotation")),
                pygltflib.AnimationChannel(sampler=3, target=tgt(node=1, path="translation")),
                pygltflib.AnimationChannel(sampler=4, target=tgt(node=2, path="rotation")),
                pygltflib.AnimationChannel(sampler=5, target=tgt(node=4, path="weights")),
                pygltflib.AnimationChannel(sampler=6, target=tgt(node=4, path="translation"))]
    g.animations = [pygltflib.Animation(name="Anim", samplers=samplers, channels=channels)]
    blob = bytes(b.data) + b"\0" * (-len(b.data) % 4)
    g.buffers[0].byteLength = len(blob)
    if kind == "glb":
        path = folder / "test.glb"
        g.set_binary_blob(blob)
        g.save_binary(str(path))
    elif kind == "embedded":
        path = folder / "test.gltf"
        g.buffers[0].uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
        g.save_json(str(path))
    else:
        path = folder / "test.gltf"
        (folder / "test data.bin").write_bytes(blob)
        g.buffers[0].uri = "test%20data.bin"
        g.save_json(str(path))
    return path


def validate_all(*paths: Path) -> list[dict]:
    """Khronos validator with no cap on issues: every error as (code, pointer)."""
    require_validator()
    node = shutil.which("node")
    script = (
        "const fs=require('fs'),path=require('path');const v=require(process.argv[1]);"
        "(async()=>{const out=[];for(const f of process.argv.slice(2)){"
        "const r=await v.validateBytes(new Uint8Array(fs.readFileSync(f)),{uri:path.basename(f),maxIssues:0,"
        "externalResourceFunction:(u)=>new Promise((res,rej)=>{try{res(new Uint8Array(fs.readFileSync("
        "path.resolve(path.dirname(f),decodeURIComponent(u)))))}catch(e){rej(e.toString())}})});"
        "out.push({numErrors:r.issues.numErrors,errors:r.issues.messages.filter(m=>m.severity===0)"
        ".map(m=>[m.code,m.pointer||''])});}process.stdout.write(JSON.stringify(out));})()"
        ".catch(e=>{console.error(String(e));process.exit(1)});")
    out = subprocess.run([node, "-e", script, str(VALIDATOR), *map(str, paths)], capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout)


# --------------------------------------------------------------------------- reading


@pytest.mark.parametrize("kind", ["glb", "embedded", "external"])
def test_samplers_give_known_values_at_known_times(tmp_path, kind, gltf_validator):
    path = build_test_gltf(tmp_path, kind)
    assert gltf_validator(path)[0]["numErrors"] == 0  # the test file itself is valid
    asset = read_asset(path)
    assert len(asset.skeletons) == 1 and len(asset.clips) == 1
    sk = asset.skeletons[0]
    assert sk.joint_names == ("hips", "arm", "hand", "node3")
    assert list(sk.parents) == [-1, 0, 1, 2]
    clip = asset.clips[0]
    assert clip.name == "Anim" and clip.fps == 30.0 and clip.num_frames == 61 and clip.start_time == 0.0
    f = {t: int(round(t * 30)) for t in (0.5, 1.0, 1.5, 2.0)}
    # LINEAR translation
    assert np.allclose(clip.translations[f[0.5], 0], [0.5, 1, 0])
    assert np.allclose(clip.translations[f[1.5], 0], [1, 2, 0])
    # sparse scale: ones with key 1 replaced by 2
    assert np.allclose(clip.scales[f[1.0], 0], 2.0) and np.allclose(clip.scales[f[0.5], 0], 1.5)
    # STEP rotation from normalized int16: identity until 1 s, then 90° about z
    assert quat_angle_deg(clip.rotations[f[1.0] - 1, 1], [0, 0, 0, 1]) < 1e-3
    assert quat_angle_deg(clip.rotations[f[1.0], 1], qz(90)) < 0.01
    # CUBICSPLINE translation: tangents scaled by the 2 s interval -> 0.75 at u = 0.5 (0.625 unscaled)
    assert np.allclose(clip.translations[f[1.0], 1], [0.75, 0.5, 0], atol=1e-6)
    assert np.allclose(clip.translations[f[2.0], 1], [1, 0.5, 0])
    # CUBICSPLINE rotation with zero tangents: normalised blend, 45° about y halfway
    assert quat_angle_deg(clip.rotations[f[1.0], 2], qy(45)) < 1e-4
    # unanimated joints keep their node values; the matrix node is decomposed
    assert np.allclose(clip.translations[:, 3], [0, 0.5, 0]) and np.allclose(clip.scales[:, 3], 2.0)
    assert np.allclose(clip.translations[:, 2], [0, 0.5, 0])
    # bind transforms are the inverse bind matrices inverted
    assert np.allclose(sk.bind_xforms[3], trs_to_xform([0, 2.5, 0], [0, 0, 0, 1], [2, 2, 2]), atol=1e-6)


def test_skinned_mesh_uvs_flipped_and_joints_mapped(tmp_path):
    asset = read_asset(build_test_gltf(tmp_path, "glb"))
    (mesh,) = asset.meshes
    assert mesh.name == "body" and mesh.skeleton_index == 0
    assert np.allclose(mesh.uvs, [[0, 1], [1, 0.75], [0, 0]])  # v_usd = 1 - v_gltf
    assert list(mesh.face_vertex_indices) == [0, 1, 2] and list(mesh.face_vertex_counts) == [3]
    assert np.array_equal(mesh.joint_indices, [[0, 1, 0, 0], [1, 0, 0, 0], [2, 3, 0, 0]])
    assert np.allclose(mesh.joint_weights[2], [0.75, 0.25, 0, 0])
    assert np.allclose(mesh.geom_bind_xform, np.eye(4), atol=1e-6)


def test_fps_option_and_detected_rates(tmp_path):
    clip = read_clip(build_test_gltf(tmp_path, "glb"), fps=4)
    assert clip.fps == 4 and clip.num_frames == 9
    assert np.allclose(clip.translations[2, 0], [0.5, 1, 0])
    for rate in (24, 30, 60, 40, 120):
        assert detect_fps((np.arange(50) / rate).astype(np.float32)) == rate
    assert detect_fps(np.arange(20) / 29.97) == 30000 / 1001     # snapped to NTSC (29.97 is within 1e-6)
    assert detect_fps(np.arange(20) / 29.5) == 29.5              # regular spacing outside the list
    # float32 keys every 0.027 s (a Leap BVH's frame time): exactly 1/0.027, so BVH -> glTF keeps the rate
    assert detect_fps((np.arange(317) * 0.027).astype(np.float32)) == 1 / 0.027
    assert detect_fps(np.array([0, 1, 3, 10, 11]) / 24) == 24.0  # keyframes on a 24 fps grid
    assert detect_fps(np.array([0, 4, 12]) / 24) == 30.0         # sparse keys (every 1/6 s) fit 30 fps
    assert detect_fps([0.0, 1.0, 2.0]) == 30.0
    assert detect_fps([0.0, 0.013, 0.5, 0.77]) == 30.0           # irregular: the default
    assert detect_fps([1.25]) == 30.0


def test_step_sampler_snaps_float32_key_times():
    times = np.array([0, 1 / 24, 2 / 24], np.float32).astype(np.float64)  # float32 1/24 is a hair late
    values = np.array([[0.0], [1.0], [2.0]])
    at = np.arange(3) / 24
    assert np.array_equal(sample_channel(times, values, "STEP", at, False, snap=1e-3 / 24)[:, 0], [0, 1, 2])
    assert sample_channel(times, values, "STEP", at, False)[1, 0] == 0.0  # without snapping: the previous key


def test_sparse_accessor_without_buffer_view_and_malformed_json(tmp_path):
    from usdhands.formats.gltf_container import GltfFile, read_accessor

    g = pygltflib.GLTF2()
    b = _Blob(g)
    idx = b.view(np.array([0, 3], np.uint8))
    val = b.view(np.array([[1, 2], [3, 4]], np.float32))
    g.accessors.append(pygltflib.Accessor(componentType=pygltflib.FLOAT, count=5, type="VEC2", sparse=pygltflib.Sparse(
        count=2, indices=pygltflib.AccessorSparseIndices(bufferView=idx, componentType=pygltflib.UNSIGNED_BYTE),
        values=pygltflib.AccessorSparseValues(bufferView=val))))
    g.buffers = [pygltflib.Buffer(byteLength=len(b.data))]
    arr = read_accessor(GltfFile(tmp_path / "x.glb", g, [bytes(b.data)], True), 0)
    assert np.array_equal(arr, [[1, 2], [0, 0], [0, 0], [3, 4], [0, 0]])
    bad = tmp_path / "bad.gltf"
    bad.write_text('{"asset": {"version": "2.0"}, "nodes": [{"children": [5]}]}')
    with pytest.raises(AssetReadError, match=r"bad.gltf: nodes\[0\]: child 5 out of range \(there are 1 nodes\)$"):
        read_asset(bad)


def test_ancestors_kept_only_where_needed_and_skins_sharing_joints_merged(tmp_path):
    """RootNode (identity) > Armature (scale 0.01, 90° about x) > hips > Mid (not a joint) > hand > tip;
    skin0 = [hips, hand], skin1 = [hand, tip] share 'hand'; skin2 = [other] is a second character.
    One animation drives hips and other."""
    g = pygltflib.GLTF2(asset=pygltflib.Asset(version="2.0"))
    g.buffers = [pygltflib.Buffer()]
    b = _Blob(g)
    rx = Rotation.from_euler("x", 90, degrees=True).as_quat().tolist()
    g.nodes = [pygltflib.Node(name="RootNode", children=[1, 6]),
               pygltflib.Node(name="Armature", rotation=rx, scale=[0.01] * 3, children=[2]),
               pygltflib.Node(name="hips", translation=[0, 100, 0], children=[3]),
               pygltflib.Node(name="Mid", translation=[0, 10, 0], children=[4]),
               pygltflib.Node(name="hand", translation=[0, 5, 0], children=[5]),
               pygltflib.Node(name="hand", translation=[0, 2, 0]),          # repeated name
               pygltflib.Node(name="other", translation=[3, 0, 0])]
    eye = np.tile(np.eye(4, dtype=np.float32).reshape(1, 16), (2, 1))
    g.skins = [pygltflib.Skin(joints=[2, 4], inverseBindMatrices=b.accessor(eye, "MAT4")),
               pygltflib.Skin(joints=[4, 5], inverseBindMatrices=b.accessor(eye, "MAT4")),
               pygltflib.Skin(name="second", joints=[6])]
    t = b.accessor(np.array([[0], [1]], np.float32), "SCALAR", min_max=True)
    out = b.accessor(np.array([[0, 100, 0], [0, 110, 0]], np.float32), "VEC3")
    out2 = b.accessor(np.array([[3, 0, 0], [4, 0, 0]], np.float32), "VEC3")
    tgt = pygltflib.AnimationChannelTarget
    g.animations = [pygltflib.Animation(
        samplers=[pygltflib.AnimationSampler(input=t, output=out), pygltflib.AnimationSampler(input=t, output=out2)],
        channels=[pygltflib.AnimationChannel(sampler=0, target=tgt(node=2, path="translation")),
                  pygltflib.AnimationChannel(sampler=1, target=tgt(node=6, path="translation"))])]
    g.scenes = [pygltflib.Scene(nodes=[0])]
    g.buffers[0].byteLength = len(b.data)
    g.set_binary_blob(bytes(b.data))
    path = tmp_path / "tree.glb"
    g.save_binary(str(path))

    asset = read_asset(path)
    first, second = asset.skeletons
    assert first.joint_names == ("Armature", "hips", "Mid", "hand", "hand.001")   # RootNode dropped
    assert list(first.parents) == [-1, 0, 1, 2, 3]
    assert second.name == "second" and second.joint_names == ("other",)
    # world positions as the node tree gives them: scale 0.01 and +y turned to +z
    assert np.allclose(first.rest_world_positions(), [[0, 0, 0], [0, 0, 1], [0, 0, 1.1], [0, 0, 1.15],
                                                      [0, 0, 1.17]], atol=1e-9)
    assert [(c.name, c.skeleton.name) for c in asset.clips] == [("animation0", "skin0"),
                                                               ("animation0:second", "second")]
    assert np.allclose(asset.clips[0].world_positions()[-1, 1], [0, 0, 1.1])
    assert np.allclose(asset.clips[1].translations[-1, 0], [4, 0, 0])


def test_nan_in_animation_is_reported(tmp_path):
    path = build_test_gltf(tmp_path, "glb", nan=True)
    with pytest.raises(InvalidAnimationError, match=r"animation 'Anim' has NaN or infinite translations "
                                                    r"\(joint 'hips', frame \d+\)"):
        read_asset(path)


def test_truncated_glb_bad_json_missing_buffer(tmp_path):
    good = build_test_gltf(tmp_path, "glb")
    raw = good.read_bytes()
    cut = tmp_path / "cut.glb"
    cut.write_bytes(raw[:1000])
    with pytest.raises(AssetReadError) as e:
        read_asset(cut)
    assert str(e.value) == f"{cut}: truncated .glb: header says {len(raw)} bytes, file has 1000"
    short = tmp_path / "short.glb"
    short.write_bytes(raw[:7])
    with pytest.raises(AssetReadError, match=r"short.glb: truncated .glb: 7 bytes, shorter than the 12-byte header$"):
        read_asset(short)
    bad = tmp_path / "bad.gltf"
    bad.write_text('{"asset": {"version": "2.0"}, "nodes": [')
    with pytest.raises(AssetReadError) as e:
        read_asset(bad)
    assert str(e.value) == f"{bad}: invalid glTF JSON: Expecting value at line 1 column 41"
    ext = build_test_gltf(tmp_path, "external")
    (tmp_path / "test data.bin").unlink()
    with pytest.raises(AssetReadError) as e:
        read_asset(ext)
    assert str(e.value) == f"{ext}: buffers[0]: buffer file 'test%20data.bin' cannot be read (No such file or directory)"


# --------------------------------------------------------------------------- writing


def random_clip(mpu=1.0, up="Y", frames=40, seed=3):
    rng = np.random.default_rng(seed)
    J = 6
    parents = [-1, 0, 1, 2, 1, 4]
    names = ["Hips", "Spine", "LeftHand", "LeftHandIndex1", "RightHand", "RightHandIndex1"]
    rest = Rotation.random(J, random_state=seed).as_quat()
    sk = Skeleton(names, parents, rng.normal(size=(J, 3)) * 20, rest, meters_per_unit=mpu, up_axis=up, name="Rig")
    rot = Rotation.random(frames * J, random_state=seed + 1).as_quat().reshape(frames, J, 4)
    tra = np.broadcast_to(sk.rest_translations, (frames, J, 3)).copy()
    tra[:, 0] += rng.normal(size=(frames, 3)) * 30
    return Clip(sk, 30.0, rot, tra, name="Take")


@pytest.mark.parametrize("ext", [".glb", ".gltf"])
def test_write_read_round_trip_random_clip(tmp_path, gltf_validator, ext):
    clip = random_clip().replace(name="/Root/Take")   # a USD prim path: the animation is named "Take"
    out = write_asset(Asset("mem", (clip.skeleton,), (clip,)), tmp_path / f"rt{ext}")
    assert gltf_validator(out)[0]["numErrors"] == 0
    back = read_clip(out)
    assert back.name == "Take" and back.fps == 30.0 and back.num_frames == clip.num_frames
    assert back.skeleton.joint_names == clip.skeleton.joint_names
    dots = np.abs(np.sum(back.rotations * clip.rotations, axis=-1))
    assert np.all(np.abs(back.rotations - clip.rotations * np.sign(np.sum(back.rotations * clip.rotations,
                                                                           axis=-1))[..., None]) < 1e-6)
    assert np.all(dots > 1 - 1e-12)
    assert np.allclose(back.translations, clip.translations, atol=1e-5)


def test_write_converts_centimetres_z_up_to_metres_y_up(tmp_path):
    clip = random_clip(mpu=0.01, up="Z")
    out = write_asset(Asset("mem", (clip.skeleton,), (clip,)), tmp_path / "cm.glb")
    back = read_clip(out)
    assert back.skeleton.meters_per_unit == 1.0 and back.skeleton.up_axis == "Y"
    z_to_y = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]])
    expected = clip.world_positions() * 0.01 @ z_to_y.T
    assert np.allclose(back.world_positions(), expected, atol=1e-5)


def test_write_mesh_with_polygons_and_eight_influences_passes_validator(tmp_path, gltf_validator):
    clip = random_clip()
    J = clip.num_joints
    rng = np.random.default_rng(0)
    V = 12
    ji = np.stack([rng.permutation(J)[:6] for _ in range(V)])
    ji[0, 1] = ji[0, 0]                        # a repeated joint: merged on write
    w = rng.random((V, 6))
    w[1] = [1, 0, 0, 0, 0, 0]
    mesh = SkinnedMesh("quads", rng.normal(size=(V, 3)), np.array([4, 4, 4]), np.arange(V),
                       normals=rng.normal(size=(V, 3)), uvs=rng.random((V, 2)), joint_indices=ji, joint_weights=w,
                       geom_bind_xform=trs_to_xform([0, 0.1, 0], [0, 0, 0, 1]))
    out = write_asset(Asset("mem", (clip.skeleton,), (clip,), (mesh,)), tmp_path / "mesh.glb")
    report = gltf_validator(out)[0]
    assert report["numErrors"] == 0, report["messages"]
    g = pygltflib.GLTF2().load(str(out))
    attrs = vars(g.meshes[0].primitives[0].attributes)
    assert attrs.get("JOINTS_1") is not None and attrs.get("JOINTS_2") is None   # 6 influences -> 2 sets
    back = read_asset(out).meshes[0]
    assert back.face_vertex_counts.size == 6                                      # 3 quads -> 6 triangles
    assert np.allclose(back.points, mesh.points + [0, 0.1, 0], atol=1e-6)
    assert np.allclose(back.uvs, mesh.uvs, atol=1e-6)

    def dense(ji, jw):
        d = np.zeros((V, J))
        np.add.at(d, (np.repeat(np.arange(V), ji.shape[1]), ji.reshape(-1)), jw.reshape(-1))
        return d / d.sum(1, keepdims=True)

    assert np.allclose(dense(back.joint_indices, back.joint_weights), dense(ji, w), atol=1e-6)


def test_write_clip_new_animation_and_relocated_external_buffer(tmp_path, gltf_validator):
    src = build_test_gltf(tmp_path, "external")
    clip = read_clip(src)
    sk = clip.skeleton
    hand = sk.index("hand")
    rot = np.broadcast_to(sk.rest_rotations, (10, 4, 4)).copy()
    rot[:, hand] = qz(30)
    bent = Clip(sk, 30.0, rot, name="Bent")                     # rest pose but for the hand
    (tmp_path / "out").mkdir()
    out = write_clip(src, bent, tmp_path / "out" / "copy.gltf")
    assert gltf_validator(out)[0]["numErrors"] == 0
    g = pygltflib.GLTF2().load(str(out))
    # the source's buffer file lies outside the output's folder, where a reader may not look: embedded
    assert g.buffers[0].uri.startswith("data:application/octet-stream;base64,")
    assert g.buffers[1].uri.startswith("data:")               # the new data
    assert [a.name for a in g.animations] == ["Anim", "Bent"]
    assert len(g.animations[1].channels) == 1                 # only the joint that differs from rest
    new = read_asset(out).clip("Bent")
    assert np.all(quat_angle_deg(new.rotations[:, hand], qz(30)) < 1e-4)
    assert np.allclose(read_asset(out).clip("Anim").translations, clip.translations)
    # the same clip written into "Anim" replaces what differs there and adds nothing else
    out2 = write_clip(src, bent, tmp_path / "out" / "anim.glb", animation="Anim")
    g2 = pygltflib.GLTF2().load(str(out2))
    assert len(g2.animations) == 1
    assert sorted((c.target.node, c.target.path) for c in g2.animations[0].channels) == sorted(
        (c.target.node, c.target.path) for c in pygltflib.GLTF2().load(str(src)).animations[0].channels)
    assert gltf_validator(out2)[0]["numErrors"] == 0
    again = read_asset(out2).clip("Anim")
    assert np.all(quat_angle_deg(again.rotations[:10], bent.rotations) < 1e-4)
    assert np.allclose(again.translations[:10], bent.translations, atol=1e-6)


def test_write_clip_rejects_foreign_joints(tmp_path):
    src = build_test_gltf(tmp_path, "glb")
    with pytest.raises(JointMismatchError, match=r"6 joints of clip 'Take' are not in the file's skeleton "
                                                 r"'skin0': 'Hips', 'Spine', 'LeftHand', 'LeftHandIndex1', 'RightHand' \.\.\."):
        write_clip(src, random_clip(), tmp_path / "x.glb")
    assert not (tmp_path / "x.glb").exists()
    with pytest.raises(OutputPathError, match=r"x.glb: an override layer \(--as-layer, as_layer\) needs a USD output"):
        write_clip(src, read_clip(src), tmp_path / "x.glb", as_layer=True)
    assert not (tmp_path / "x.glb").exists() and [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


# --------------------------------------------------------------------------- real files


def test_robot_expressive_read(shared_assets):
    asset = HANDLER.read(shared_assets / "robot_expressive" / "RobotExpressive.glb")
    (sk,) = asset.skeletons                   # two skins over the same 43 joints: one skeleton
    g = pygltflib.GLTF2().load(str(shared_assets / "robot_expressive" / "RobotExpressive.glb"))
    skin_names = {g.nodes[n].name for n in g.skins[0].joints}
    assert len(g.skins[0].joints) == 43 and skin_names <= set(sk.joint_names)
    # the armature node (scale 100, -90° about x) is kept as the root: world positions are metres
    assert sk.joint_names[0] == "RobotArmature" and sk.num_joints == 44
    assert 2.5 < sk.rest_world_positions()[:, 1].max() < 3.5
    assert len(asset.clips) == 14
    assert {"Wave", "ThumbsUp", "Idle", "Dance"} <= {c.name for c in asset.clips}
    wave = asset.clip("Wave")
    assert wave.fps == 24.0 and wave.num_frames == 45
    # 2 skinned nodes (2 primitives each, 4 influences) and 12 mesh nodes below joints (15 primitives,
    # following their joint rigidly): every one of the 7,214 vertices
    skinned = [m for m in asset.meshes if m.rigid_joint() is None]
    rigid = [m for m in asset.meshes if m.rigid_joint() is not None]
    assert len(skinned) == 4 and all(m.joint_indices.shape[1] == 4 for m in skinned)
    assert len(rigid) == 15 and all(m.joint_indices.shape[1] == 1 for m in rigid)
    assert sum(len(m.points) for m in asset.meshes) == 7214
    assert {sk.joint_names[m.rigid_joint()] for m in rigid if m.group == "Head"} == {"Head"}


def test_robot_expressive_write_clip_changes_fingers_only(shared_assets, tmp_path):
    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    asset = read_asset(src)
    wave = asset.clip("Wave")
    sk = wave.skeleton
    fingers = [sk.index(n) for n in ("Thumb.L", "Thumb2.L", "Index.L", "Index2.L",
                                     "Thumb.R", "Thumb2.R", "Index.R", "Index2.R")]
    T = wave.num_frames
    bend = Rotation.from_euler("x", np.linspace(0, 50, T)[:, None], degrees=True).as_quat()[:, None]
    changed = wave.with_joint_rotations(fingers, quat_multiply(wave.rotations[:, fingers], bend))
    out = write_clip(src, changed, tmp_path / "wave.glb")

    back = read_asset(out)
    assert np.all(quat_angle_deg(back.clip("Wave").rotations, changed.rotations) < 1e-4)
    for before, after in zip(asset.clips, back.clips):
        assert before.name == after.name
        if before.name != "Wave":
            assert np.array_equal(before.rotations, after.rotations)
            assert np.array_equal(before.translations, after.translations)
    g0, g1 = pygltflib.GLTF2().load(str(src)), pygltflib.GLTF2().load(str(out))
    assert len(g1.meshes) == len(g0.meshes) and len(g1.materials) == len(g0.materials)
    assert [len(p.targets or []) for m in g1.meshes for p in m.primitives] == \
        [len(p.targets or []) for m in g0.meshes for p in m.primitives]
    assert [a.name for a in g1.animations] == [a.name for a in g0.animations]
    for a0, a1 in zip(g0.animations, g1.animations):
        if a0.name != "Wave":
            assert a0.to_dict() == a1.to_dict()
    # the original binary data is untouched: new data is appended after it
    assert g1.binary_blob()[:g0.buffers[0].byteLength] == g0.binary_blob()[:g0.buffers[0].byteLength]
    assert g1.accessors[:len(g0.accessors)] == g0.accessors
    # the source already has validator errors (non-normalized weights): the copy adds none
    r0, r1 = validate_all(src, out)
    assert r0["numErrors"] > 0
    assert {tuple(e) for e in r1["errors"]} <= {tuple(e) for e in r0["errors"]}
    assert r1["numErrors"] == r0["numErrors"]


def test_webxr_hand_read_and_rewrite(shared_assets, tmp_path, gltf_validator):
    asset = read_asset(shared_assets / "webxr_hand" / "left.glb")
    (sk,) = asset.skeletons
    assert sk.num_joints == 25 and "wrist" in sk.joint_names and "index-finger-phalanx-proximal" in sk.joint_names
    assert asset.clips == ()
    (mesh,) = asset.meshes
    assert mesh.points.shape == (1360, 3) and mesh.joint_indices.max() < 25
    out = write_asset(asset, tmp_path / "left.gltf")
    assert gltf_validator(out)[0]["numErrors"] == 0
    back = read_asset(out)
    assert back.skeletons[0].joint_names == sk.joint_names
    assert np.allclose(back.meshes[0].points, mesh.points, atol=1e-6)
    assert np.allclose(back.skeletons[0].bind_xforms, sk.bind_xforms, atol=1e-5)


def test_glb_header_is_written_consistently(tmp_path):
    out = write_asset(Asset("mem", (random_clip().skeleton,), (random_clip(),)), tmp_path / "h.glb")
    raw = out.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", raw)
    assert (magic, version, length) == (b"glTF", 2, len(raw)) and length % 4 == 0


def test_write_clip_keeps_extensions_materials_extras_and_other_animations(tmp_path, gltf_validator):
    src = build_test_gltf(tmp_path, "embedded")
    d = json.loads(src.read_text())
    d["extensionsUsed"] = ["KHR_materials_emissive_strength", "KHR_texture_transform"]
    d["materials"] = [{"name": "skin", "emissiveFactor": [1, 0.5, 0],
                       "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 3.0}},
                       "extras": {"studio": "kept"}}]
    d["meshes"][0]["primitives"][0]["material"] = 0
    d["nodes"][0]["extras"] = {"rig": "v2"}
    d["asset"]["extras"] = {"note": "from a DCC"}
    other = json.loads(json.dumps(d["animations"][0]))
    other["name"] = "Other"
    d["animations"].append(other)
    src.write_text(json.dumps(d))
    clip = read_clip(src, animation="Anim")
    hand = clip.skeleton.index("hand")
    bent = clip.with_joint_rotations([hand], np.tile(qz(40), (clip.num_frames, 1, 1)))
    out = write_clip(src, bent, tmp_path / "out.gltf", animation="Anim")
    assert gltf_validator(out)[0]["numErrors"] == 0
    e = json.loads(out.read_text())
    for key in ("extensionsUsed", "scenes", "skins"):
        assert e[key] == d[key], key
    # pygltflib spells out the glTF defaults of a material; nothing else changes
    defaults = {"alphaMode": "OPAQUE", "doubleSided": False, "alphaCutoff": 0.5}
    assert {k: v for k, v in e["materials"][0].items() if defaults.get(k, object()) != v} == d["materials"][0]
    assert e["asset"]["extras"] == {"note": "from a DCC"}
    assert e["nodes"][0]["extras"] == {"rig": "v2"}
    assert e["meshes"][0]["primitives"][0]["material"] == 0
    assert [a["name"] for a in e["animations"]] == ["Anim", "Other"]
    assert e["animations"][1] == d["animations"][1]  # the other animation, untouched
    back = read_asset(out)
    assert quat_angle_deg(back.clip("Anim").rotations[:, hand], qz(40)).max() < 1e-4
    np.testing.assert_array_equal(back.clip("Other").rotations, read_asset(src).clip("Other").rotations)


@pytest.mark.parametrize("name", ["robot_expressive/RobotExpressive.glb", "SAMPLE:conversation.glb",
                                  "SAMPLE:humanoid.glb", "GENERATED"])
def test_clips_equal_channel_by_channel_sampling(shared_assets, tmp_path, name):
    """read_gltf copies baked channels straight into the clip (keys checked once per input
    accessor, float32 values converted where they are put, a joint-major block transposed
    once where every joint has a channel of a kind): the same arrays, to the bit, as
    sampling every channel on its own, time-major in memory."""
    from usdhands.formats.gltf_container import load_gltf
    from usdhands.formats.gltf_read import animation_channels, channel_keys, detect_fps, scan_scene, snap_time

    if name == "GENERATED":  # every joint keyed (rotation, translation and scale): the transposed blocks
        rng = np.random.default_rng(3)
        T, J = 41, 9
        sk = Skeleton([f"j{k}" for k in range(J)], [-1] + [int(rng.integers(0, k)) for k in range(1, J)],
                      rng.normal(size=(J, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (J, 1)))
        q = rng.normal(size=(T, J, 4))
        clip = Clip(sk, 24.0, q / np.linalg.norm(q, axis=-1, keepdims=True), rng.normal(size=(T, J, 3)),
                    1 + rng.random((T, J, 3)), name="Take")
        path = write_asset(Asset("g", (sk,), (clip,)), tmp_path / "generated.glb")
    else:
        path = (Path(__file__).resolve().parent.parent / "sample_assets" / name[7:] if name.startswith("SAMPLE:")
                else shared_assets / name)
    asset = read_asset(path)
    doc = load_gltf(path)
    scene = scan_scene(doc)
    binding = scene.bindings[0]
    sk = binding.skeleton
    clips = [c for c in asset.clips if c.skeleton.joint_names == sk.joint_names]
    assert len(clips) == len([a for a in range(len(doc.gltf.animations)) if animation_channels(doc, a, binding)])
    for a, clip in zip(range(len(doc.gltf.animations)), clips):
        chans = animation_channels(doc, a, binding)
        keys = {c: channel_keys(doc, a, c) for c, _, _ in chans}
        rate = detect_fps(np.concatenate([k[0] for k in keys.values()]))
        t0 = min(float(k[0].min()) for k in keys.values())
        at = t0 + np.arange(clip.num_frames) / rate
        want = {"rotation": np.broadcast_to(sk.rest_rotations, clip.rotations.shape).copy(),
                "translation": np.broadcast_to(sk.rest_translations, clip.translations.shape).copy(),
                "scale": np.broadcast_to(sk.rest_scales, clip.scales.shape).copy()}
        for c, j, path_ in chans:
            times, values, interp = keys[c]
            want[path_][:, j] = sample_channel(times, values, interp, at, path_ == "rotation", snap_time(rate))
        assert clip.fps == rate
        assert np.array_equal(clip.rotations, want["rotation"])
        assert np.array_equal(clip.translations, want["translation"])
        assert np.array_equal(clip.scales, want["scale"])
        for a in (clip.rotations, clip.translations, clip.scales):
            assert a.flags.c_contiguous and not a.flags.writeable


def test_differs_from_rest_equals_the_frame_by_frame_test():
    """The writer's min/max shortcut against |values - rest| > tol at every frame, NaN and inf included."""
    from usdhands.formats.gltf_write import _differs_from_rest

    rng = np.random.default_rng(0)
    for trial in range(200):
        T, J = rng.integers(1, 6), rng.integers(1, 8)
        rest = rng.normal(size=(J, 3)) * 10.0 ** rng.integers(-3, 4)
        v = rest[None] + rng.normal(size=(T, J, 3)) * 10.0 ** rng.integers(-9, 0) * (rng.random((T, J, 3)) < 0.3)
        if trial % 5 == 0:
            v[rng.random(v.shape) < 0.2] = np.nan
        if trial % 7 == 0:
            v[rng.random(v.shape) < 0.1] = np.inf
        for tol in (1e-6, 0.0, 1e-3):
            naive = np.any(np.abs(v - rest[None]) > tol * np.maximum(1.0, np.abs(rest))[None], axis=(0, 2))
            assert np.array_equal(_differs_from_rest(v, rest, tol), naive)


def test_a_document_loaded_again_is_equal_and_independent(sample_assets):
    """Loads of the same JSON share pygltflib's decoding (kept by text) but never the objects."""
    from usdhands.formats.gltf_container import clear_decoded_cache, load_gltf

    clear_decoded_cache()
    src = sample_assets / "conversation_bodyonly.glb"
    first = load_gltf(src)
    first.gltf.nodes[0].name = "changed by a writer"
    first.gltf.animations[0].channels.clear()
    second = load_gltf(src)
    clear_decoded_cache()
    fresh = load_gltf(src)
    assert second.gltf == fresh.gltf and second.gltf is not fresh.gltf
    assert second.gltf.nodes[0].name != "changed by a writer" and second.gltf.animations[0].channels
    other = load_gltf(sample_assets / "humanoid.glb")  # another text in between: the documents never mix
    assert load_gltf(src).gltf == fresh.gltf and load_gltf(sample_assets / "humanoid.glb").gltf == other.gltf
    assert other.gltf != fresh.gltf


def test_a_property_pygltflib_types_as_required_missing_reads_without_warnings(tmp_path):
    """A channel without target (skipped by the reader) and a property dataclasses_json
    defaults to None: no RuntimeWarning escapes the read (the fuzz harness counts any
    as a value nobody checked), and the clip is the one without that channel."""
    import warnings

    path = build_test_gltf(tmp_path, "embedded")
    data = json.loads(path.read_text())
    dropped = data["animations"][0]["channels"].pop()  # the channel on the mesh node, which the reader ignores
    data["animations"][0]["channels"].append({"sampler": dropped["sampler"]})  # the same channel without target
    bad = tmp_path / "no_target.gltf"
    bad.write_text(json.dumps(data))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        clip = read_clip(bad)
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in caught]
    want = read_clip(path)
    np.testing.assert_array_equal(clip.rotations, want.rotations)
    np.testing.assert_array_equal(clip.translations, want.translations)


def test_continuous_quaternions_equal_the_frame_by_frame_flips():
    """The writer's sign flips (one exclusive-or pass over the neighbours that point apart)
    against flipping frame by frame; unit checks and lengths as before."""
    from usdhands.formats.gltf_write import _continuous

    rng = np.random.default_rng(8)
    for T, J, scale in ((1, 3, 1.0), (2, 1, 1.0), (50, 4, 1.0), (40, 2, 3.0)):
        q = rng.normal(size=(T, J, 4))
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        q *= scale
        want = q / np.linalg.norm(q, axis=-1, keepdims=True) if scale != 1.0 else q.copy()
        for t in range(1, T):
            for j in range(J):
                a, b = want[t, j], want[t - 1, j]
                if a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] < 0:
                    want[t, j] = -a
        got = _continuous(q)
        assert np.array_equal(got, want)
        if T >= 40:  # random neighbours point apart about half the time: flips were made
            assert (np.sign(got[1:, :, 0]) != np.sign(q[1:, :, 0])).any()

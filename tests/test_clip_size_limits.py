"""Frames x joints limits of the readers (usdhands.model.clip.MAX_JOINT_FRAMES, MAX_FILLED_JOINT_FRAMES):
a file over them is refused in one line before its arrays are allocated, one just under reads.

Found by the usdz fuzz target: a package of 4 time samples, the last at time code 209,722,
read 209,723 frames x 65 joints (2.2 GB of arrays); the same hole in glTF (keys far apart)
and BVH (joints without channels: a 200 KB file asked for 15 GB).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from hostile import check_promise, glb_bytes  # noqa: E402

import usdhands.model.clip as clip_module  # noqa: E402
from usdhands.errors import UsdHandsError  # noqa: E402
from usdhands.formats.io import read_asset  # noqa: E402
from usdhands.model.clip import clip_size_problem  # noqa: E402


def usda_chain(joints: int, times: list[float], tcps: float = 60.0) -> str:
    """A Skeleton of ``joints`` joints in a chain, animated (all joints) at ``times``."""
    paths, p = [], ""
    for i in range(joints):
        p = f"{p}/j{i}" if p else f"j{i}"
        paths.append(p)
    joint_list = ", ".join(f'"{q}"' for q in paths)
    ident = "( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1) )"
    binds = ", ".join(f"( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, {i}, 0, 1) )" for i in range(joints))
    rest = ", ".join([ident] + ["( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 1, 0, 1) )"] * (joints - 1))
    quats = "[" + ", ".join(["(1, 0, 0, 0)"] * joints) + "]"
    trans = "[" + ", ".join(["(0, 1, 0)"] * joints) + "]"
    rot_samples = ", ".join(f"{t:g}: {quats}" for t in times)
    tra_samples = ", ".join(f"{t:g}: {trans}" for t in times)
    return f"""#usda 1.0
(
    defaultPrim = "Root"
    timeCodesPerSecond = {tcps:g}
)

def SkelRoot "Root" (
    prepend apiSchemas = ["SkelBindingAPI"]
)
{{
    def Skeleton "Skel" (
        prepend apiSchemas = ["SkelBindingAPI"]
    )
    {{
        uniform token[] joints = [{joint_list}]
        uniform matrix4d[] bindTransforms = [{binds}]
        uniform matrix4d[] restTransforms = [{rest}]
        rel skel:animationSource = </Root/Skel/Anim>

        def SkelAnimation "Anim"
        {{
            uniform token[] joints = [{joint_list}]
            quatf[] rotations.timeSamples = {{ {rot_samples} }}
            float3[] translations.timeSamples = {{ {tra_samples} }}
            half3[] scales = {"[" + ", ".join(["(1, 1, 1)"] * joints) + "]"}
        }}
    }}
}}
"""


def test_the_limits_let_an_hour_of_capture_read_and_refuse_what_the_fuzzer_found():
    hour = 3600 * 120
    assert clip_size_problem(hour, 200, hour * 200) is None  # an hour at 120 fps, 200 joints: a key per frame
    assert clip_size_problem(hour, 200, hour * 200 // 16) is None  # a key every 16th frame
    assert clip_size_problem(hour, 200, hour * 200 // 17) is not None
    assert clip_size_problem(216_000, 65, 216_000 * 65) is None  # an hour at 60 fps of 65 joints, a key per frame
    assert clip_size_problem(209_723, 65, 4 * 65) is not None  # the .usdz the fuzzer found
    assert clip_size_problem(153_846, 65, 4 * 65) is None  # 9,999,990 joint-frames: under the fill limit
    assert clip_size_problem(1_000_001, 100, 100_000_100) is not None  # a key per frame, over 100 million
    # a reader's count of the values held is asked for only past the fill limit
    assert clip_size_problem(153_846, 65, lambda: 1 // 0) is None
    assert clip_size_problem(209_723, 65, lambda: 260) == clip_size_problem(209_723, 65, 260)


def test_usd_keys_far_apart_refused_in_one_line(tmp_path):
    from pxr import Sdf, UsdUtils

    usda = tmp_path / "root.usda"
    usda.write_text(usda_chain(65, [0, 1, 2, 209_722]))
    with pytest.raises(UsdHandsError) as e:
        read_asset(usda)
    assert str(e.value) == (f"{usda}: /Root/Skel/Anim: 209,723 frames x 65 joints from values for 260 joint-frames: "
                            "more than 10,000,000 joint-frames, over 16 per value the file holds, are refused")
    crate = tmp_path / "root.usdc"
    Sdf.Layer.FindOrOpen(str(usda)).Export(str(crate))
    package = tmp_path / "fuzz.usdz"
    assert UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(crate)), str(package))
    check_promise(["inspect", package], folder=tmp_path, inputs=[package, usda, crate], names=package,
                  message="/Root/Skel/Anim: 209,723 frames x 65 joints from values for 260 joint-frames: more than "
                          "10,000,000 joint-frames, over 16 per value the file holds, are refused")


def test_usd_just_under_the_limits_reads(tmp_path, monkeypatch):
    usda = tmp_path / "keys.usda"
    usda.write_text(usda_chain(5, [0, 1, 2, 99]))  # 100 frames x 5 joints from 4 x 5 values
    monkeypatch.setattr(clip_module, "MAX_FILLED_JOINT_FRAMES", 500)
    clip = read_asset(usda).clips[0]
    assert clip.rotations.shape == (100, 5, 4)
    monkeypatch.setattr(clip_module, "MAX_FILLED_JOINT_FRAMES", 499)
    with pytest.raises(UsdHandsError, match=r"100 frames x 5 joints from values for 20 joint-frames: more than 499 "):
        read_asset(usda)
    dense = tmp_path / "dense.usda"
    dense.write_text(usda_chain(5, list(range(100))))  # a key per frame: only the hard limit
    clip = read_asset(dense).clips[0]
    assert clip.rotations.shape == (100, 5, 4)
    monkeypatch.setattr(clip_module, "MAX_JOINT_FRAMES", 500)
    assert read_asset(dense).clips[0].num_frames == 100
    monkeypatch.setattr(clip_module, "MAX_JOINT_FRAMES", 499)
    with pytest.raises(UsdHandsError) as e:
        read_asset(dense)
    assert str(e.value) == f"{dense}: /Root/Skel/Anim: 100 frames x 5 joints: more than 499 joint-frames are refused"


def glb_chain(joints: int, key_times: list[float], fps: float = 60.0) -> bytes:
    """A glb of a skin of ``joints`` chained nodes; one rotation channel on the root, keys at ``key_times``."""
    times = np.asarray(key_times, np.float32)
    quats = np.tile(np.array([0, 0, 0, 1], np.float32), (len(times), 1))
    binary = times.tobytes() + quats.tobytes()
    nodes = [{"name": f"j{i}", "translation": [0, 1 if i else 0, 0]} | ({"children": [i + 1]} if i + 1 < joints else {})
             for i in range(joints)]
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": nodes,
        "skins": [{"joints": list(range(joints))}],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": times.nbytes},
                        {"buffer": 0, "byteOffset": times.nbytes, "byteLength": quats.nbytes}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(times), "type": "SCALAR",
                       "min": [float(times.min())], "max": [float(times.max())]},
                      {"bufferView": 1, "componentType": 5126, "count": len(times), "type": "VEC4"}],
        "animations": [{"name": "take", "extras": {"usdhands": {"fps": fps}},
                        "samplers": [{"input": 0, "output": 1, "interpolation": "LINEAR"}],
                        "channels": [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}]}],
    }
    return glb_bytes(doc, binary)


def test_gltf_keys_far_apart_refused_in_one_line_and_just_under_reads(tmp_path, monkeypatch):
    far = tmp_path / "far.glb"
    far.write_bytes(glb_chain(65, [0.0, 4000.0]))  # 240,001 frames at 60 fps from 2 keys of one joint
    check_promise(["inspect", far], folder=tmp_path, inputs=[far], names=far,
                  message="animations[0]: 240,001 frames x 65 joints from values for 2 joint-frames: more than "
                          "10,000,000 joint-frames, over 16 per value the file holds, are refused")
    near = tmp_path / "near.glb"
    near.write_bytes(glb_chain(5, [0.0, 1.0, 2.0, 3.0]))  # 181 frames x 5 joints from 4 keys
    monkeypatch.setattr(clip_module, "MAX_FILLED_JOINT_FRAMES", 905)
    assert read_asset(near).clips[0].rotations.shape == (181, 5, 4)
    monkeypatch.setattr(clip_module, "MAX_FILLED_JOINT_FRAMES", 904)
    with pytest.raises(UsdHandsError) as e:
        read_asset(near)
    assert str(e.value) == (f"{near}: animations[0]: 181 frames x 5 joints from values for 4 joint-frames: more than "
                            "904 joint-frames, over 16 per value the file holds, are refused")


def bvh_wide(end_sites: int, frames: int) -> str:
    """A root of one channel with ``end_sites`` children without channels (each with its End Site)."""
    lines = ["HIERARCHY", "ROOT r", "{", "OFFSET 0 0 0", "CHANNELS 1 Xrotation"]
    for i in range(end_sites):
        lines += [f"JOINT j{i}", "{", "OFFSET 0 1 0", "End Site", "{", "OFFSET 0 1 0", "}", "}"]
    lines += ["}", "MOTION", f"Frames: {frames}", "Frame Time: 0.01"] + ["0"] * frames
    return "\n".join(lines) + "\n"


def test_bvh_joints_without_channels_refused_in_one_line_and_just_under_reads(tmp_path, monkeypatch):
    wide = tmp_path / "wide.bvh"
    wide.write_text(bvh_wide(3000, 10_000))  # 6,001 joints (End Sites too), 200 KB: 4.8 GB of arrays
    check_promise(["inspect", wide], folder=tmp_path, inputs=[wide], names=wide,
                  message="10,000 frames x 6,001 joints from values for 10,000 joint-frames: more than "
                          "10,000,000 joint-frames, over 16 per value the file holds, are refused")
    wider = tmp_path / "wider.bvh"
    wider.write_text(bvh_wide(3000, 20_000))
    check_promise(["inspect", wider], folder=tmp_path, inputs=[wider], names=wider,
                  message="20,000 frames x 6,001 joints: more than 100,000,000 joint-frames are refused")
    small = tmp_path / "small.bvh"
    small.write_text(bvh_wide(2, 100))  # 100 frames x 5 joints from 100 values
    monkeypatch.setattr(clip_module, "MAX_FILLED_JOINT_FRAMES", 400)  # 500 > 16 x 100 is false: reads anyway
    assert read_asset(small).clips[0].rotations.shape == (100, 5, 4)
    monkeypatch.setattr(clip_module, "FILL_RATIO", 4)
    with pytest.raises(UsdHandsError) as e:
        read_asset(small)
    assert str(e.value) == (f"{small}: 100 frames x 5 joints from values for 100 joint-frames: more than 400 "
                            "joint-frames, over 4 per value the file holds, are refused")
    monkeypatch.setattr(clip_module, "MAX_FILLED_JOINT_FRAMES", 500)
    assert read_asset(small).clips[0].rotations.shape == (100, 5, 4)
    with pytest.raises(UsdHandsError) as e:  # resampled to 4x the rate: the frames made are counted
        read_asset(small, fps=400.0)
    assert str(e.value).startswith(f"{small}: 397 frames x 5 joints from values for 100 joint-frames: ")

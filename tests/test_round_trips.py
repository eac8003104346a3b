"""Every third-party asset with a skeleton, converted to each writable format and read back.

World joint positions (in metres, so unit conversions are checked too) and detected
hands must survive; glTF outputs must pass the Khronos validator and USD outputs
UsdUtils' compliance checker.
"""

from __future__ import annotations

import numpy as np
import pytest

from usdhands.jobs.conversion import convert
from usdhands.formats.hands import hands_for
from usdhands.formats.io import read_asset
from usdhands.formats.usd_validate import usd_compliance_errors
from usdhands.model.skeleton import short_joint_name

ASSETS = ["leap_hands/fingers-ok.bvh", "leap_hands/gesture-pointing.bvh", "leap_hands/gesture-typing.bvh",
          "robot_expressive/RobotExpressive.glb", "webxr_hand/left.glb", "webxr_hand/right.glb",
          "usd_cesiumman/CesiumMan.usdz"]


def world_m(clip) -> dict[str, np.ndarray]:
    """Short joint name -> (T, 3) world positions in metres."""
    p = clip.world_positions() * clip.skeleton.meters_per_unit
    return {short_joint_name(n): p[:, j] for j, n in enumerate(clip.skeleton.joint_names)}


def rest_world_m(sk) -> dict[str, np.ndarray]:
    p = sk.rest_world_positions() * sk.meters_per_unit
    return {short_joint_name(n): p[j] for j, n in enumerate(sk.joint_names)}


def short_hands(hm):
    return {side: None if h is None else {f: [short_joint_name(j) for j in c] for f, c in h.fingers.items()}
            for side, h in (("left", hm.left), ("right", hm.right))}


# every other format (same-format round trips are in tests/test_format_*.py); the WebXR
# hands have no animation, which BVH needs
CASES = [(name, ext) for name in ASSETS for ext in (".usda", ".glb", ".bvh")
         if not name.endswith(ext) and not (name.startswith("webxr") and ext == ".bvh")]


@pytest.mark.parametrize("name, ext", CASES)
def test_asset_round_trip(shared_assets, tmp_path, gltf_validator, name, ext):
    src = shared_assets / name
    a = read_asset(src)
    out = tmp_path / (src.stem + ext)
    convert(src, out)
    if ext == ".glb":
        report = gltf_validator(out)[0]
        assert report["numErrors"] == 0, report["messages"][:5]
    if ext == ".usda":
        assert usd_compliance_errors(out) == []
    b = read_asset(out)
    extent = max(np.ptp(a.skeletons[0].rest_world_positions(), axis=0).max() * a.skeletons[0].meters_per_unit, 1e-3)
    tol = 1e-5 * extent
    clips_a = a.clips[:1] if ext == ".bvh" else a.clips
    # static glTF nodes above the skin's joints become Xforms above the SkelRoot in USD
    lifted = {short_joint_name(n) for names in a.non_skin_joints.values() for n in names} if ext == ".usda" else set()
    assert len(b.clips) == len(clips_a)
    for ca, cb in zip(clips_a, b.clips):
        assert cb.num_frames == ca.num_frames and cb.fps == pytest.approx(ca.fps)
        pa, pb = world_m(ca), world_m(cb)
        assert set(pa) - set(pb) <= lifted
        for joint, p in pa.items():
            if joint in pb:
                np.testing.assert_allclose(pb[joint], p, atol=tol, err_msg=joint)
    if not a.clips:
        ra, rb = rest_world_m(a.skeletons[0]), rest_world_m(b.skeletons[0])
        assert set(ra) - set(rb) <= lifted
        for joint, p in ra.items():
            if joint in rb:
                np.testing.assert_allclose(rb[joint], p, atol=tol, err_msg=joint)
    # hands: the same joints found before and after (CesiumMan has none)
    if "cesium" not in name.lower():
        before, _ = hands_for(src, a.skeletons[0])
        after, _ = hands_for(out, b.skeletons[0], side_hint=src.stem if src.stem in ("left", "right") else None)
        assert short_hands(after) == short_hands(before)

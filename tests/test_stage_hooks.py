"""USD stage hooks: the jobs on an open stage author into the edit target (or the layer named) and save nothing."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdSkel

import usdhands
import usdhands.usd
from usdhands.errors import UsdHandsError
from usdhands.formats.usd_schema_data import read_finger_motion


@pytest.fixture()
def ok_usda(ok_glb, tmp_path):
    usdhands.convert(ok_glb, tmp_path / "ok.usda")
    return tmp_path / "ok.usda"


def _in_memory(path):
    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().TransferContent(Sdf.Layer.FindOrOpen(str(path)))
    return stage


def _rotations(stage, anim_path="/Root/ok_00", times=range(89)):
    """Joint order and (frames, J, 4) local rotations at ``times``, read back through UsdSkel's AnimQuery."""
    cache = UsdSkel.Cache()
    query = cache.GetAnimQuery(UsdSkel.Animation(stage.GetPrimAtPath(anim_path)))
    rots = []
    for t in times:
        _, r, _ = query.ComputeJointLocalTransformComponents(t)
        rots.append(np.array(r))
    return [str(j) for j in query.GetJointOrder()], np.array(rots)


def _finger_columns(joints):
    return [i for i, j in enumerate(joints) if "Index" in j or "Pinky" in j]


def test_synthesize_stage_authors_into_the_layer_named(ok_usda):
    stage = _in_memory(ok_usda)
    root_before = stage.GetRootLayer().ExportToString()
    joints, before = _rotations(stage)
    fingers = Sdf.Layer.CreateAnonymous("fingers.usda")
    # a sublayer of the session layer: stronger than the root layer, whose opinions it overrides
    stage.GetSessionLayer().subLayerPaths.append(fingers.identifier)

    edit = usdhands.usd.synthesize_stage(stage, "/Root/Humanoid", options=usdhands.SynthesizeOptions(k=3),
                                         layer=fingers)
    assert (edit.skeleton, edit.animation, edit.layer) == ("/Root/Humanoid", "/Root/ok_00", fingers.identifier)
    assert set(edit.report["hands"]) == {"left", "right"} and edit.report["k"] == 3
    # the root layer is untouched; the edits are in the layer named
    assert stage.GetRootLayer().ExportToString() == root_before
    assert fingers.GetPrimAtPath("/Root/ok_00") is not None
    assert fingers.GetAttributeAtPath("/Root/ok_00.rotations") is not None
    # read back through UsdSkel: the fingers changed, the body did not
    joints_after, after = _rotations(stage)
    assert joints_after[:len(joints)] == joints
    cols = _finger_columns(joints)
    body = [i for i, j in enumerate(joints) if j.endswith(("Hips", "Spine"))]
    assert np.abs(after[:, cols] - before[:, cols]).max() > 0.01
    np.testing.assert_allclose(after[:, body], before[:, body], atol=1e-6)
    # the same motion the synthesize job writes into a file
    usdhands.synthesize(ok_usda, ok_usda.with_name("job.usda"), usdhands.SynthesizeOptions(k=3))
    _, from_job = _rotations(Usd.Stage.Open(str(ok_usda.with_name("job.usda"))))
    np.testing.assert_allclose(after, from_job, atol=1e-6)
    record = read_finger_motion(stage.GetPrimAtPath("/Root/ok_00"))
    assert record["method"] == "synthesis" and record["parameters"]["k"] == 3


def test_hooks_author_into_the_current_edit_target_and_save_nothing(ok_usda):
    on_disk = ok_usda.read_bytes()
    stage = Usd.Stage.Open(str(ok_usda))
    stage.SetEditTarget(stage.GetSessionLayer())
    usdhands.usd.reduce_stage(stage)
    assert not stage.GetRootLayer().dirty
    assert stage.GetSessionLayer().GetAttributeAtPath("/Root/ok_00.rotations") is not None
    assert read_finger_motion(stage.GetPrimAtPath("/Root/ok_00"))["method"] == "reduction"

    stage = Usd.Stage.Open(str(ok_usda))  # default edit target: the root layer, dirty but not saved
    joints, before = _rotations(stage)
    edit = usdhands.usd.reduce_stage(stage, options=usdhands.ReduceOptions(steps="range<5,rmsd<0.5"))
    assert stage.GetRootLayer().dirty and ok_usda.read_bytes() == on_disk
    assert edit.layer == stage.GetRootLayer().identifier
    _, after = _rotations(stage)
    cols = _finger_columns(joints)
    # the reduced hand differs from the keyed one by at most the reduction's reported error
    worst = edit.report["steps"][-1]["max_error_deg"]
    assert 0 < np.abs(after[:, cols] - before[:, cols]).max() and worst > 0


def test_a_layer_outside_the_stage_is_refused(ok_usda):
    stage = _in_memory(ok_usda)
    stray = Sdf.Layer.CreateAnonymous("stray.usda")
    with pytest.raises(UsdHandsError, match="is not in the stage's layer stack"):
        usdhands.usd.reduce_stage(stage, layer=stray)
    assert stray.ExportToString().count("def") == 0


def test_no_animated_skeleton_at_the_path(ok_usda):
    with pytest.raises(UsdHandsError, match="no animated Skeleton at /Nope"):
        usdhands.usd.synthesize_stage(_in_memory(ok_usda), "/Nope")

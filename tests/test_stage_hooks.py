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


@pytest.fixture(scope="module")
def closing_scene(tmp_path_factory):
    """The humanoid's left hand closing 15+ mm deep into a cylinder under its palm: the .usda and the cylinder .obj."""
    from interaction_data import write_closing_scene

    d = tmp_path_factory.mktemp("correct_stage")
    return d, write_closing_scene(d)


def _depth_read_back_mm(stage, clip, anim_path):
    """Deepest finger penetration of the cylinder per frame (mm), for the rotations UsdSkel's AnimQuery
    computes on the composed stage (mapped onto ``clip``'s joints)."""
    from interaction_data import colliders_for, cylinder_under_palm

    from usdhands.algorithms.interaction.correction import chain_posers, penetration_depth_mm
    from usdhands.algorithms.interaction.finger_geometry import InteractionConfig
    from usdhands.model.clip import Clip
    from usdhands.samples.humanoid import humanoid_handmap

    joints, rots = _rotations(stage, anim_path, range(clip.num_frames))
    leaf = [j.rsplit("/", 1)[-1] for j in joints]
    order = [leaf.index(n.rsplit("/", 1)[-1]) for n in clip.skeleton.joint_names]
    read = Clip(clip.skeleton, clip.fps, rots[:, order].astype(np.float64), name=clip.name)  # xyzw from Vt
    posers = chain_posers(read, humanoid_handmap(clip.skeleton), InteractionConfig())
    return penetration_depth_mm(read, posers, colliders_for(read, cylinder_under_palm()))


def test_correct_stage_authors_the_correction_into_the_edit_target(closing_scene):
    d, clip = closing_scene
    stage = _in_memory(d / "closing.usda")
    anim = str(next(p.GetPath() for p in stage.Traverse() if p.IsA(UsdSkel.Animation)))
    root_before = stage.GetRootLayer().ExportToString()
    assert _depth_read_back_mm(stage, clip, anim).max() > 15
    stage.SetEditTarget(stage.GetSessionLayer())

    edit = usdhands.usd.correct_stage(stage, props=[d / "cyl.obj"])
    assert edit.layer == stage.GetSessionLayer().identifier and edit.animation == anim
    assert stage.GetRootLayer().ExportToString() == root_before  # the edit target only
    assert stage.GetSessionLayer().GetAttributeAtPath(anim + ".rotations") is not None
    assert edit.report["penetration_before_mm"]["max"] > 15 and edit.report["penetration_after_mm"]["max"] <= 0.5
    assert set(edit.report["penetration_after_mm"]) == {"max", "mean", "frames"}
    depth = _depth_read_back_mm(stage, clip, anim)
    assert depth.max() <= 0.5
    record = read_finger_motion(stage.GetPrimAtPath(anim))
    assert record["method"] == "interaction" and record["parameters"]["props"] == [str(d / "cyl.obj")]
    # the same motion the correct job writes into a file
    usdhands.correct(d / "closing.usda", d / "job.usda", usdhands.CorrectOptions(props=(d / "cyl.obj",)))
    _, from_job = _rotations(Usd.Stage.Open(str(d / "job.usda")), anim, range(clip.num_frames))
    _, on_stage = _rotations(stage, anim, range(clip.num_frames))
    np.testing.assert_allclose(on_stage, from_job, atol=1e-6)


def test_correct_stage_into_a_named_layer_saves_nothing(closing_scene, tmp_path):
    d, clip = closing_scene
    src = tmp_path / "closing.usda"
    src.write_bytes((d / "closing.usda").read_bytes())
    stage = Usd.Stage.Open(str(src))
    fix = Sdf.Layer.CreateAnonymous("fix.usda")
    stage.GetSessionLayer().subLayerPaths.append(fix.identifier)
    edit = usdhands.usd.correct_stage(stage, options=usdhands.CorrectOptions(props=(d / "cyl.obj",), margin=1.0),
                                      layer=fix)
    assert edit.layer == fix.identifier and edit.report["output"] == fix.identifier
    assert not stage.GetRootLayer().dirty and not stage.GetSessionLayer().GetPrimAtPath(edit.animation)
    assert src.read_bytes() == (d / "closing.usda").read_bytes()
    assert fix.GetAttributeAtPath(edit.animation + ".rotations") is not None
    assert _depth_read_back_mm(stage, clip, edit.animation).max() <= 0.5


def test_correct_stage_without_props_is_refused(closing_scene):
    d, _ = closing_scene
    stage = _in_memory(d / "closing.usda")
    with pytest.raises(UsdHandsError, match="--props: name at least one prop"):
        usdhands.usd.correct_stage(stage)
    assert stage.GetSessionLayer().ExportToString().count("over") == 0

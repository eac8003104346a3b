"""The reader's fold of a world transform that does not move and is a rotation times one scale
(``fold_similarity_into_roots``) against the general fold (``fold_into_roots``) it stands in for."""

from __future__ import annotations

import shutil

import numpy as np
from pxr import Gf, Usd, UsdGeom, UsdSkel

from usdhands.formats import usd_read
from usdhands.formats.io import read_asset
from usdhands.formats.usd_common import fold_into_roots, fold_similarity_into_roots
from usdhands.model.rotations import trs_to_xform


def _random_case(rng, T, J):
    parents = np.array([-1] + [int(rng.integers(-1, j)) for j in range(1, J)])
    t = rng.normal(size=(T, J, 3)) * 10
    q = rng.normal(size=(T, J, 4)) * rng.uniform(0.2, 3, (T, J, 1))  # not unit: the fold normalizes them
    s = rng.uniform(0.5, 2, (T, J, 3))
    return parents, t, q, s


def test_fold_of_a_similarity_is_the_general_fold():
    """Rotations times scales from 1e-3 to 1e3, any translation: the general fold's numbers within 1e-14
    (relative to the largest value) and its quaternions' signs, non-root joints untouched (bit for bit)."""
    rng = np.random.default_rng(11)
    for trial in range(300):
        T, J = int(rng.integers(1, 40)), int(rng.integers(1, 6))
        parents, t, q, s = _random_case(rng, T, J)
        world = trs_to_xform(rng.normal(size=3) * 100, rng.normal(size=4), np.full(3, 10 ** rng.uniform(-3, 3)))
        if trial % 5 == 0:  # a Z-up stage's: -90 degrees about x (float32 cosines), no scale
            world = np.array([[1, 0, 0, 0], [0, -4.371139e-08, -1, 0], [0, 1, -4.371139e-08, 0], [0, 0, 0, 1.0]])
        fast = fold_similarity_into_roots(parents, world, t, q, s)
        assert fast is not None, trial
        slow = fold_into_roots(parents, np.repeat(world[None], T, axis=0), t, q, s)
        roots = parents < 0
        for a, b, x in zip(fast, slow, (t, q, s)):
            assert a.shape == b.shape and a.dtype == b.dtype == np.float64
            assert np.abs(a - b).max() <= 1e-14 * max(1.0, np.abs(b).max()), trial
            assert a[:, ~roots].tobytes() == np.asarray(x, dtype=np.float64)[:, ~roots].tobytes()
        assert ((fast[1] * slow[1]).sum(-1) > 0).all(), trial  # the same hemisphere everywhere


def test_fold_of_a_similarity_leaves_the_rest_to_the_general_fold():
    """None (the general fold's case) for a world with shear, two scales, a mirror, a projective or
    non-finite entry, and for root rotations or scales the general fold must see (NaN, zero length,
    zero or negative scales)."""
    rng = np.random.default_rng(12)
    parents, t, q, s = _random_case(rng, 5, 3)
    base = trs_to_xform(rng.normal(size=3), rng.normal(size=4), np.full(3, 0.01))
    assert fold_similarity_into_roots(parents, base, t, q, s) is not None
    for change in ("shear", "scales", "mirror", "projective", "nan", "inf", "tiny shear"):
        w = base.copy()
        if change == "shear":
            w[:3, 1] += 0.3 * w[:3, 0]
        elif change == "scales":
            w = w @ np.diag([1.0, 1.0, 1.001, 1.0])
        elif change == "mirror":
            w = w @ np.diag([1.0, -1.0, 1.0, 1.0])
        elif change == "projective":
            w[3, 0] = 1e-3
        elif change == "nan":
            w[0, 3] = np.nan
        elif change == "inf":
            w[1, 1] = np.inf
        else:  # orthogonal only to 1e-9: the general fold takes it apart as it is
            w[:3, 1] += 1e-9 * w[:3, 0]
        assert fold_similarity_into_roots(parents, w, t, q, s) is None, change
    for change in ("nan rotation", "zero rotation", "zero scale", "negative scale", "nan scale", "inf rotation"):
        q2, s2 = q.copy(), s.copy()
        if change == "nan rotation":
            q2[2, 0, 1] = np.nan
        elif change == "zero rotation":
            q2[1, 0] = 0.0
        elif change == "zero scale":
            s2[0, 0, 2] = 0.0
        elif change == "negative scale":
            s2[3, 0, 0] = -1.0
        elif change == "nan scale":
            s2[4, 0, 1] = np.nan
        else:
            q2[0, 0, 3] = np.inf
        assert fold_similarity_into_roots(parents, base, t, q2, s2) is None, change
    # a joint that is no root may hold anything: only the roots' values are taken apart
    q3 = q.copy()
    q3[:, 1:] = 0.0
    assert fold_similarity_into_roots(np.array([-1, 0, 0]), base, t, q3, s) is not None


def _rotated(src, dst, *, moving: bool = False):
    """``src`` (a .usda with a SkelRoot) saved as ``dst`` with the SkelRoot rotated to Z-up and scaled
    by 0.01 (time-sampled, changing, where ``moving``): its skeleton's world transform."""
    shutil.copy(src, dst)
    stage = Usd.Stage.Open(str(dst))
    root = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Root))
    x = UsdGeom.Xformable(root)
    x.ClearXformOpOrder()
    rotate = x.AddRotateXOp()
    x.AddScaleOp().Set(Gf.Vec3f(0.01, 0.01, 0.01))
    if moving:
        rotate.Set(-90.0, 0.0)
        rotate.Set(-60.0, 1000.0)
    else:
        rotate.Set(-90.0)
    stage.GetRootLayer().Save()
    return dst


def test_reading_a_z_up_skeleton_gives_the_general_folds_numbers(sample_assets, tmp_path, monkeypatch):
    """A skeleton under a Z-up, 0.01-scaled SkelRoot reads as with the general fold (within 1e-14 of the
    largest value), and one whose SkelRoot turns over time is folded by the general fold alone."""
    still = _rotated(sample_assets / "humanoid.usda", tmp_path / "still.usda")
    moving = _rotated(sample_assets / "humanoid.usda", tmp_path / "moving.usda", moving=True)
    calls = []
    real = usd_read.fold_similarity_into_roots

    def counted(*args):
        out = real(*args)
        calls.append(out is not None)
        return out

    monkeypatch.setattr(usd_read, "fold_similarity_into_roots", counted)
    fast = read_asset(still)
    assert calls and all(calls)
    calls.clear()
    read_asset(moving)
    assert not calls  # a world that moves: never offered to the similarity fold
    monkeypatch.setattr(usd_read, "fold_similarity_into_roots", lambda *args: None)
    slow = read_asset(still)
    assert len(fast.clips) == len(slow.clips) >= 1
    for a, b in zip(fast.clips, slow.clips):
        for x, y in ((a.rotations, b.rotations), (a.translations, b.translations), (a.scales, b.scales)):
            assert np.abs(x - y).max() <= 1e-14 * max(1.0, np.abs(y).max())
        assert ((a.rotations * b.rotations).sum(-1) > 0).all()
        assert not np.allclose(a.translations, read_asset(sample_assets / "humanoid.usda").clips[0].translations)


def test_a_shared_z_up_asset_reads_as_with_the_general_fold(shared_assets, monkeypatch):
    """CesiumMan.usdz (an Armature turned Z-up in the file), from ../shared/assets."""
    path = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    fast = read_asset(path)
    monkeypatch.setattr(usd_read, "fold_similarity_into_roots", lambda *args: None)
    slow = read_asset(path)
    for a, b in zip(fast.clips, slow.clips):
        for x, y in ((a.rotations, b.rotations), (a.translations, b.translations), (a.scales, b.scales)):
            assert np.abs(x - y).max() <= 1e-14 * max(1.0, np.abs(y).max())


def test_world_rotation_quaternion_is_matrix_to_quat_to_the_bit():
    """The similarity fold's quaternion of the world rotation (four Python floats) is
    ``quat_canonical(matrix_to_quat(r))`` bit for bit: random rotations, rotations about one axis (ties
    between the diagonal and the trace), and rotations made slightly not orthogonal, on both sides of
    the tolerance that sends matrix_to_quat to its SVD."""
    from usdhands.formats.usd_common import _rotation_quat
    from usdhands.model.rotations import matrix_to_quat, quat_canonical

    rng = np.random.default_rng(13)
    bent = 0
    for trial in range(20000):
        q = rng.normal(size=4)
        if trial % 4 == 0:
            q = np.zeros(4)
            q[rng.integers(4)] = 1.0
            q[rng.integers(4)] += rng.choice([0.0, 1e-8, 1.0])
        r = trs_to_xform(np.zeros(3), q, np.ones(3))[:3, :3]
        if trial % 3 == 0:
            r = r + rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-16, -10)
            gram = r @ r.T
            bent += not (np.abs(gram - np.eye(3)) <= 1e-12 + 1e-5 * np.eye(3)).all()
        got = np.array(_rotation_quat(r))
        assert got.tobytes() == quat_canonical(matrix_to_quat(r)).tobytes(), trial
    assert bent > 100  # the SVD branch was seen

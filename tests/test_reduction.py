"""Finger DOF reduction (Jörg and O'Sullivan 2009): rules, distances, chains, model, CLI."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from usdhands.algorithms.reduction.reduce import (
    RangeRule, RmsdRule, align_euler_branches, continuous_euler_curves, pair_rmsd, paper_style_names, parse_steps, reduce_curves, standardise,
)
from usdhands.algorithms.reduction.model import Constant, ReductionModel, Relation
from usdhands.errors import ConfigError
from usdhands.model import HandMap, HandSide

ROOT = Path(__file__).resolve().parent.parent
T = 1200
_t = np.arange(T) / T * 2 * np.pi


def basis(k: int) -> np.ndarray:
    """Orthonormal zero-mean curves over whole periods: mean 0, mean square 1, mutually orthogonal."""
    return math.sqrt(2) * np.sin((k + 1) * _t + 0.3)


def unit_with_corr(u: np.ndarray, n: np.ndarray, r: float) -> np.ndarray:
    """A standardised curve whose correlation with standardised ``u`` is exactly ``r`` (``n`` orthogonal)."""
    return r * u + math.sqrt(1 - r * r) * n


# ---------------------------------------------------------------------------- the distances
def naive_rmsd(values):
    """The paper's equations pair by pair: standardise, then rmsd1 and rmsd2 (a twin of pair_rmsd)."""
    T_, D = values.shape
    z = [(values[:, k] - values[:, k].mean()) / values[:, k].std() for k in range(D)]
    r1 = np.full((D, D), np.nan)
    r2 = np.full((D, D), np.nan)
    for i in range(D):
        for j in range(D):
            if i != j:
                r1[i, j] = math.sqrt(sum((z[i] - z[j]) ** 2) / T_)
                r2[i, j] = math.sqrt(sum((z[i] + z[j]) ** 2) / T_)
    return r1, r2


def test_pair_rmsd_matches_paper_equations_pair_by_pair():
    rng = np.random.default_rng(3)
    v = rng.normal(size=(300, 7)).cumsum(axis=0) * rng.uniform(0.5, 20, size=7) + rng.uniform(-40, 40, size=7)
    v[:, 3] = -0.7 * v[:, 1] + rng.normal(0, 0.5, 300)
    r1, r2 = pair_rmsd(v)
    n1, n2 = naive_rmsd(v)
    assert np.allclose(r1, n1, atol=1e-9, equal_nan=True)
    assert np.allclose(r2, n2, atol=1e-9, equal_nan=True)
    # rmsd1^2 = 2 - 2r and rmsd2^2 = 2 + 2r for standardised curves (population std)
    r = np.corrcoef(v.T)
    off = ~np.eye(7, dtype=bool)
    assert np.allclose(r1[off] ** 2, 2 - 2 * r[off]) and np.allclose(r2[off] ** 2, 2 + 2 * r[off])


def test_standardised_curves_have_mean_0_and_std_1_and_still_curves_are_left_out():
    v = np.stack([np.linspace(0, 10, 50), np.full(50, 3.0), np.sin(np.arange(50.0))], axis=1)
    z, valid = standardise(v)
    assert valid.tolist() == [True, False, True]
    assert np.allclose(z[:, valid].mean(axis=0), 0) and np.allclose(z[:, valid].std(axis=0), 1)
    assert np.all(z[:, 1] == 0)
    r1, r2 = pair_rmsd(v)
    assert np.all(np.isnan(r1[1])) and np.all(np.isnan(r2[:, 1]))


def test_pairs_across_groups_are_not_compared():
    u = basis(0)
    v = np.stack([u, 2 * u, 3 * u, -u], axis=1)
    r1, r2 = pair_rmsd(v, ["left", "left", "right", "right"])
    assert r1[0, 1] == pytest.approx(0, abs=1e-6) and np.isnan(r1[0, 2]) and np.isnan(r2[1, 3])
    assert r2[2, 3] == pytest.approx(0, abs=1e-6)
    res = reduce_curves(v, ["a.x", "b.x", "c.x", "d.x"], "rmsd<0.3", groups=["left", "left", "right", "right"])
    rel = {r.dependent: r.controlling for r in res.final.model.relations}
    assert rel == {"a.x": "b.x", "d.x": "c.x"}
    assert res.final.dofs_left_by_group == {"left": 1, "right": 1}


# ---------------------------------------------------------------------------- relations and formulas
def test_positive_and_negative_relations_rebuild_by_the_papers_formulas():
    rng = np.random.default_rng(7)
    b = 40 * basis(0) + 10
    a_pos = 0.3 * b - 5 + rng.normal(0, 0.4, T)  # smaller std, positive slope
    a_neg = -0.6 * b + 2 + rng.normal(0, 0.4, T)  # smaller std, negative slope
    v = np.stack([a_pos, b, a_neg], axis=1)
    res = reduce_curves(v, ["p.x", "b.x", "n.x"], "rmsd<0.3")
    rel = {r.dependent: r for r in res.final.model.relations}
    assert set(rel) == {"p.x", "n.x"}
    assert rel["p.x"].controlling == "b.x" and rel["p.x"].kind == "rmsd1"
    assert rel["n.x"].controlling == "b.x" and rel["n.x"].kind == "rmsd2"
    rebuilt = res.final.model.apply(v)
    mb, sb = b.mean(), b.std()
    paper_pos = (b - mb) / sb * a_pos.std() + a_pos.mean()  # §4.2, first equation
    paper_neg = (mb - b) / sb * a_neg.std() + a_neg.mean()  # §4.2, second equation
    assert np.allclose(rebuilt[:, 0], paper_pos, atol=1e-10)
    assert np.allclose(rebuilt[:, 2], paper_neg, atol=1e-10)
    # mean and standard deviation preserved; the controlling curve untouched
    for k in (0, 2):
        assert rebuilt[:, k].mean() == pytest.approx(v[:, k].mean(), abs=1e-9)
        assert rebuilt[:, k].std() == pytest.approx(v[:, k].std(), rel=1e-9)
    assert np.array_equal(rebuilt[:, 1], b)
    # the error figures: RMS per curve = std * rmsd (no pass over the data), checked against the rebuild
    err = rebuilt - v
    assert np.allclose(res.final.curve_rms_error_deg, np.sqrt(np.mean(err ** 2, axis=0)), rtol=1e-9, atol=1e-12)
    assert np.allclose(res.final.curve_max_error_deg, np.abs(err).max(axis=0))
    assert res.final.rms_error_deg == pytest.approx(math.sqrt(np.mean(err ** 2)), rel=1e-9)
    assert res.final.max_error_deg == pytest.approx(np.abs(err).max())
    # the reported distances are those of the standardised pair
    r1, r2 = naive_rmsd(v)
    assert rel["p.x"].rmsd == pytest.approx(r1[0, 1], abs=1e-9)
    assert rel["n.x"].rmsd == pytest.approx(r2[2, 1], abs=1e-9)


def test_relation_needs_the_right_kind_of_rule():
    b = 10 * basis(0)
    v = np.stack([-0.5 * b + 0.01 * basis(1), b], axis=1)
    assert reduce_curves(v, ["a.x", "b.x"], "rmsd1<0.3").final.model.relations == ()
    only2 = reduce_curves(v, ["a.x", "b.x"], "rmsd2<0.3").final.model.relations
    assert [(r.dependent, r.kind) for r in only2] == [("a.x", "rmsd2")]


def test_threshold_is_strict_and_uses_the_distance():
    u, n = basis(0), basis(1)
    r = 1 - 0.3 ** 2 / 2  # rmsd1 exactly 0.3
    v = np.stack([5 * unit_with_corr(u, n, r + 1e-6), 9 * u], axis=1)
    assert reduce_curves(v, ["a.x", "b.x"], "rmsd<0.3").final.dofs_left == 1
    v = np.stack([5 * unit_with_corr(u, n, r - 1e-6), 9 * u], axis=1)
    assert reduce_curves(v, ["a.x", "b.x"], "rmsd<0.3").final.dofs_left == 2


# ---------------------------------------------------------------------------- range rule
def test_constants_and_near_constants():
    v = np.stack([
        np.full(T, 12.5),  # never moves
        7 + 0.999 * np.linspace(0, 1, T),  # range 0.999: below 1
        -3 + np.linspace(0, 1, T),  # range exactly 1: not below 1
        4.0 + 4.9 * np.linspace(0, 1, T) ** 2,  # range 4.9
        30 * basis(0),
    ], axis=1)
    names = ["k.x", "near.x", "edge.x", "small.x", "big.x"]
    res = reduce_curves(v, names, "range<1,range<5")
    s1, s2 = res.steps
    assert [c.curve for c in s1.model.constants] == ["k.x", "near.x"]
    assert [c.curve for c in s2.model.constants] == ["k.x", "near.x", "edge.x", "small.x"]
    assert s1.dofs_left == 3 and s2.dofs_left == 1
    rebuilt = s2.model.apply(v)
    for k in range(4):
        assert np.all(rebuilt[:, k] == rebuilt[0, k]) and rebuilt[0, k] == pytest.approx(v[:, k].mean(), abs=1e-12)
    assert s1.model.constants[1].range == pytest.approx(0.999)
    # error figures: max = the largest distance from the mean, RMS over every entry
    full = s2.model.apply(v) - v
    assert s2.max_error_deg == pytest.approx(np.abs(full).max())
    assert s2.rms_error_deg == pytest.approx(math.sqrt(np.mean(full ** 2)))
    assert np.allclose(s2.curve_rms_error_deg, np.sqrt(np.mean(full ** 2, axis=0)))
    assert np.allclose(s2.curve_max_error_deg, np.abs(full).max(axis=0))
    assert s2.worst_curve == names[int(np.argmax(np.abs(full).max(axis=0)))] == "small.x"
    assert res.to_dict()["steps"][2]["worst_curve"] == "small.x"


def test_never_moving_curve_stays_free_without_a_range_rule():
    v = np.stack([np.zeros(T), np.zeros(T), 10 * basis(0)], axis=1)
    res = reduce_curves(v, ["a.x", "b.x", "c.x"], "rmsd<0.5")
    assert res.final.dofs_left == 3 and res.final.model.relations == ()


def test_constant_curves_take_no_part_in_relations():
    u = basis(0)
    v = np.stack([0.2 * u, 0.3 * u + 0.001 * basis(1), 30 * u], axis=1)  # ranges ~0.57, ~0.85, 85
    res = reduce_curves(v, ["a.x", "b.x", "c.x"], "range<1,rmsd<0.3")
    assert [c.curve for c in res.final.model.constants] == ["a.x", "b.x"]
    assert res.final.model.relations == () and res.final.dofs_left == 1
    res = reduce_curves(v, ["a.x", "b.x", "c.x"], "rmsd<0.3")
    assert {r.dependent: r.controlling for r in res.final.model.relations} == {"a.x": "c.x", "b.x": "c.x"}


# ---------------------------------------------------------------------------- chains and ties
def test_chain_is_resolved_to_the_final_controller_with_composed_sign():
    u, n1, n2 = basis(0), basis(1), basis(2)
    cos = 0.96875  # rmsd = 0.25 for each link; a to c: r = cos^2, rmsd ~0.351 > 0.3
    c = u
    b = unit_with_corr(c, n1, cos)
    a = unit_with_corr(b, n2, cos)
    v = np.stack([1.0 * a + 3, -2.0 * b + 1, 3.0 * c - 7], axis=1)  # b inverted: both links negative
    res = reduce_curves(v, ["a.x", "b.x", "c.x"], "rmsd<0.3")
    rel = {r.dependent: r for r in res.final.model.relations}
    assert rel["b.x"].controlling == "c.x" and rel["b.x"].kind == "rmsd2"
    assert rel["a.x"].controlling == "c.x" and rel["a.x"].kind == "rmsd1"  # (-1) * (-1)
    assert rel["a.x"].rmsd == pytest.approx(math.sqrt(2 - 2 * cos ** 2), abs=1e-6)
    assert rel["a.x"].rmsd > 0.3  # §5.2: kept though above the threshold
    assert res.final.dofs_left == 1 and res.final.model.controlling_curves == ("c.x",)
    # the composed map is the paper's formula from the final controller
    rebuilt = res.final.model.apply(v)
    va, vc = v[:, 0], v[:, 2]
    assert np.allclose(rebuilt[:, 0], (vc - vc.mean()) / vc.std() * va.std() + va.mean(), atol=1e-10)
    # and equals rebuilding a from b and b from c in turn
    rb = (vc.mean() - vc) / vc.std() * v[:, 1].std() + v[:, 1].mean()
    ra = (v[:, 1].mean() - rb) / v[:, 1].std() * va.std() + va.mean()
    assert np.allclose(rebuilt[:, 0], ra, atol=1e-10)


def test_longer_chain_ends_at_the_root():
    u = basis(0)
    cos = 0.99
    curves = [u]
    for k in range(1, 5):
        curves.append(unit_with_corr(curves[-1], basis(k), cos))
    v = np.stack([(5 - k) * c for k, c in enumerate(curves)], axis=1)  # std 5, 4, 3, 2, 1
    res = reduce_curves(v, [f"c{k}.x" for k in range(5)], "rmsd<0.2")
    assert {r.controlling for r in res.final.model.relations} == {"c0.x"}
    assert res.final.dofs_left == 1


def _tie_curves(std_b: float, std_c: float) -> np.ndarray:
    u, n = basis(0), basis(1)
    c15, s15 = math.cos(math.radians(15)), math.sin(math.radians(15))
    a = u  # rmsd(a, b) = rmsd(a, c) = 0.261 < 0.3; rmsd(b, c) = 0.518
    b = c15 * u + s15 * n
    c = c15 * u - s15 * n
    return np.stack([1.0 * a, std_b * b, std_c * c], axis=1)


def test_tie_between_two_controllers_goes_to_the_larger_std():
    names = ["a.x", "b.x", "c.x"]
    res = reduce_curves(_tie_curves(2.0, 3.0), names, "rmsd<0.3")
    assert {r.dependent: r.controlling for r in res.final.model.relations} == {"a.x": "c.x"}
    res = reduce_curves(_tie_curves(3.0, 2.0), names, "rmsd<0.3")
    assert {r.dependent: r.controlling for r in res.final.model.relations} == {"a.x": "b.x"}
    assert res.final.dofs_left == 2


def test_equal_standard_deviations_the_earlier_curve_controls():
    u = basis(0)
    v = np.stack([4 * u, -4 * u], axis=1)
    res = reduce_curves(v, ["first.x", "second.x"], "rmsd<0.3")
    [r] = res.final.model.relations
    assert (r.dependent, r.controlling, r.kind) == ("second.x", "first.x", "rmsd2")
    res = reduce_curves(v[:, ::-1], ["first.x", "second.x"], "rmsd<0.3")
    [r] = res.final.model.relations
    assert (r.dependent, r.controlling) == ("second.x", "first.x")


# ---------------------------------------------------------------------------- steps
def _hand():
    """Ten curves whose step table is known (range and correlations set exactly)."""
    u, n = basis(0), basis(1)
    cols = {
        "k1.x": np.full(T, 2.0),  # range 0
        "k2.x": 0.2 * basis(3),  # range ~0.57
        "s1.x": 1.5 * basis(4),  # range ~4.2
        "m.x": 40 * u,  # the big controller
        "p1.x": 20 * unit_with_corr(u, n, 0.99),  # rmsd ~0.141 with m
        "p2.x": -10 * unit_with_corr(u, basis(5), 0.98),  # rmsd2 0.2 with m
        "q1.x": 15 * unit_with_corr(u, basis(6), 0.9),  # rmsd 0.447: only at 0.5
        "f1.x": 25 * basis(7),  # free
        "f2.x": 25 * basis(8),  # free
        "s2.x": 1.6 * unit_with_corr(u, basis(9), 0.999),  # range ~4.5, related to m at 0.3
    }
    return np.stack(list(cols.values()), axis=1), list(cols)


def test_step_table_counts_on_constructed_data():
    v, names = _hand()
    res = reduce_curves(v, names)  # the paper's four steps
    table = [(s.condition, s.dofs_left) for s in res.steps]
    assert table == [
        ("range < 1", 8),  # k1, k2 constant
        ("range < 1 + rmsd < 0.3", 5),  # p1, p2, s2 from m
        ("range < 5", 6),  # k1, k2, s1, s2 constant; no relations (paper's table 5: 31 > 27)
        ("range < 5 + rmsd < 0.5", 3),  # p1, p2, q1 from m; left m, f1, f2
    ]
    d = res.to_dict()
    assert [s["dofs_left"] for s in d["steps"]] == [10, 8, 5, 6, 3]
    assert d["steps"][0]["condition"] == "original"
    assert {r["dependent"] for r in d["relations"]} == {"p1.x", "p2.x", "q1.x"}
    assert {c["curve"] for c in d["constants"]} == {"k1.x", "k2.x", "s1.x", "s2.x"}
    # errors grow with each simplification of the same range rule
    assert res.steps[1].rms_error_deg > res.steps[0].rms_error_deg
    assert res.steps[3].max_error_deg >= res.steps[2].max_error_deg


def test_rmsd_steps_accumulate_until_the_next_range_step():
    v, names = _hand()
    res = reduce_curves(v, names, "rmsd1<0.5,rmsd2<0.3,range<1")
    assert [s.condition for s in res.steps] == ["rmsd1 < 0.5", "rmsd1 < 0.5 + rmsd2 < 0.3", "range < 1"]
    first = {r.dependent for r in res.steps[0].model.relations}
    second = {r.dependent for r in res.steps[1].model.relations}
    assert "p2.x" not in first and "p2.x" in second and first < second
    assert res.steps[2].model.relations == ()


@pytest.mark.parametrize("text, message", [
    ("", "no steps given"),
    (" , ", "no steps given"),
    ("range<1,foo", "bad step 'foo': expected range<N, rmsd<N, rmsd1<N or rmsd2<N with N a positive number"),
    ("range<-1", "bad step 'range<-1': expected range<N, rmsd<N, rmsd1<N or rmsd2<N with N a positive number"),
    ("rmsd<nan", "bad step 'rmsd<nan': expected range<N, rmsd<N, rmsd1<N or rmsd2<N with N a positive number"),
    ("range>1", "bad step 'range>1': expected range<N, rmsd<N, rmsd1<N or rmsd2<N with N a positive number"),
    ("range<1,,rmsd<0.3", "bad step '': expected range<N, rmsd<N, rmsd1<N or rmsd2<N with N a positive number"),
])
def test_bad_steps_are_refused_with_a_clear_message(text, message):
    with pytest.raises(ConfigError) as e:
        parse_steps(text)
    assert str(e.value) == message


def test_parse_steps():
    assert parse_steps(" range < 1 , rmsd<0.3,rmsd1<0.4, rmsd2<5e-1") == (
        RangeRule(1.0), RmsdRule(0.3), RmsdRule(0.4, ("rmsd1",)), RmsdRule(0.5, ("rmsd2",)))


# ---------------------------------------------------------------------------- the model
def test_model_json_round_trip_and_schema(tmp_path):
    v, names = _hand()
    model = reduce_curves(v, names, source="hand.bvh").final.model
    path = model.save(tmp_path / "m.json")
    back = ReductionModel.load(path)
    assert back == model
    assert np.array_equal(back.apply(v), model.apply(v))
    d = json.loads(path.read_text())
    assert d["free"] == ["m.x", "f1.x", "f2.x"] and d["controlling"] == ["m.x"]
    assert d["condition"] == "range < 5 + rmsd < 0.5" and d["source"] == "hand.bvh"


def test_schema_shipped_in_the_package_is_the_source_schema():
    assert (ROOT / "schemas" / "reduction_model.schema.json").read_bytes() == \
        (ROOT / "usdhands" / "schemas" / "reduction_model.schema.json").read_bytes()


def test_model_load_errors(tmp_path):
    with pytest.raises(ConfigError, match="no such reduction model file"):
        ReductionModel.load(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    with pytest.raises(ConfigError, match="not valid JSON"):
        ReductionModel.load(bad)
    v, names = _hand()
    d = reduce_curves(v, names).final.model.to_dict()
    d["relations"][0]["kind"] = "rmsd3"
    bad.write_text(json.dumps(d))
    with pytest.raises(ConfigError) as e:
        ReductionModel.load(bad)
    assert str(e.value) == f"{bad}: relations/0/kind: not a valid reduction model: 'rmsd3' is not one of ['rmsd1', 'rmsd2']"
    d = reduce_curves(v, names).final.model.to_dict()
    d["relations"][0]["controlling"] = d["relations"][1]["dependent"]
    bad.write_text(json.dumps(d))
    with pytest.raises(ConfigError, match="chains must be resolved"):
        ReductionModel.load(bad)


def test_model_apply_reads_only_the_free_curves():
    model = ReductionModel(("a.x", "b.x", "c.x"), (Constant("c.x", 4.0),),
                           (Relation.from_statistics("a.x", "b.x", "rmsd2", 0.1, 1.0, 2.0, 10.0, 4.0),))
    v = np.array([[99.0, 10.0, 99.0], [99.0, 14.0, 99.0]])
    out = model.apply(v)
    assert np.allclose(out, [[1.0, 10.0, 4.0], [-1.0, 14.0, 4.0]])  # a = -(b - 10)/4*2 + 1
    with pytest.raises(ValueError, match=r"Curves \['c.x'\] of the model are not among the given names"):
        model.apply(v[:, :2], ["a.x", "b.x"])


# ---------------------------------------------------------------------------- Euler branches
@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_continuous_euler_curves_follow_a_bend_through_the_gimbal(order):
    from usdhands.model.rotations import euler_deg_to_quat, quat_angle_deg, quat_to_euler_deg, unwrap_deg

    frames = 200
    truth = np.zeros((frames, 2, 3))
    truth[:, 0, 1] = np.linspace(0, 130, frames)  # middle angle through 90: the per-frame branch flips
    truth[:, 0, 0] = 10 * np.sin(np.linspace(0, 3, frames))
    truth[:, 0, 2] = -5 + 3 * np.cos(np.linspace(0, 2, frames))
    truth[:, 1] = [20.0, -30.0, 40.0]  # a still joint
    q = euler_deg_to_quat(truth, order)
    raw = unwrap_deg(quat_to_euler_deg(q, order), axis=0).reshape(frames, 6)
    assert np.abs(np.diff(raw, axis=0)).max() > 100  # the jump being fixed
    cont = continuous_euler_curves(raw)
    assert np.allclose(cont, truth.reshape(frames, 6), atol=1e-6)
    assert quat_angle_deg(euler_deg_to_quat(cont.reshape(frames, 2, 3), order), q).max() < 1e-9


def _continuous_naive(values):
    """Frame by frame: of the two triples (each angle moved by 360s), the one nearest the previous frame."""
    e = values.reshape(len(values), -1, 3)
    out = e.copy()
    for t in range(1, len(e)):
        for j in range(e.shape[1]):
            a = e[t, j]
            cands = [a, np.array([a[0] + 180, 180 - a[1], a[2] + 180])]
            cands = [c + 360 * np.round((out[t - 1, j] - c) / 360) for c in cands]
            dists = [np.abs(c - out[t - 1, j]).sum() for c in cands]
            out[t, j] = cands[int(dists[1] < dists[0])]
    return out.reshape(values.shape)


def test_continuous_euler_curves_match_the_frame_by_frame_twin():
    rng = np.random.default_rng(5)
    from usdhands.model.rotations import euler_deg_to_quat, quat_to_euler_deg

    walk = np.cumsum(rng.normal(0, 6, size=(400, 4, 3)), axis=0)  # wanders through gimbal regions
    raw = quat_to_euler_deg(euler_deg_to_quat(walk, "XYZ"), "XYZ").reshape(400, 12)
    assert np.allclose(continuous_euler_curves(raw), _continuous_naive(raw), atol=1e-9)


# ---------------------------------------------------------------------------- naming
def test_paper_style_names():
    hm = HandMap(
        left=HandSide("left", "LeftHand", fingers={
            "thumb": ("LeftHandThumb1", "LeftHandThumb2", "LeftHandThumb3"),
            "ring": ("LeftHandRing1", "LeftHandRing2", "LeftHandRing3")}),
        right=HandSide("right", "hand_r", fingers={
            "index": ("index_metacarpal_r", "index_01_r", "index_02_r", "index_03_r"),
            "pinky": ("Root/Hand/PinkyA", "Root/Hand/PinkyB")}),
    )
    names = paper_style_names(hm)
    assert names["LeftHandThumb1.z"] == "leThumbCMCz" and names["LeftHandThumb3.z"] == "leThumbIPz"
    assert names["LeftHandRing2.y"] == "leRingPIPy" and names["LeftHandRing1.x"] == "leRingMCPx"
    assert names["index_metacarpal_r.x"] == "riIndexCMCx" and names["index_01_r.y"] == "riIndexMCPy"
    assert names["PinkyA.y"] == "riPinkyPIPy" and names["PinkyB.y"] == "riPinkyDIPy"


def test_bad_arrays_are_refused():
    v = np.stack([basis(0), basis(1)], axis=1)
    v[5, 1] = np.nan
    with pytest.raises(ValueError, match="Expected finite values, got NaN or infinity"):
        reduce_curves(v, ["a.x", "b.x"])
    with pytest.raises(ValueError, match=r"Expected values to have shape \(T, D\), got \(5,\)"):
        reduce_curves(np.zeros(5), ["a.x"])
    with pytest.raises(ValueError, match="Expected 2 names, got 1"):
        reduce_curves(np.zeros((5, 2)), ["a.x"])


# ---------------------------------------------------------------------------- the command line
LEAP = ("leap_hands", "gesture-typing.bvh")


def run_cli(capsys, *argv) -> tuple[int, str, str]:
    from usdhands.cli import main

    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_leap_never_moving_third_joints_are_irrelevant_at_step_1(shared_assets, capsys):
    for name in ("fingers-ok.bvh", "gesture-pointing.bvh", "gesture-typing.bvh"):
        code, out, err = run_cli(capsys, "reduce", shared_assets / "leap_hands" / name, "--json", "--step", "1")
        assert code == 0, err
        report = json.loads(out)
        assert report["curves"] == 45 and report["steps"][0]["dofs_left"] == 45
        assert report["steps"][1]["condition"] == "range < 1"
        third = {f"r{f}3.{a}" for f in ("Thumb", "Index", "Mid", "Ring", "Pinky") for a in "xyz"}
        constants = {c["curve"]: c for c in report["constants"]}
        assert third <= set(constants), name
        assert all(constants[c]["value"] == 0 for c in third)
        assert constants["rIndex3.y"]["curve_paper"] == "riIndexDIPy"
        assert constants["rThumb3.z"]["curve_paper"] == "riThumbIPz"
        # the moving joints are not all constant: step 1 leaves DOFs, the last step fewer
        assert report["steps"][1]["dofs_left"] == 45 - len(constants) > 0
        assert report["steps"][-1]["dofs_left"] < report["steps"][2]["dofs_left"]


def test_reduce_json_report_layout(shared_assets, capsys):
    code, out, _ = run_cli(capsys, "reduce", shared_assets.joinpath(*LEAP), "--json")
    assert code == 0
    report = json.loads(out)
    assert [s["condition"] for s in report["steps"]] == [
        "original", "range < 1", "range < 1 + rmsd < 0.3", "range < 5", "range < 5 + rmsd < 0.5"]
    for s in report["steps"]:
        assert set(s) >= {"condition", "dofs_left", "rms_error_deg", "max_error_deg"}
    for r in report["relations"]:
        assert set(r) >= {"dependent", "controlling", "kind", "rmsd"} and r["kind"] in ("rmsd1", "rmsd2")
    assert all(set(c) >= {"curve", "value"} for c in report["constants"])
    # the reported rmsd is the distance of the original pair, recomputed here
    from usdhands.jobs.reduction import load_finger_curves

    _, _, curves, _ = load_finger_curves(shared_assets.joinpath(*LEAP), None, None, None, "XYZ")
    r1, r2 = pair_rmsd(curves.values)
    col = {n: k for k, n in enumerate(curves.names)}
    for r in report["relations"]:
        m = r1 if r["kind"] == "rmsd1" else r2
        assert r["rmsd"] == pytest.approx(m[col[r["dependent"]], col[r["controlling"]]], abs=1e-9)


def test_reduce_then_expand_reproduces_the_reduced_clip(shared_assets, tmp_path, capsys):
    from usdhands.algorithms.reduction.model import ReductionModel
    from usdhands.jobs.reduction import load_finger_curves
    from usdhands.formats.io import read_clip
    from usdhands.model.rotations import quat_angle_deg

    src = shared_assets.joinpath(*LEAP)
    reduced, model = tmp_path / "reduced.bvh", tmp_path / "model.json"
    code, out, err = run_cli(capsys, "reduce", src, "-o", reduced, "--model", model)
    assert code == 0, err
    assert f"wrote {reduced}" in out
    m = ReductionModel.load(model)
    assert m.condition == "range < 5 + rmsd < 0.5" and m.relations and m.constants
    assert m.metadata["paper_names"]["rIndex2.y"] == "riIndexPIPy"

    # expand the original: the controlling curves are the same, so the result is the reduced clip
    from_orig = tmp_path / "from_orig.bvh"
    assert run_cli(capsys, "expand", src, "--model", model, "-o", from_orig)[0] == 0
    # expand the reduced clip: reproduces itself (BVH stores 6 decimals: one rounding step each way)
    again = tmp_path / "again.bvh"
    code, out, err = run_cli(capsys, "expand", reduced, "--model", model, "-o", again)
    assert code == 0, err
    assert out.startswith(f"{reduced}: rebuilt {len(m.relations)} dependent curves from "
                          f"{len(m.controlling_curves)} controlling curves and set {len(m.constants)} constants")
    r_red, r_orig, r_again = (read_clip(p).rotations for p in (reduced, from_orig, again))
    assert quat_angle_deg(r_red, r_orig).max() < 1e-9
    # 6 decimals: 5e-7 degrees per angle, times the relations' scales for the rebuilt curves
    assert quat_angle_deg(r_red, r_again).max() < 1e-5

    # the reduced clip really is the model's rebuild of the original: dependents follow their controllers
    # (read as expand reads curves for a model: continuity and Euler branch judged on the free curves)
    from usdhands.algorithms.reduction.reduce import model_curves

    red_clip = read_clip(reduced)
    curves = model_curves(red_clip, [red_clip.skeleton.index(c.rsplit(".", 1)[0]) for c in m.curves[::3]], m)
    v = curves.values
    col = {n: k for k, n in enumerate(curves.names)}
    for r in m.relations:
        assert np.allclose(v[:, col[r.dependent]], r.scale * v[:, col[r.controlling]] + r.offset, atol=1e-5)
    for c in m.constants:
        assert np.allclose(v[:, col[c.curve]], c.value, atol=1e-5)
    # and differs from the original where the model rebuilt something
    _, _, orig, _ = load_finger_curves(src, None, None, None, "XYZ")
    assert np.abs(orig.values - v).max() > 1.0


def test_expand_in_memory_is_exact(shared_assets):
    from usdhands.jobs.reduction import load_finger_curves
    from usdhands.model.finger_dofs import apply_finger_curves, finger_curves
    from usdhands.model.rotations import quat_angle_deg

    clip, _, curves, sides = load_finger_curves(shared_assets.joinpath(*LEAP), None, None, None, "XYZ")
    model = reduce_curves(curves.values, curves.names, groups=sides).final.model
    reduced = apply_finger_curves(clip, curves.with_values(model.apply(curves.values, curves.names)))
    again_curves = finger_curves(reduced, curves.joints)
    again_curves = again_curves.with_values(continuous_euler_curves(again_curves.values))
    again = apply_finger_curves(reduced, again_curves.with_values(model.apply(again_curves.values, curves.names)))
    assert quat_angle_deg(reduced.rotations, again.rotations).max() < 1e-9


@pytest.mark.parametrize("steps, message", [
    ("range<1,foo", "bad step 'foo': expected range<N, rmsd<N, rmsd1<N or rmsd2<N with N a positive number"),
    ("rmsd<0", "bad step 'rmsd<0': expected range<N, rmsd<N, rmsd1<N or rmsd2<N with N a positive number"),
    ("", "no steps given"),
])
def test_cli_bad_steps_exit_2(shared_assets, capsys, steps, message):
    code, out, err = run_cli(capsys, "reduce", shared_assets.joinpath(*LEAP), "--steps", steps)
    assert code == 2 and out == ""
    assert err == f"usdhands: error: {message}\n"


def test_cli_user_mistakes(shared_assets, tmp_path, capsys):
    src = shared_assets.joinpath(*LEAP)
    code, _, err = run_cli(capsys, "reduce", src, "--hands", "left")
    assert code == 2 and err == f"usdhands: error: {src}: no left hand with fingers (hands found: right)\n"
    code, _, err = run_cli(capsys, "reduce", src, "--model", tmp_path / "x.bvh", "-o", tmp_path / "x.bvh")
    assert code == 2 and err == f"usdhands: error: {tmp_path / 'x.bvh'}: output path equals the -o file; choose another file\n"
    cesium = shared_assets / "usd_cesiumman" / "CesiumMan.usdz"
    code, _, err = run_cli(capsys, "reduce", cesium)
    assert code == 2 and err.startswith(f"usdhands: error: {cesium}: no hand found in skeleton") and err.count("\n") == 1
    code, _, err = run_cli(capsys, "reduce", src, "--step", "5")
    assert code == 2 and err == "usdhands: error: --step 5 is out of range: 4 step(s) given\n"
    model = ReductionModel(("LeftHandIndex1.x", "LeftHandIndex1.y", "LeftHandIndex1.z"),
                           (Constant("LeftHandIndex1.x", 1.0),))
    model.save(tmp_path / "m.json")
    code, _, err = run_cli(capsys, "expand", src, "--model", tmp_path / "m.json", "-o", tmp_path / "o.bvh")
    assert code == 2
    assert err == (f"usdhands: error: {src}: none of the joints of the reduction model m.json is in the file "
                   "(the model has LeftHandIndex1)\n")
    assert not (tmp_path / "o.bvh").exists()


def test_plots_are_written(shared_assets, tmp_path, capsys):
    code, out, err = run_cli(capsys, "reduce", shared_assets.joinpath(*LEAP), "--plot", tmp_path / "plots")
    assert code == 0, err
    names = sorted(p.name for p in (tmp_path / "plots").iterdir())
    assert names == ["reduction_curves.png", "reduction_ranges.png", "reduction_rmsd1.png",
                     "reduction_rmsd2.png", "reduction_scatter.png"]
    for p in (tmp_path / "plots").iterdir():
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and 5_000 < len(data) < 150_000


def test_robot_expressive_two_bone_fingers_without_pinky(shared_assets, tmp_path, capsys, gltf_validator):
    from usdhands.formats.io import read_clip
    from usdhands.model.rotations import quat_angle_deg

    src = shared_assets / "robot_expressive" / "RobotExpressive.glb"
    reduced, model = tmp_path / "wave.glb", tmp_path / "wave.json"
    code, out, err = run_cli(capsys, "reduce", src, "--animation", "Wave", "--json", "-o", reduced, "--model", model)
    assert code == 0, err
    report = json.loads(out)
    # thumb: 2 joints; index, middle, ring: palm bone + 2 joints; no pinky; both hands
    assert report["curves"] == 2 * (2 + 3 * 3) * 3 == 66
    assert report["steps"][0]["dofs_left_by_hand"] == {"left": 33, "right": 33}
    assert report["steps"][-1]["dofs_left"] < 66
    m = ReductionModel.load(model)
    assert not any("Pinky" in c for c in m.curves)
    assert m.metadata["paper_names"]["Thumb2.R.z"] == "riThumbIPz"
    assert m.metadata["paper_names"]["Index2.L.y"] == "leIndexDIPy"
    # the source itself has validator errors (non-normalised skin weights): the output adds none
    out_report, src_report = gltf_validator(reduced, src)
    assert out_report["numErrors"] <= src_report["numErrors"]
    assert {e["code"] for e in out_report["messages"] if e["severity"] == 0} <= \
        {e["code"] for e in src_report["messages"] if e["severity"] == 0} == {"ACCESSOR_WEIGHTS_NON_NORMALIZED"}
    again = tmp_path / "again.glb"
    assert run_cli(capsys, "expand", reduced, "--animation", "Wave", "--model", model, "-o", again)[0] == 0
    a, b = read_clip(reduced, animation="Wave"), read_clip(again, animation="Wave")
    assert quat_angle_deg(a.rotations, b.rotations).max() < 1e-6
    # one hand only
    code, out, _ = run_cli(capsys, "reduce", src, "--animation", "Wave", "--hands", "right", "--json")
    assert code == 0 and json.loads(out)["curves"] == 33


def test_other_euler_order_round_trips_and_bad_order_is_refused(shared_assets, tmp_path, capsys):
    from usdhands.formats.io import read_clip
    from usdhands.model.rotations import quat_angle_deg

    src = shared_assets.joinpath(*LEAP)
    reduced, model = tmp_path / "r.bvh", tmp_path / "m.json"
    code, _, err = run_cli(capsys, "reduce", src, "--order", "zyx", "-o", reduced, "--model", model)
    assert code == 0, err
    assert ReductionModel.load(model).order == "ZYX"
    out = tmp_path / "e.bvh"
    assert run_cli(capsys, "expand", src, "--model", model, "-o", out)[0] == 0
    assert quat_angle_deg(read_clip(reduced).rotations, read_clip(out).rotations).max() < 1e-9
    code, _, err = run_cli(capsys, "reduce", src, "--order", "XXY")
    assert code == 2 and err == "usdhands: error: bad --order 'XXY': expected a permutation of XYZ such as XYZ or ZYX\n"


def test_across_hands_relates_curves_of_both_hands():
    u = 20 * basis(0)
    v = np.stack([u, 0.5 * u + 0.01 * basis(1), 0.7 * u, 15 * basis(2)], axis=1)
    names = ["L1.x", "L2.x", "R1.x", "R2.x"]
    sides = ["left", "left", "right", "right"]
    apart = reduce_curves(v, names, "rmsd<0.3", groups=sides).final
    pooled = reduce_curves(v, names, "rmsd<0.3", groups=sides, across_groups=True).final
    assert {r.dependent: r.controlling for r in apart.model.relations} == {"L2.x": "L1.x"}
    assert {r.dependent: r.controlling for r in pooled.model.relations} == {"L2.x": "L1.x", "R1.x": "L1.x"}
    assert apart.dofs_left_by_group == {"left": 1, "right": 2}
    assert pooled.dofs_left_by_group == {"left": 1, "right": 1}


def test_cli_across_hands_on_a_two_handed_clip(tmp_path, capsys):
    """Both hands of the sample conversation given the same finger curves: pooled, the left controls all."""
    from usdhands.formats.io import write_asset
    from usdhands.model.asset import Asset
    from usdhands.model.hand_detection import detect_hands
    from usdhands.samples.gestures import conversation_clip

    clip = conversation_clip().slice(0, 300)
    sk = clip.skeleton
    hands = detect_hands(sk)
    left = [sk.index(j) for j in hands.left.finger_joints]
    right = [sk.index(j) for j in hands.right.finger_joints]
    # BVH has no rest rotations (the reader's rest is the identity), so equal local rotations
    # read back as equal finger curves
    twin = clip.with_joint_rotations(left, clip.rotations[:, right])
    path = tmp_path / "twins.bvh"
    write_asset(Asset(path=None, skeletons=(sk,), clips=(twin,)), path)

    code, out, err = run_cli(capsys, "reduce", path, "--json")
    assert code == 0, err
    apart = json.loads(out)
    assert apart["steps"][-1]["dofs_left_by_hand"]["left"] == apart["steps"][-1]["dofs_left_by_hand"]["right"] > 0
    code, out, err = run_cli(capsys, "reduce", path, "--json", "--across-hands")
    assert code == 0, err
    pooled = json.loads(out)
    assert pooled["steps"][-1]["dofs_left_by_hand"] == {"left": apart["steps"][-1]["dofs_left_by_hand"]["left"],
                                                         "right": 0}
    assert any(r["dependent"].startswith("Right") and r["controlling"].startswith("Left") and r["rmsd"] < 1e-4
               for r in pooled["relations"])


def test_reduce_expand_through_usd(sample_assets, tmp_path, capsys):
    from usdhands.formats.io import read_clip
    from usdhands.model.rotations import quat_angle_deg

    src = sample_assets / "humanoid.usda"
    reduced, model = tmp_path / "reduced.usda", tmp_path / "m.json"
    code, out, err = run_cli(capsys, "reduce", src, "-o", reduced, "--model", model)
    assert code == 0, err
    m = ReductionModel.load(model)
    assert m.relations and m.constants and "LeftHandIndex2.y" in m.curves  # short names of USD joint paths
    from_orig, again = tmp_path / "from_orig.usda", tmp_path / "again.usda"
    assert run_cli(capsys, "expand", src, "--model", model, "-o", from_orig)[0] == 0
    assert run_cli(capsys, "expand", reduced, "--model", model, "-o", again)[0] == 0
    r_red, r_orig, r_again = (read_clip(p).rotations for p in (reduced, from_orig, again))
    assert quat_angle_deg(r_red, r_orig).max() < 1e-9
    assert quat_angle_deg(r_red, r_again).max() < 2e-5  # USD stores quatf (float32): about 6e-6 degrees
    assert quat_angle_deg(r_red, read_clip(src).rotations).max() > 0.1


def _renamed(path, out, renames: dict):
    """Write the clip of ``path`` as BVH with some joints renamed: a rig that lacks those joints."""
    import dataclasses

    from usdhands.formats.io import read_clip, write_asset
    from usdhands.model.asset import Asset

    clip = read_clip(path)
    sk = dataclasses.replace(clip.skeleton, joint_names=tuple(renames.get(n, n) for n in clip.skeleton.joint_names))
    clip = clip.replace(skeleton=sk)
    write_asset(Asset(path=None, skeletons=(sk,), clips=(clip,)), out)
    return out


def test_expand_onto_another_clip_of_the_same_rig(shared_assets, tmp_path, capsys):
    """A model made on one recording rebuilds another of the same rig from that recording's free curves."""
    from usdhands.algorithms.reduction.reduce import model_curves
    from usdhands.formats.io import read_clip
    from usdhands.model.finger_dofs import apply_finger_curves
    from usdhands.model.rotations import quat_angle_deg

    model = tmp_path / "typing.json"
    assert run_cli(capsys, "reduce", shared_assets.joinpath(*LEAP), "--model", model)[0] == 0
    m = ReductionModel.load(model)
    other = shared_assets / "leap_hands" / "gesture-pointing.bvh"
    out = tmp_path / "pointing.bvh"
    code, _, err = run_cli(capsys, "expand", other, "--model", model, "-o", out)
    assert code == 0, err
    clip = read_clip(other)
    joints = [clip.skeleton.index(c.rsplit(".", 1)[0]) for c in m.curves[::3]]
    before = model_curves(clip, joints, m)
    col = {n: k for k, n in enumerate(before.names)}
    b = before.values
    want = m.apply(b, before.names)
    for c in m.free_curves:  # the other take's own keyed curves are kept
        assert np.array_equal(want[:, col[c]], b[:, col[c]])
    for r in m.relations:  # the dependents follow the other take's controllers by the stored map
        assert np.allclose(want[:, col[r.dependent]], r.scale * b[:, col[r.controlling]] + r.offset)
    for c in m.constants:
        assert np.all(want[:, col[c.curve]] == c.value)
    expected = apply_finger_curves(clip, before.with_values(want))
    got = read_clip(out)
    assert quat_angle_deg(got.rotations, expected.rotations).max() < 1e-4  # BVH stores 6 decimals
    assert quat_angle_deg(got.rotations, clip.rotations).max() > 1.0  # something was rebuilt
    # expanding the expansion changes nothing, though this recording's rotations jump between frames
    # (tracking glitches) and rebuilt curves leave the first frame's Euler range
    again = tmp_path / "again.bvh"
    assert run_cli(capsys, "expand", out, "--model", model, "-o", again)[0] == 0
    assert quat_angle_deg(read_clip(again).rotations, got.rotations).max() < 1e-4


def test_expand_onto_a_rig_lacking_joints(shared_assets, tmp_path, capsys):
    src = shared_assets.joinpath(*LEAP)
    model = tmp_path / "typing.json"
    assert run_cli(capsys, "reduce", src, "--model", model)[0] == 0
    m = ReductionModel.load(model)
    assert "rIndex2.y" in m.controlling_curves and "rPinky3.x" in m.constant_curves
    # a controlling joint missing: nothing can be rebuilt from it
    no_ctrl = _renamed(src, tmp_path / "no_index2.bvh", {"rIndex2": "rIndexB"})
    code, out, err = run_cli(capsys, "expand", no_ctrl, "--model", model, "-o", tmp_path / "o.bvh")
    driven = ", ".join(r.dependent for r in m.relations if r.controlling.startswith("rIndex2."))
    assert code == 2 and out == ""
    assert err == (f"usdhands: error: {no_ctrl}: controlling joint rIndex2 of the reduction model typing.json is not "
                   f"in the file (needed to rebuild {driven})\n")
    assert not (tmp_path / "o.bvh").exists()
    # a joint with constant curves only missing: the rest is rebuilt, with a note
    no_tip = _renamed(src, tmp_path / "no_pinky3.bvh", {"rPinky3": "rPinkyTip"})
    out_path = tmp_path / "o2.bvh"
    code, out, err = run_cli(capsys, "expand", no_tip, "--model", model, "-o", out_path)
    assert code == 0, err
    assert err == "usdhands: note: joints of the reduction model typing.json that no_pinky3.bvh lacks are skipped: " \
                  "rPinky3\n"
    assert f"rebuilt {len(m.relations)} dependent curves" in out and f"set {len(m.constants) - 3} constants" in out
    # no joint at all in common
    none = _renamed(src, tmp_path / "none.bvh", {n: n + "_x" for n in ("rThumb1", "rThumb2", "rThumb3", "rIndex1",
                                                                         "rIndex2", "rIndex3", "rMid1", "rMid2",
                                                                         "rMid3", "rRing1", "rRing2", "rRing3",
                                                                         "rPinky1", "rPinky2", "rPinky3")})
    code, _, err = run_cli(capsys, "expand", none, "--model", model, "-o", tmp_path / "o3.bvh")
    assert code == 2 and err.startswith(f"usdhands: error: {none}: none of the joints of the reduction model "
                                        "typing.json is in the file (the model has rThumb1, rThumb2, rThumb3, "
                                        "rIndex1, rIndex2, rIndex3, ... (15 in all))")


def test_model_subset_keeps_what_rebuilds_the_kept_curves():
    m = ReductionModel(("a.x", "b.x", "c.x", "d.x"), (Constant("d.x", 2.0),),
                       (Relation("b.x", "a.x", "rmsd1", 0.1, 2.0, 1.0),))
    s = m.subset(["a.x", "b.x", "c.x"])
    assert s.curves == ("a.x", "b.x", "c.x") and s.constants == () and s.relations == m.relations
    assert m.subset(["a.x", "c.x", "d.x"]).relations == ()
    with pytest.raises(ValueError, match="Curve 'b.x' is rebuilt from 'a.x', which is not kept"):
        m.subset(["b.x", "c.x"])


def test_reduce_and_expand_write_usd_override_layers(sample_assets, tmp_path, capsys):
    from usdhands.formats.io import read_clip
    from usdhands.model.rotations import quat_angle_deg

    src = sample_assets / "humanoid.usda"
    full, layer, model = tmp_path / "full.usda", tmp_path / "layer.usda", tmp_path / "m.json"
    assert run_cli(capsys, "reduce", src, "-o", full, "--model", model)[0] == 0
    code, _, err = run_cli(capsys, "reduce", src, "-o", layer, "--as-layer")
    assert code == 0, err
    text = layer.read_text()
    assert "subLayers" in text[:600] and "humanoid.usda" in text[:600] and "def Mesh" not in text
    assert len(text) < full.stat().st_size
    assert quat_angle_deg(read_clip(layer).rotations, read_clip(full).rotations).max() < 1e-5
    again = tmp_path / "again.usda"
    code, _, err = run_cli(capsys, "expand", layer, "--model", model, "-o", again, "--as-layer")
    assert code == 0, err
    assert "@./layer.usda@" in again.read_text()[:600]
    from usdhands.formats.usd_validate import usd_compliance_errors

    assert usd_compliance_errors(layer) == [] and usd_compliance_errors(again) == []
    assert quat_angle_deg(read_clip(again).rotations, read_clip(full).rotations).max() < 2e-5
    for argv, message in ((["reduce", src, "-o", tmp_path / "x.glb", "--as-layer"],
                           f"{tmp_path / 'x.glb'}: --as-layer needs a USD output (.usd, .usda, .usdc)"),
                          (["reduce", src, "--as-layer"], "--as-layer needs -o OUT"),
                          (["expand", shared_bvh(), "--model", model, "-o", tmp_path / "x.usda", "--as-layer"],
                           f"{shared_bvh()}: --as-layer needs a USD input: the layer sublayers it")):
        code, out, err = run_cli(capsys, *argv)
        assert code == 2 and err == f"usdhands: error: {message}\n", argv


def shared_bvh() -> Path:
    return ROOT / "sample_assets" / "humanoid.bvh"


def test_align_euler_branches_puts_each_joint_on_the_reference_branch():
    t = np.linspace(0, 1, 50)
    e = np.stack([30 + 20 * t, 60 + 50 * t, -40 + 10 * t,   # joint 0: the middle angle passes 90
                  10 * t, 5 * t, -5 * t], axis=1)            # joint 1
    alt = e.copy()
    alt[:, 0:3] = np.stack([e[:, 0] + 180 - 360, 180 - e[:, 1], e[:, 2] + 180], axis=1)  # same rotations
    ref = e.mean(axis=0)
    back = align_euler_branches(alt, ref)
    assert np.allclose(back, e)
    assert np.allclose(align_euler_branches(e, ref), e)
    # judged only where there is a reference; without one a joint stays as it is
    only_x = np.where(np.arange(6) == 0, ref, np.nan)
    assert np.allclose(align_euler_branches(alt, only_x)[:, :3], e[:, :3])
    assert np.array_equal(align_euler_branches(alt, np.full(6, np.nan)), alt)
    with pytest.raises(ValueError, match=r"Expected reference to have shape \(6,\), got \(3,\)"):
        align_euler_branches(e, ref[:3])


def test_continuity_measured_on_chosen_angles():
    """Jumps in angles that will be rebuilt must not decide the branch when continuity is measured on the kept ones."""
    v = np.array([[10.0, 80.0, 30.0], [185.0, 82.0, 205.0]])  # x and z jump by 175 (a tracking glitch)
    # on all angles the twin of frame 1, (5, 98, 25), is nearer frame 0 (distance 28 against 352)
    assert np.allclose(continuous_euler_curves(v)[1], [5.0, 98.0, 25.0])
    # on y alone, 82 is nearer 80 than 98 is
    assert np.allclose(continuous_euler_curves(v, use=np.array([False, True, False])), v)
    with pytest.raises(ValueError, match=r"Expected use to have shape \(3,\), got \(2,\)"):
        continuous_euler_curves(v, use=np.array([True, False]))


def test_cli_every_curve_constant(sample_assets, capsys):
    code, out, err = run_cli(capsys, "reduce", sample_assets / "humanoid.usda", "--steps", "range<1000")
    assert code == 0, err
    assert out.rstrip().endswith("step 1 (range < 1000) keeps 0 of 90 curves: none")
    means = [line.split()[-1] for line in out.splitlines() if line.startswith(("LeftHand", "RightHand"))]
    assert len(means) == 90 and "-0" not in means  # a mean rounded to zero prints as 0


def test_usd_joints_sharing_short_names_are_named_by_path(sample_assets, tmp_path, capsys):
    """``.../LeftHand/Index1`` and ``.../RightHand/Index1``: curves named by the full joint paths."""
    import dataclasses
    import re

    from usdhands.formats.io import read_clip, write_asset
    from usdhands.model.asset import Asset
    from usdhands.model.rotations import quat_angle_deg

    clip = read_clip(sample_assets / "humanoid.usda")
    names = tuple(re.sub(r"(Left|Right)Hand(Thumb|Index|Middle|Ring|Pinky)(\d)$", r"\2\3", n)
                  for n in clip.skeleton.joint_names)
    sk = dataclasses.replace(clip.skeleton, joint_names=names)
    src = tmp_path / "shared_names.usda"
    write_asset(Asset(path=None, skeletons=(sk,), clips=(clip.replace(skeleton=sk),)), src)
    reduced, model = tmp_path / "reduced.usda", tmp_path / "m.json"
    code, out, err = run_cli(capsys, "reduce", src, "--json", "-o", reduced, "--model", model)
    assert code == 0, err
    report = json.loads(out)
    assert report["curves"] == 90
    m = ReductionModel.load(model)
    left_index1 = "Hips/Spine/Spine1/Spine2/LeftShoulder/LeftArm/LeftForeArm/LeftHand/Index1.x"
    assert left_index1 in m.curves and len(set(m.curves)) == 90
    assert m.metadata["paper_names"][left_index1] == "leIndexMCPx"
    again = tmp_path / "again.usda"
    code, out, err = run_cli(capsys, "expand", reduced, "--model", model, "-o", again)
    assert code == 0, err
    assert quat_angle_deg(read_clip(reduced).rotations, read_clip(again).rotations).max() < 2e-5


def test_cli_one_frame_and_bad_hands_exit_2(shared_assets, tmp_path, capsys):
    from usdhands.formats.io import read_clip, write_clip

    src = shared_assets.joinpath(*LEAP)
    one = tmp_path / "one.bvh"
    write_clip(src, read_clip(src).slice(0, 1), one)
    code, out, err = run_cli(capsys, "reduce", one)
    assert code == 2 and err == f"usdhands: error: {one}: the animation has 1 frame(s); finger curves need at least 2\n"
    code, out, err = run_cli(capsys, "reduce", src, "--hands", "right,foo")
    assert code == 2 and err == "usdhands: error: --hands: unknown value(s) ['foo']; expected some of ['left', 'right']\n"


def test_reduce_uses_the_hand_map_recorded_in_a_usd_file(sample_assets, tmp_path, capsys):
    """A UsdHandsHandMapAPI map on the Skeleton wins over detection (one finger, right hand only)."""
    from usdhands.formats.io import read_clip, write_clip
    from usdhands.model.hand_detection import detect_hands
    from usdhands.model.handmap import HandMap, HandSide

    src = sample_assets / "humanoid.usda"
    clip = read_clip(src)
    right = detect_hands(clip.skeleton).right
    only_index = HandMap(right=HandSide("right", right.wrist, right.forearm, right.shoulder, right.root,
                                        {"index": right.fingers["index"]}))
    marked = write_clip(src, clip, tmp_path / "marked.usda", hand_map=only_index)
    code, out, err = run_cli(capsys, "reduce", marked, "--json")
    assert code == 0, err
    report = json.loads(out)
    assert report["steps"][0]["dofs_left"] == 3 * len(right.fingers["index"])
    assert report["steps"][0]["dofs_left_by_hand"] == {"right": 3 * len(right.fingers["index"])}

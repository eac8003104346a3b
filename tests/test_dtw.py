"""Banded DTW with user constraints (usdhands.algorithms.dtw) against its naive twin."""

from __future__ import annotations

import numpy as np
import pytest

from usdhands.algorithms.dtw import Band, Constraint, check_constraints, dtw, dtw_naive


def _random_cases(count, seed=0):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        n, m = (int(v) for v in rng.integers(1, 45, 2))
        yield rng, n, m, rng.random((n, m)), float(rng.choice([0.02, 0.1, 0.3, np.inf]))


def test_banded_dtw_equals_naive_full_matrix_dtw_on_random_costs():
    for rng, n, m, cost, width in _random_cases(60):
        band = Band.diagonal(n, m, width)
        fast = dtw(cost, band)
        path, total = dtw_naive(cost, band.mask())
        assert fast.cost == pytest.approx(total, rel=1e-12, abs=1e-12)
        np.testing.assert_array_equal(fast.path, path)
        # the cost is the sum along the path
        assert fast.cost == pytest.approx(cost[path[:, 0], path[:, 1]].sum())


def test_banded_dtw_breaks_ties_as_the_naive_twin_on_integer_costs():
    """Small integer costs (as eq. 6's sign counts) tie everywhere: the steps the kernel
    records while accumulating must pick diagonal, then up, then left, as the backtrack
    over the whole matrix of the naive twin does."""
    rng = np.random.default_rng(11)
    for _ in range(80):
        n, m = (int(v) for v in rng.integers(1, 40, 2))
        cost = rng.integers(0, 3, (n, m)).astype(float)
        band = Band.diagonal(n, m, float(rng.choice([0.05, 0.2, np.inf])))
        fast = dtw(cost, band)
        path, total = dtw_naive(cost, band.mask())
        assert fast.cost == total
        np.testing.assert_array_equal(fast.path, path)
        counts = dtw(lambda b: cost[b.cells()].astype(np.uint8), band, shape=(n, m), on_band=True)
        assert counts.cell_costs.dtype == np.uint8  # kept as they are (splicing's first pass)
        assert counts.cost == total
        np.testing.assert_array_equal(counts.path, path)
    flat = dtw(np.zeros((30, 40)))  # every path costs 0: the diagonal first, then up
    np.testing.assert_array_equal(flat.path, dtw_naive(np.zeros((30, 40)))[0])
    assert (np.diff(flat.path, axis=0) == [1, 1]).all(axis=1).sum() == 29


def test_constrained_dtw_equals_naive_with_the_same_mask():
    for rng, n, m, cost, width in _random_cases(60, seed=1):
        if n < 8 or m < 8:
            continue
        xs = np.sort(rng.choice(np.arange(1, n - 1, 2), 2, replace=False))  # not adjacent
        ys = np.sort(rng.choice(np.arange(1, m - 1), 2, replace=False))
        cons = [Constraint(int(x), int(y), int(rng.integers(0, 3))) for x, y in zip(xs, ys)]
        band = Band.diagonal(n, m, width, cons)
        fast = dtw(cost, band)
        path, total = dtw_naive(cost, band.mask())
        assert fast.cost == pytest.approx(total, rel=1e-12)
        np.testing.assert_array_equal(fast.path, path)


def test_cost_function_is_called_on_band_cells_only_and_gives_the_same_warp():
    rng = np.random.default_rng(3)
    cost = rng.random((50, 70))
    band = Band.diagonal(50, 70, 0.1)
    seen = []

    def fn(i, j):
        seen.append(len(i))
        return cost[i, j]

    a = dtw(fn, band, shape=(50, 70))
    b = dtw(cost, band)
    assert seen == [band.num_cells] and band.num_cells < 50 * 70 // 2
    np.testing.assert_array_equal(a.path, b.path)
    m = a.cost_matrix()
    assert np.isnan(m[0, 69]) and m[10, 13] == cost[10, 13]


def test_cost_on_the_band_gives_the_same_warp_as_cost_on_cells():
    """``on_band=True`` hands the cost function the Band (its rows as runs), not a list of cells."""
    for rng, n, m, cost, width in _random_cases(40, seed=7):
        band = Band.diagonal(n, m, width)
        seen = []

        def on_band(b):
            seen.append(b)
            rows, cols = b.cells()
            return cost[rows, cols]

        a = dtw(on_band, band, shape=(n, m), on_band=True)
        b = dtw(cost, band)
        assert seen == [band]
        assert a.cost == b.cost
        np.testing.assert_array_equal(a.path, b.path)
        np.testing.assert_array_equal(a.cell_costs, b.cell_costs)
    with pytest.raises(ValueError, match=r"Expected the cost function to return shape \(\d+,\), got \(3,\)"):
        dtw(lambda b: np.zeros(3), Band.diagonal(10, 10, 0.3), shape=(10, 10), on_band=True)


def test_path_is_monotone_with_unit_steps_from_corner_to_corner():
    rng = np.random.default_rng(4)
    r = dtw(rng.random((30, 55)), Band.diagonal(30, 55, 0.2))
    steps = np.diff(r.path, axis=0)
    assert tuple(r.path[0]) == (0, 0) and tuple(r.path[-1]) == (29, 54)
    assert {tuple(s) for s in steps} <= {(1, 1), (1, 0), (0, 1)}


def test_matches_dtaidistance_on_squared_differences():
    dtai = pytest.importorskip("dtaidistance.dtw")
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=40), rng.normal(size=57)
    ours = dtw((a[:, None] - b[None, :]) ** 2).cost
    assert ours == pytest.approx(dtai.distance(a, b) ** 2, rel=1e-9)


def test_band_of_eq3_is_the_perpendicular_distance_to_the_diagonal():
    n, m, w = 80, 120, 0.1
    band = Band.diagonal(n, m, w)
    i, j = np.mgrid[0:n, 0:m]
    # distance of (i, j) to the line from (0, 0) to (n-1, m-1), in frames
    dist = np.abs(j * (n - 1) - i * (m - 1)) / np.hypot(n - 1, m - 1)
    mask = band.mask()
    assert mask[dist <= w * n - 1.0].all()
    assert not mask[dist > w * n + 1.5].any()


def test_exact_constraints_put_the_path_through_the_pairs():
    rng = np.random.default_rng(6)
    cost = rng.random((100, 90))
    cons = [Constraint(20, 60), Constraint(50, 61), Constraint(80, 85)]
    free = dtw(cost, Band.diagonal(100, 90, 0.3))
    r = dtw(cost, Band.diagonal(100, 90, 0.3, cons))
    for c in cons:
        cols = r.path[r.path[:, 0] == c.body, 1]
        assert cols.tolist() == [c.hand]
    # the unconstrained warp goes elsewhere, so the constraints did bend it
    assert any(free.path[free.path[:, 0] == c.body, 1].tolist() != [c.hand] for c in cons)
    assert r.cost > free.cost


def test_constraints_with_tolerance_keep_the_path_within_it():
    rng = np.random.default_rng(7)
    cost = rng.random((100, 90))
    cons = [Constraint(20, 60, 3), Constraint(70, 70, 5)]
    r = dtw(cost, Band.diagonal(100, 90, 0.3, cons))
    for c in cons:
        cols = r.path[r.path[:, 0] == c.body, 1]
        assert np.all(np.abs(cols - c.hand) <= c.tolerance)
    # a cheap valley at the far edge of the tolerance is used: tolerance is not exactness
    i, j = np.mgrid[0:100, 0:90]
    valley = np.where(i <= 20, i * 63 / 20, 63 + (i - 20) * 26 / 79)
    cost2 = np.abs(j - valley)
    r2 = dtw(cost2, Band.diagonal(100, 90, 0.3, [Constraint(20, 60, 3)]))
    assert r2.path[r2.path[:, 0] == 20, 1].max() >= 62


def test_band_around_a_path_contains_it_and_has_the_given_width():
    rng = np.random.default_rng(8)
    r = dtw(rng.random((60, 60)), Band.diagonal(60, 60, 0.3))
    band = Band.around_path(r.path, 60, 60, 0.05)
    assert band.mask()[r.path[:, 0], r.path[:, 1]].all()
    delta = int(np.ceil(0.05 * 60 * np.hypot(60, 60) / 60))
    row = r.path[r.path[:, 0] == 30, 1]
    assert band.lo[30] == max(row.min() - delta, 0) and band.hi[30] == min(row.max() + delta, 59)


@pytest.mark.parametrize("cons, message", [
    ([Constraint(100, 5)], r"constraint 100:5: body frame 100 is out of range 0..99"),
    ([Constraint(5, 90)], r"constraint 5:90: hand frame 90 is out of range 0..89"),
    ([Constraint(10, 40), Constraint(20, 30)],
     r"constraints out of order: 20:30 after 10:40 \(body and hand frames must both increase\)"),
    ([Constraint(10, 40), Constraint(10, 50)], r"constraints out of order: 10:50 after 10:40"),
    ([Constraint(0, 5, 2)], r"constraint 0:5:2 contradicts the start of the path 0:0"),
    ([Constraint(99, 80)], r"constraint 99:80 contradicts the end of the path 99:89"),
    ([Constraint(5, 5, -1)], r"tolerance must be >= 0, got -1"),
    ([Constraint(20, 10, 2), Constraint(21, 38, 1)],
     r"constraints 20:10:2 and 21:38:1 cannot both hold: hand frames 13..36 would match no body frame"),
])
def test_bad_constraints_are_rejected_with_exact_messages(cons, message):
    with pytest.raises(ValueError, match=message):
        check_constraints(cons, 100, 90)


def test_constraints_on_the_ends_are_accepted_when_consistent():
    band = Band.diagonal(100, 90, 0.1, [Constraint(0, 0), Constraint(99, 88, 1)])
    assert band.lo[0] == 0 and band.hi[-1] == 89


def test_bad_shapes_are_rejected():
    with pytest.raises(ValueError, match=r"Expected cost to have shape \(n, m\), got \(5,\)"):
        dtw(np.zeros(5))
    with pytest.raises(ValueError, match=r"Expected shape=\(n, m\) with a cost function"):
        dtw(lambda i, j: i * 0.0)
    with pytest.raises(ValueError, match=r"Expected the cost function to return shape"):
        dtw(lambda i, j: np.zeros(3), shape=(4, 4))
    with pytest.raises(ValueError, match=r"Expected a band of shape \(4, 4\), got \(4, 5\)"):
        dtw(np.zeros((4, 4)), Band.full(4, 5))
    with pytest.raises(ValueError, match="the band has a gap between rows 1 and 2"):
        Band(np.array([0, 0, 5, 5]), np.array([1, 2, 9, 9]), 10).check_connected()

"""The NumPy twins of the synthesis kernels hold to the kernels to the bit, and a small synthesize loads neither numba nor scipy.

The twins (``usdhands.algorithms.synthesis._dtw_numpy``) serve searches too small to pay
for loading numba; they must give the kernel's neighbours, costs and statistics exactly,
so the output of a synthesis does not depend on which one ran.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from usdhands.algorithms.synthesis import _dtw_kernel as kern
from usdhands.algorithms.synthesis import _dtw_numpy as twin
from usdhands.algorithms.synthesis import segment_cost
from usdhands.algorithms.synthesis.output_warp import moving_average_nearest


def _segments(rng, total, lo, hi):
    """Consecutive ``[start, stop)`` ranges of random lengths in ``lo..hi - 1`` covering most of ``total`` frames."""
    out, s = [], 0
    while True:
        n = int(rng.integers(lo, hi))
        if s + n > total:
            return np.array(out, dtype=np.int64).reshape(-1, 2)
        out.append((s, s + n))
        s += n


def _both(qf, qb, qg, df, ds, dg, k, lf, band, bound):
    outs = []
    for search in (kern.search, twin.search):
        Q = len(qb)
        idx, cost, stats = np.full((Q, k), -1, np.int64), np.full((Q, k), np.inf), np.zeros((Q, 4), np.int64)
        search(qf, qb, qg, df, ds, dg, k, lf, band, bound, idx, cost, stats)
        outs.append((idx, cost, stats))
    return outs


@pytest.mark.parametrize("seed", range(8))
def test_numpy_search_equals_kernel_to_the_bit(seed):
    """Neighbours, costs (array_equal, not approx) and the kernel's counts of pruned/aligned/abandoned pairs."""
    rng = np.random.default_rng(seed)
    D = int(rng.choice([3, 6, 12]))
    qf = np.cumsum(rng.normal(size=(400, D)), axis=0)
    df = np.cumsum(rng.normal(size=(3000, D)), axis=0)
    qb, ds = _segments(rng, 400, 1, 60), _segments(rng, 3000, 1, 70)
    if seed % 2:  # repeated database segments: ties in cost go to the lower index
        ds = np.concatenate([ds, ds[::3]])
    qg = rng.integers(-1, 3, len(qb))
    dg = rng.integers(0, 3, len(ds))
    k = int(rng.integers(1, 8))
    for lf, band in ((1.5, 0.3), (1.5, 0.1), (2.0, 1.0), (1e6, 1.0)):
        for bound in (0, 1):
            (i1, c1, s1), (i2, c2, s2) = _both(qf, qb, qg, df, ds, dg, k, lf, band, bound)
            assert np.array_equal(i1, i2) and np.array_equal(c1, c2), (lf, band, bound)
            assert np.array_equal(s1, s2), (lf, band, bound)
            assert (i1 >= 0).any()


def test_numpy_search_refuses_keogh():
    z = np.zeros((4, 3))
    with pytest.raises(ValueError, match="bounds 0 and 1"):
        twin.search(z, np.array([[0, 4]]), np.array([-1]), z, np.array([[0, 4]]), np.array([-2]), 1, 1.5, 0.3, 2,
                    np.zeros((1, 1), np.int64), np.zeros((1, 1)), np.zeros((1, 4), np.int64))


def test_align_paths_equal_the_kernel_to_the_bit():
    rng = np.random.default_rng(5)
    qf, df = rng.normal(size=(600, 6)) * 20, rng.normal(size=(900, 6)) * 20
    pairs, bands = [], []
    for _ in range(300):
        n, m = int(rng.integers(1, 40)), int(rng.integers(1, 60))  # m > 2n - 1: no warp fits
        q0, d0 = int(rng.integers(0, 600 - n)), int(rng.integers(0, 900 - m))
        pairs.append((q0, q0 + n, d0, d0 + m))
        bands.append(float(rng.choice([0.1, 0.3, 1.0])))
    totals, paths = twin.align_paths(qf, df, np.array(pairs), np.array(bands))
    fits = 0
    for (q0, q1, d0, d1), band, total, path in zip(pairs, bands, totals, paths):
        want = np.zeros(q1 - q0, np.int64)
        ref = kern.align_path(np.ascontiguousarray(qf[q0:q1]), np.ascontiguousarray(df[d0:d1]), band, want)
        assert total == ref
        if np.isfinite(ref):
            fits += 1
            assert np.array_equal(path, want)
        else:
            assert len(path) == 0
    assert 100 < fits < 300
    many = segment_cost.dtw_align_many(qf, df, np.array(pairs[:20]), np.array(bands[:20]))
    for (q0, q1, d0, d1), band, (cost, path) in zip(pairs, bands, many):
        ref_cost, ref_path = segment_cost.dtw_align_fast(qf[q0:q1], df[d0:d1], band)
        assert cost == ref_cost and np.array_equal(path, ref_path)


def test_moving_average_equals_scipy_uniform_filter_to_the_bit():
    from scipy.ndimage import uniform_filter1d

    rng = np.random.default_rng(2)
    for t in range(3000):
        n = int(rng.integers(1, 120))
        size = int(rng.integers(1, n + 1))
        x = np.maximum.accumulate(rng.integers(0, 3, n)).astype(float) if t % 2 else rng.normal(size=n) * 50
        assert np.array_equal(moving_average_nearest(x, size), uniform_filter1d(x, size=size, mode="nearest"))


def test_search_choice_follows_the_work(monkeypatch):
    """Without the kernels compiled ahead of time (an install with no C compiler): NumPy for small
    searches, numba's beyond (the choice with them: tests/test_compiled_kernels.py)."""
    import usdhands.compiled

    qb = np.array([[0, 30], [30, 60]])
    ds = np.array([[0, 30], [30, 55], [55, 90]])
    monkeypatch.setattr(usdhands.compiled, "ENABLED", False)
    monkeypatch.setattr(segment_cost, "_kernel_loaded", lambda: False)
    monkeypatch.setattr(segment_cost, "_numpy_cells_searched", [0.0])
    assert segment_cost._search_kernel(qb, ds, 1.5, 0.3, "kim") is twin.search
    # a process that has searched a lot in NumPy loads the kernel
    monkeypatch.setattr(segment_cost, "_numpy_cells_searched", [segment_cost.NUMPY_SEARCH_PROCESS_CELLS])
    assert segment_cost._search_kernel(qb, ds, 1.5, 0.3, "kim") is kern.search
    monkeypatch.setattr(segment_cost, "_numpy_cells_searched", [0.0])
    assert segment_cost._search_kernel(qb, ds, 1.5, 0.3, "keogh") is kern.search
    monkeypatch.setattr(segment_cost, "NUMPY_SEARCH_MAX_CELLS", 100)
    assert segment_cost._search_kernel(qb, ds, 1.5, 0.3, "kim") is kern.search
    # the estimate is the band cells of the pairs within the length factor
    cells = sum(n * min(m, 2 * max(0.3 * m, 1) + 1) for n in (30, 30) for m in (30, 25, 35))
    assert twin.estimated_cells([30, 30], [30, 25, 35], 1.5, 0.3) == pytest.approx(cells)
    assert twin.estimated_cells([30], [10, 60], 1.5, 0.3) == 0


def test_synthesize_with_either_search_writes_the_same_file(sample_assets, tmp_path, monkeypatch):
    """NumPy's search and numba's (the kernels compiled ahead of time: tests/test_compiled_kernels.py)."""
    import usdhands
    import usdhands.compiled

    src = sample_assets / "conversation_bodyonly.bvh"
    monkeypatch.setattr(usdhands.compiled, "ENABLED", False)
    monkeypatch.setattr(segment_cost, "_kernel_loaded", lambda: False)
    monkeypatch.setattr(segment_cost, "_numpy_cells_searched", [0.0])
    usdhands.synthesize(src, tmp_path / "numpy.bvh")
    monkeypatch.setattr(segment_cost, "NUMPY_SEARCH_MAX_CELLS", -1)
    usdhands.synthesize(src, tmp_path / "kernel.bvh")
    assert (tmp_path / "numpy.bvh").read_bytes() == (tmp_path / "kernel.bvh").read_bytes()


@pytest.mark.parametrize("compiled", ["1", "0"])
def test_a_small_synthesize_imports_neither_numba_nor_scipy(sample_assets, tmp_path, compiled):
    """With the kernels compiled ahead of time, and without them (NumPy)."""
    env = dict(os.environ, USDHANDS_COMPILED_KERNELS=compiled)
    code = ("import sys, json, usdhands\n"
            f"usdhands.synthesize({str(sample_assets / 'conversation_bodyonly.bvh')!r}, {str(tmp_path / 'o.bvh')!r})\n"
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules} & {'numba', 'scipy', 'pxr', 'pygltflib'})))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.splitlines()[-1]) == []

"""The kernels compiled ahead of time (Cython, at install) against their numba twins, to the bit, and
when the package runs them: the search, one pair's warp, playing, stitching and step-limiting the
chosen fragments, and reading BVH motion; a process that runs them imports no numba."""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys

import numpy as np
import pytest

import usdhands.compiled
from usdhands.algorithms.synthesis import _dtw_kernel, _dtw_numpy, _play_kernel, segment_cost
from usdhands.compiled import KERNEL_MODULES, kernel_module
from usdhands.formats import _bvh_kernel

from test_dtw_numpy_twin import _segments  # noqa: E402  (consecutive random segments)

BUILT = {name: kernel_module(name) for name in KERNEL_MODULES}
search_compiled = BUILT["algorithms.synthesis._search_compiled"]
play_compiled = BUILT["algorithms.synthesis._play_compiled"]
bvh_compiled = BUILT["formats._bvh_compiled"]
needs_built = pytest.mark.skipif(any(m is None for m in BUILT.values()),
                                 reason="the kernels compiled ahead of time were not built (no C compiler at install)")


def test_built_where_ci_requires_them():
    """CI installs with a C compiler: there the build must not have failed quietly (it is optional)."""
    if os.environ.get("USDHANDS_REQUIRE_COMPILED") != "1":
        pytest.skip("USDHANDS_REQUIRE_COMPILED is not set")
    assert {name: module is not None for name, module in BUILT.items()} == dict.fromkeys(KERNEL_MODULES, True)


def test_kernel_module_names_only_the_compiled_modules(monkeypatch):
    with pytest.raises(ValueError, match="unknown compiled kernel module 'formats.bvh'"):
        kernel_module("formats.bvh")
    monkeypatch.setattr(usdhands.compiled, "ENABLED", False)
    assert kernel_module("formats._bvh_compiled") is None


def test_kernel_file_built_tells_a_built_module_by_its_file_without_importing_it(monkeypatch, tmp_path):
    from usdhands.compiled import kernel_file_built

    assert {name: kernel_file_built(name) for name in KERNEL_MODULES} == {
        name: module is not None for name, module in BUILT.items()}
    code = ("import json, sys\nfrom usdhands.compiled import KERNEL_MODULES, kernel_file_built\n"
            "[kernel_file_built(name) for name in KERNEL_MODULES]\n"
            "print(json.dumps(sorted(m for m in sys.modules if m.startswith(('numpy', 'usdhands.algorithms', "
            "'usdhands.formats')))))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert json.loads(done.stdout) == [], done.stderr[-2000:]
    with pytest.raises(ValueError, match="unknown compiled kernel module 'formats.bvh'"):
        kernel_file_built("formats.bvh")
    monkeypatch.setattr(usdhands.compiled, "ENABLED", False)
    assert not kernel_file_built("formats._bvh_compiled")
    # a package without the extension files: not built
    monkeypatch.setattr(usdhands.compiled, "ENABLED", True)
    monkeypatch.setattr(usdhands.compiled, "__file__", str(tmp_path / "compiled.py"))
    assert not any(kernel_file_built(name) for name in KERNEL_MODULES)


def _search(search, qf, qb, qg, df, ds, dg, k, lf, band, bound):
    Q = len(qb)
    idx, cost, stats = np.full((Q, k), -1, np.int64), np.full((Q, k), np.inf), np.zeros((Q, 4), np.int64)
    search(qf, qb, qg, df, ds, dg, k, lf, band, bound, idx, cost, stats)
    return idx, cost, stats


@needs_built
@pytest.mark.parametrize("seed", range(6))
def test_search_equals_numbas_to_the_bit(seed):
    """Neighbours, costs and the counts of pruned/aligned/abandoned pairs, every bound (LB_Keogh too),
    12-D features (numba's unrolled alignment) and others, repeated segments (ties), groups, one-frame
    segments, tied segment means (the visiting order's stable sort)."""
    rng = np.random.default_rng(seed)
    D = int(rng.choice([1, 3, 12])) if seed else 12
    qf = np.cumsum(rng.normal(size=(300, D)), axis=0)
    df = np.cumsum(rng.normal(size=(2500, D)), axis=0)
    qb, ds = _segments(rng, 300, 1, 50), _segments(rng, 2500, 1, 60)
    if seed % 2:
        ds = np.concatenate([ds, ds[::3], ds[::5]])
    if seed == 4:  # every frame alike: every mean ties, every cost ties
        qf[:] = 1.0
        df[:] = 1.0
    if seed == 5:  # each segment and its reverse: the same mean (tied guesses), other costs
        half = df[:1250]
        df = np.concatenate([half, half[::-1]])
        ds = _segments(rng, 1250, 1, 60)
        ds = np.concatenate([ds, 2500 - ds[:, ::-1]])[rng.permutation(2 * len(ds))]
    qg = rng.integers(-1, 3, len(qb))
    dg = rng.integers(0, 3, len(ds))
    k = int(rng.integers(1, 8))
    found = 0
    for lf, band in ((1.5, 0.3), (2.0, 1.0), (1e6, 0.05)):
        for bound in (0, 1, 2):
            ours = _search(search_compiled.search, qf, qb, qg, df, ds, dg, k, lf, band, bound)
            numba = _search(_dtw_kernel.search, qf, qb, qg, df, ds, dg, k, lf, band, bound)
            for a, b in zip(ours, numba):
                assert a.tobytes() == b.tobytes(), (lf, band, bound)
            found += int((ours[0] >= 0).sum())
    assert found > 0


@needs_built
def test_align_path_equals_numbas_to_the_bit():
    rng = np.random.default_rng(5)
    qf, df = rng.normal(size=(600, 6)) * 20, rng.normal(size=(900, 6)) * 20
    fits = 0
    for _ in range(300):
        n, m = int(rng.integers(1, 40)), int(rng.integers(1, 60))  # m > 2n - 1: no warp fits
        q0, d0 = int(rng.integers(0, 600 - n)), int(rng.integers(0, 900 - m))
        band = float(rng.choice([0.1, 0.3, 1.0]))
        q, d = np.ascontiguousarray(qf[q0:q0 + n]), np.ascontiguousarray(df[d0:d0 + m])
        ours, theirs = np.zeros(n, np.int64), np.zeros(n, np.int64)
        total = search_compiled.align_path(q, d, band, ours)
        assert np.float64(total).tobytes() == np.float64(_dtw_kernel.align_path(q, d, band, theirs)).tobytes()
        if np.isfinite(total):
            fits += 1
            assert np.array_equal(ours, theirs)
    assert 100 < fits < 300


def _play_inputs(rng, fingers_dtype):
    D, M = 6, 9
    qf, df = np.cumsum(rng.normal(size=(400, D)), axis=0), np.cumsum(rng.normal(size=(1500, D)), axis=0)
    fingers = (rng.normal(size=(1500, M)) * 30).astype(fingers_dtype)
    qb, sr = _segments(rng, 400, 1, 40), _segments(rng, 1500, 1, 50)
    k = 4
    cand = rng.integers(-1, len(sr), (len(qb), k))
    weights = np.where(rng.random((len(qb), k)) < 0.25, 0.0, rng.random((len(qb), k)))
    bands = rng.choice([0.1, 0.3, 1.0], (len(qb), k))
    return qf, df, fingers, sr, qb, cand, weights, bands


@needs_built
@pytest.mark.parametrize("fingers_dtype", [np.float64, np.float32])
@pytest.mark.parametrize("width", [0, 1, 2, 7, 45])
def test_play_equals_numbas_to_the_bit(fingers_dtype, width):
    """Pairs a warp fits and pairs none fits (stretched), skipped candidates, warp smoothing widths
    from none to wider than the segments, float32 database fingers (the bundled database's)."""
    qf, df, fingers, sr, qb, cand, weights, bands = _play_inputs(np.random.default_rng(width), fingers_dtype)
    outs = []
    for kern in (play_compiled, _play_kernel):
        out = np.zeros((len(qf), fingers.shape[1]))
        kern.play(qf, df, fingers, sr, qb, cand, weights, bands, width, 0.25, out)
        outs.append(out)
    assert outs[0].tobytes() == outs[1].tobytes()
    assert np.abs(outs[0]).max() > 1


@needs_built
def test_limit_and_stitch_equal_numbas_to_the_bit():
    rng = np.random.default_rng(9)
    for trial in range(30):
        T, C = int(rng.integers(1, 300)), int(rng.integers(1, 12))
        x = np.cumsum(rng.normal(size=(T, C)) * rng.choice([0.5, 5.0, 50.0]), axis=0)
        lim = rng.uniform(0.1, 8.0, C)
        a, b = np.empty_like(x), np.empty_like(x)
        play_compiled.limit(x, lim, a)
        _play_kernel.limit(x, lim, b)
        assert a.tobytes() == b.tobytes()
        if T < 3:
            continue
        cuts = np.unique(rng.integers(1, T, int(rng.integers(0, 8))))
        bounds = np.concatenate([[0], cuts, [T]]).astype(np.int64)
        mask = rng.random(C) < 0.7
        blend_n = int(rng.integers(1, 20))
        results = []
        for kern in (play_compiled, _play_kernel):
            S = len(bounds) - 2
            out, means, maxes, blended = np.empty_like(x), np.zeros(S), np.zeros(S), np.zeros(S, dtype=bool)
            kern.stitch(x, bounds, mask, 5.0, 20.0, blend_n, out, means, maxes, blended)
            results.append((out, means, maxes, blended))
        for ours, theirs in zip(*results):
            assert ours.tobytes() == theirs.tobytes(), trial


def _random_number(rng: random.Random) -> str:
    sign = rng.choice(["", "-", "+"])
    whole = "".join(rng.choice("0123456789") for _ in range(rng.randint(0, 12)))
    frac = "".join(rng.choice("0123456789") for _ in range(rng.randint(0, 12)))
    text = whole + ("." + frac if frac or rng.random() < 0.2 else "")
    if not whole and not frac:
        text = "0"
    if rng.random() < 0.2:
        text += rng.choice("eE") + rng.choice(["", "-", "+"]) + str(rng.randint(0, 40))
    return sign + text


@needs_built
def test_parse_rows_equals_numbas_on_random_text():
    """Numbers of every form (long mantissas, exponents, signs), whitespace, CRLF, and broken rows: the same
    rows to the bit, or handed back (-1) alike."""
    rng = random.Random(3)
    for trial in range(400):
        C = rng.randint(1, 6)
        rows = [" ".join(_random_number(rng) for _ in range(C)) for _ in range(rng.randint(0, 20))]
        text = rng.choice(["\n", "\r\n"]).join(rows) + rng.choice(["", "\n"])
        if trial % 5 == 0 and text:  # a broken byte somewhere
            i = rng.randrange(len(text))
            text = text[:i] + rng.choice(["x", "\r", "1 2", ",", "\t"]) + text[i + 1:]
        buf = np.frombuffer(text.encode(), np.uint8)
        got = []
        for kern in (bvh_compiled, _bvh_kernel):
            out = np.full((25, C), np.nan)
            got.append((kern.parse_rows(buf, 0, C, out, kern.POW10), out.tobytes()))
        assert got[0] == got[1], text


@needs_built
def test_clip_arrays_equal_numbas_to_the_bit():
    rng = np.random.default_rng(4)
    special = np.array([0.0, 90.0, -90.0, 180.0, 360.0, 720.5, 1e-300, -1e-7, -0.0])
    for trial in range(30):
        J = int(rng.integers(1, 9))
        count = rng.integers(0, 5, J)
        first = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
        axes = rng.integers(0, 3, int(count.sum())).astype(np.int64)
        P = int(rng.integers(0, 5))
        C = int(count.sum()) + P + 1
        cols = rng.permutation(C)[:len(axes)].astype(np.int64)
        pjoint, paxis, pcol = (rng.integers(0, J, P), rng.integers(0, 3, P), rng.integers(0, C, P))
        T = int(rng.integers(1, 200))
        values = np.where(rng.random((T, C)) < 0.3, rng.choice(special, (T, C)), rng.uniform(-400, 400, (T, C)))
        offsets = rng.normal(size=(J, 3))
        results = []
        for kern in (bvh_compiled, _bvh_kernel):
            rot, trans = np.empty((T, J, 4)), np.empty((T, J, 3))
            kern.clip_arrays(values, offsets, first, count.astype(np.int64), axes, cols, pjoint.astype(np.int64),
                             paxis.astype(np.int64), pcol.astype(np.int64), kern.PERM, kern.SIGN, rot, trans)
            results.append((rot.tobytes(), trans.tobytes()))
        assert results[0] == results[1], trial


@needs_built
def test_search_choice_with_the_kernels_compiled_ahead_of_time(monkeypatch):
    """Theirs up to COMPILED_SEARCH_MAX_CELLS (LB_Keogh too), numba's beyond it or once numba's is loaded;
    the play kernels follow the search (numba's once numba is loaded, else these)."""
    from usdhands.algorithms.synthesis.output_warp import play_kernels

    qb = np.array([[0, 30], [30, 60]])
    ds = np.array([[0, 30], [30, 55], [55, 90]])
    monkeypatch.setattr(segment_cost, "_kernel_loaded", lambda: False)
    for bound in ("kim", "keogh", "none"):
        assert segment_cost._search_kernel(qb, ds, 1.5, 0.3, bound) is search_compiled.search
    cells = _dtw_numpy.estimated_cells(qb[:, 1] - qb[:, 0], ds[:, 1] - ds[:, 0], 1.5, 0.3)
    monkeypatch.setattr(segment_cost, "COMPILED_SEARCH_MAX_CELLS", cells - 1)
    assert segment_cost._search_kernel(qb, ds, 1.5, 0.3, "kim") is _dtw_kernel.search
    monkeypatch.setattr(segment_cost, "COMPILED_SEARCH_MAX_CELLS", cells)
    assert segment_cost._search_kernel(qb, ds, 1.5, 0.3, "kim") is search_compiled.search
    monkeypatch.setattr(segment_cost, "_kernel_loaded", lambda: True)
    assert segment_cost._search_kernel(qb, ds, 1.5, 0.3, "kim") is _dtw_kernel.search
    monkeypatch.setitem(sys.modules, "usdhands.algorithms.synthesis._dtw_kernel", None)
    assert play_kernels() is play_compiled


def _fresh(code: str, **environ) -> list:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, **environ))
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.splitlines()[-1])


@needs_built
@pytest.mark.parametrize("source", ["conversation_bodyonly.bvh", "conversation_bodyonly.glb",
                                    "conversation_bodyonly.usdc"])
def test_synthesize_with_them_writes_numbas_bytes_without_numba(sample_assets, tmp_path, source):
    """One synthesize of each format in a fresh process: with the kernels compiled ahead of time it imports
    no numba, and writes the same bytes as with numba's kernels (the search forced into numba) and as
    without either (NumPy)."""
    src = sample_assets / source
    code = ("import json, sys, usdhands\n"
            "from usdhands.algorithms.synthesis import segment_cost\n"
            "if {force_numba}:\n"
            "    segment_cost.NUMPY_SEARCH_MAX_CELLS = -1\n"
            f"usdhands.synthesize({str(src)!r}, {str(tmp_path)!r} + '/{{name}}{src.suffix}')\n"
            "print(json.dumps(['numba' in sys.modules]))")
    assert _fresh(code.format(force_numba=False, name="compiled")) == [False]
    assert _fresh(code.format(force_numba=True, name="numba"), USDHANDS_COMPILED_KERNELS="0") == [True]
    assert _fresh(code.format(force_numba=False, name="numpy"), USDHANDS_COMPILED_KERNELS="0") == [False]
    written = {name: (tmp_path / f"{name}{src.suffix}").read_bytes() for name in ("compiled", "numba", "numpy")}
    assert written["compiled"] == written["numba"] == written["numpy"]


def test_kernel_threads_asked_before_numba_is_imported_are_set_when_it_is():
    """A batch worker asks for one kernel thread at its start without importing numba (it may never need
    it); the package's first import of numba in that thread sets it."""
    code = ("import json, sys\n"
            "from usdhands import jit\n"
            "jit.set_kernel_threads(1)\n"
            "before = 'numba' in sys.modules\n"
            "from usdhands.algorithms.synthesis import _dtw_kernel\n"
            "import numba\n"
            "print(json.dumps([before, numba.get_num_threads(), numba.config.NUMBA_NUM_THREADS > 1]))")
    before, threads, several = _fresh(code)
    assert before is False and threads == 1
    assert several or threads == 1

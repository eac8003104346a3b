"""Benchmark: finger DOF reduction on both hands, 50 curves each, 100,000 frames.

Prints the time of ``reduce_curves`` (the paper's four steps: statistics, the rmsd1 and
rmsd2 matrices from one correlation product per hand, chain resolution, models and
reconstruction errors) and of the pair matrices alone, against two baselines measured in
the same run on the same data:

- a pair-by-pair loop calling numpy on each pair of standardised curves (all
  2 x 50*49/2 = 2450 pairs, full length);
- a plain Python loop over pairs and frames (the paper's equations written out). It runs
  on a random subsample of the pairs at full length and is scaled by
  ``pairs / sampled pairs`` (its cost per pair does not depend on which pair it is).

Run: ``python benchmarks/bench_reduce.py [--frames N] [--curves N] [--sample-pairs N]``.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

# One BLAS thread unless told otherwise (--blas-threads): on a shared 2-core machine a
# multi-threaded matrix product competing with other processes swings from 0.03 s to 2 s;
# one thread is the steady, conservative figure. Must be set before numpy is imported.
_threads = next((a.split("=", 1)[1] for a in sys.argv if a.startswith("--blas-threads=")), "1")
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, _threads)

import numpy as np  # noqa: E402

from usdhands.algorithms.reduction.reduce import DEFAULT_STEPS, pair_rmsd, reduce_curves, standardise  # noqa: E402


def make_hands(frames: int, curves: int, seed: int = 0):
    """Two hands of ``curves`` curves each: a few latent motions mixed with noise, some still curves."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / 30.0
    cols, names, groups = [], [], []
    for side in ("left", "right"):
        latent = [np.sin(f * t + p) for f, p in zip(rng.uniform(0.2, 2.0, 6), rng.uniform(0, 6, 6))]
        for k in range(curves):
            kind = k % 5
            if kind == 0:
                c = rng.normal(0, 0.1, frames) + rng.uniform(-10, 10)  # near-constant
            else:
                w = rng.normal(size=6) * (rng.random(6) < 0.4)
                w[k % 6] += rng.choice([-1, 1]) * 3
                c = sum(wi * li for wi, li in zip(w, latent)) * rng.uniform(1, 15) + rng.normal(0, 0.5, frames)
            cols.append(c)
            names.append(f"{side}{k // 3}.{'xyz'[k % 3]}")
            groups.append(side)
    return np.stack(cols, axis=1), names, groups


def numpy_pair_loop(values: np.ndarray, groups) -> tuple[np.ndarray, np.ndarray]:
    """Pair by pair with numpy on each pair (within a hand)."""
    z, valid = standardise(values)
    D = values.shape[1]
    r1 = np.full((D, D), np.nan)
    r2 = np.full((D, D), np.nan)
    for i in range(D):
        for j in range(i + 1, D):
            if groups[i] != groups[j] or not (valid[i] and valid[j]):
                continue
            r1[i, j] = r1[j, i] = np.sqrt(np.mean((z[:, i] - z[:, j]) ** 2))
            r2[i, j] = r2[j, i] = np.sqrt(np.mean((z[:, i] + z[:, j]) ** 2))
    return r1, r2


def python_pair(a: list, b: list) -> tuple[float, float]:
    """The paper's rmsd1 and rmsd2 of two standardised curves, frame by frame."""
    n = len(a)
    s1 = s2 = 0.0
    for x, y in zip(a, b):
        s1 += (x - y) ** 2
        s2 += (x + y) ** 2
    return math.sqrt(s1 / n), math.sqrt(s2 / n)


def best_of(fn, repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100_000)
    ap.add_argument("--curves", type=int, default=50, help="curves per hand")
    ap.add_argument("--sample-pairs", type=int, default=12, help="pairs for the pure-Python loop")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--blas-threads", default="1", help="BLAS threads (give as --blas-threads=N; default 1)")
    args = ap.parse_args()

    values, names, groups = make_hands(args.frames, args.curves)
    T, D = values.shape
    pairs = 2 * (args.curves * (args.curves - 1) // 2)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"machine: {os.cpu_count()} CPUs, load average {load:.1f} at start, BLAS threads "
          f"{os.environ.get('OPENBLAS_NUM_THREADS')} (ratios are the figure to compare)")
    print(f"data: 2 hands x {args.curves} curves, {T} frames ({values.nbytes / 1e6:.0f} MB float64), "
          f"{pairs} pairs within hands")

    t_reduce, res = best_of(lambda: reduce_curves(values, names, DEFAULT_STEPS, groups=groups), args.repeat)
    t_pairs, (r1, r2) = best_of(lambda: pair_rmsd(values, groups), args.repeat)
    t_loop, (l1, l2) = best_of(lambda: numpy_pair_loop(values, groups), 1)
    if not (np.allclose(r1, l1, atol=1e-9, equal_nan=True) and np.allclose(r2, l2, atol=1e-9, equal_nan=True)):
        raise SystemExit("vectorised and looped pair matrices differ")

    rng = np.random.default_rng(1)
    z, _ = standardise(values)
    within = [(i, j) for i in range(D) for j in range(i + 1, D) if groups[i] == groups[j]]
    sample = [within[k] for k in rng.choice(len(within), size=min(args.sample_pairs, len(within)), replace=False)]
    cols = {k: z[:, k].tolist() for pair in sample for k in pair}
    t0 = time.perf_counter()
    for i, j in sample:
        p1, p2 = python_pair(cols[i], cols[j])
        if abs(p1 - r1[i, j]) > 1e-9 or abs(p2 - r2[i, j]) > 1e-9:
            raise SystemExit(f"pure-Python pair {i},{j} differs")
    t_py_sample = time.perf_counter() - t0
    t_py = t_py_sample * pairs / len(sample)

    print()
    print(f"{'what':<58} {'seconds':>9}")
    print(f"{'reduce_curves, 4 paper steps (best of ' + str(args.repeat) + ')':<58} {t_reduce:9.3f}")
    print(f"{'  of which pair_rmsd (both matrices, both hands)':<58} {t_pairs:9.3f}")
    print(f"{'numpy pair-by-pair loop (all pairs)':<58} {t_loop:9.3f}")
    print(f"{f'pure-Python loop ({len(sample)} pairs measured, scaled x{pairs / len(sample):.1f})':<58} "
          f"{t_py:9.1f}")
    print()
    print(f"pair matrices: vectorised is {t_loop / t_pairs:.0f}x faster than the numpy pair loop, "
          f"{t_py / t_pairs:.0f}x faster than the pure-Python loop")
    print(f"whole reduction vs pair loops alone: {t_loop / t_reduce:.1f}x (numpy loop), "
          f"{t_py / t_reduce:.0f}x (pure Python)")
    print(f"whole reduction under 1 s: {'yes' if t_reduce < 1.0 else 'NO'} ({t_reduce:.3f} s)")
    print("DOFs left per step:", ", ".join(f"{s.condition}: {s.dofs_left}" for s in res.steps))


if __name__ == "__main__":
    main()

"""Benchmark: finger synthesis of a 3-minute input against a 10-minute database, both hands.

Prints the end-to-end time of :func:`usdhands.algorithms.synthesis.synthesize.synthesize_clip`
(features, segmentation, the k-nearest search, graph, stitching, applying the curves;
numba compiled beforehand), the time of the search alone, and beside it, measured in
the same run on a random sample of the same candidate pairs and scaled to all of
them, the time a plain per-pair NumPy DTW (:func:`segment_cost.dtw_align`) and
``dtaidistance`` per pair (``dtw_ndim.distance`` with the same band, C library)
would take for the search. Also the share of candidate pairs the lower bound pruned.

It also times ``usdhands synthesize`` file to file (USD, glTF, BVH input of the
same 3 minutes, the database saved and loaded memory-mapped), in-process and as a
fresh command.

Run: ``python benchmarks/bench_synthesis.py [--input-min 3] [--db-min 10] [--pairs 1500]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def concat_clips(clips, name):
    from usdhands.model import Clip

    c0 = clips[0]
    return Clip(c0.skeleton, c0.fps, np.concatenate([c.rotations for c in clips]),
                np.concatenate([c.translations for c in clips]), np.concatenate([c.scales for c in clips]), name=name)


def make_clips(minutes: float, first_seed: int):
    from usdhands.samples.gestures import conversation_clip

    clips, total, seed = [], 0.0, first_seed
    while total < minutes * 60:
        c = conversation_clip(seed=seed)
        clips.append(c)
        total += c.duration
        seed += 1
    return clips


def file_to_file(inp, db, repeat: int) -> dict:
    """Seconds of ``usdhands synthesize`` on files: ``{format: (in-process best, fresh process best, bytes)}``."""
    import contextlib
    import io
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    from usdhands.algorithms.synthesis.database import save_database
    from usdhands.cli import main as cli
    from usdhands.formats.io import write_asset
    from usdhands.model.asset import Asset

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        db_path = save_database(db, tmp / "db")
        for ext in (".usdc", ".glb", ".bvh"):
            src = tmp / f"input{ext}"
            write_asset(Asset("memory", [inp.skeleton], [inp], []), src)
            argv = ["synthesize", str(src), "-o", str(tmp / f"out{ext}"), "--db", str(db_path), "--json"]
            inproc, fresh = [], []
            for _ in range(repeat):
                t = time.perf_counter()
                subprocess.run([sys.executable, "-m", "usdhands", *argv], check=True, capture_output=True)
                fresh.append(time.perf_counter() - t)
                t = time.perf_counter()
                with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                    status = cli(argv)
                inproc.append(time.perf_counter() - t)
                if status != 0:
                    raise RuntimeError(f"usdhands {' '.join(argv)} failed")
            out[ext[1:]] = (min(inproc), min(fresh), src.stat().st_size)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--input-min", type=float, default=3.0)
    ap.add_argument("--db-min", type=float, default=10.0)
    ap.add_argument("--pairs", type=int, default=1500, help="candidate pairs timed for the per-pair baselines")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    from dtaidistance import dtw_ndim

    from usdhands.algorithms.synthesis.database import DatabaseClip, build_database, segment_track
    from usdhands.algorithms.synthesis.segment_cost import dtw_align, knn_segments, weight_features
    from usdhands.algorithms.synthesis.synthesize import db_side_segments, segment_weights, synthesize_clip
    from usdhands.algorithms.synthesis.config import SynthesisConfig
    from usdhands.algorithms.synthesis.wrist_features import wrist_features
    from usdhands.model.hand_detection import detect_hands
    from usdhands.samples.gestures import body_only

    t0 = time.perf_counter()
    db_clips = make_clips(args.db_min, 100)
    hm = detect_hands(db_clips[0].skeleton)
    db = build_database([DatabaseClip(c, hm, None, f"conversation seed {100 + i}") for i, c in enumerate(db_clips)])
    inp = body_only(concat_clips(make_clips(args.input_min, 1), "input"))
    print(f"setup {time.perf_counter() - t0:.1f} s: database {db.num_frames / 2 / db.fps / 60:.1f} min per hand "
          f"({len(db.segments)} segments, both hands), input {inp.duration / 60:.1f} min ({inp.num_frames} frames, "
          f"{inp.num_joints} joints)")
    cfg = SynthesisConfig()
    synthesize_clip(inp.slice(0, 300), hm, db, cfg)  # compile the numba kernels

    times, cpu = [], []
    for _ in range(args.repeat):
        t, c = time.perf_counter(), time.process_time()
        res = synthesize_clip(inp, hm, db, cfg)
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)  # all threads of the process: what the load inflates least
    end_to_end = min(times)

    # the search alone, and the candidate pairs it considered
    sc = cfg.segment_cost
    w = segment_weights(cfg)
    dw = weight_features(db.features, w)
    world = inp.world_xforms()
    pairs, cand, aligned_full = [], 0, 0
    bound_t = {"kim": 0.0, "keogh": 0.0, "none": 0.0}
    bound_pruned = {"kim": 0, "keogh": 0, "none": 0}
    for side in ("left", "right"):
        f = wrist_features(inp, hm[side], res.scale[side], world)
        qw = weight_features(f, w)
        b = segment_track(f, db.fps, cfg.segmentation)
        qb = np.stack([b[:-1], b[1:]], axis=1)
        idx = db_side_segments(db, side)
        ds = db.segments[idx, :2]
        results = {}
        for bound in ("kim", "keogh", "none"):
            t = time.perf_counter()
            results[bound] = knn_segments(qw, qb, dw, ds, k=sc.k, length_factor=sc.length_factor, band=sc.dtw_band,
                                          bound=bound)
            bound_t[bound] += time.perf_counter() - t
            bound_pruned[bound] += int(results[bound].pruned.sum())
            assert (results[bound].index == results["kim"].index).all()
        r = results["kim"]
        cand += int(r.candidates.sum())
        aligned_full += int((r.aligned - r.abandoned).sum())
        lens = ds[:, 1] - ds[:, 0]
        for q0, q1 in qb:
            n = q1 - q0
            ok = np.nonzero((lens * sc.length_factor >= n) & (lens <= n * sc.length_factor) & (lens <= 2 * n - 1))[0]
            pairs += [(qw[q0:q1], dw[ds[c, 0]:ds[c, 1]]) for c in ok]
    rng = np.random.default_rng(0)
    sample = [pairs[i] for i in rng.choice(len(pairs), size=min(args.pairs, len(pairs)), replace=False)]
    t = time.perf_counter()
    for q, d in sample:
        dtw_align(q, d, sc.dtw_band)
    numpy_per_pair = (time.perf_counter() - t) / len(sample)
    t = time.perf_counter()
    for q, d in sample:
        win = max(int(np.ceil(sc.dtw_band * len(d))), abs(len(q) - len(d)) + 1)
        dtw_ndim.distance(q, d, window=win, use_c=True)
    dtai_per_pair = (time.perf_counter() - t) / len(sample)
    numpy_total = numpy_per_pair * len(pairs)
    dtai_total = dtai_per_pair * len(pairs)

    files = file_to_file(inp, db, args.repeat)

    print(f"end to end (synthesize_clip, both hands): {end_to_end:.3f} s (best of {args.repeat}; "
          f"target < 2 s), CPU time {min(cpu):.3f} s; segments: left {len(res.hands['left'].chosen)}, "
          f"right {len(res.hands['right'].chosen)}")
    for fmt, (inproc, fresh, size) in files.items():
        print(f"  file to file, {fmt} ({size / 1e6:.1f} MB): 'usdhands synthesize IN -o OUT --db DB' in-process "
              f"{inproc:.3f} s (read, load the database memory-mapped, synthesize, write); as a fresh command "
              f"{fresh:.2f} s (with Python start-up, imports and loading the cached numba kernels)")
    search_t = bound_t["kim"]
    print(f"search (numba kernel, 2 threads, default end-point bound): {search_t:.3f} s over {cand} candidate pairs;"
          f" {100 * bound_pruned['kim'] / cand:.1f}% pruned by the bound, "
          f"{100 * (1 - aligned_full / max(cand, 1)):.1f}% never aligned in full (pruned or abandoned early)")
    print(f"  with LB_Keogh after the end points: {bound_t['keogh']:.3f} s, {100 * bound_pruned['keogh'] / cand:.1f}% "
          f"pruned; without a bound (early abandoning only): {bound_t['none']:.3f} s")
    print(f"plain NumPy DTW per pair: {1e6 * numpy_per_pair:.0f} us/pair -> {numpy_total:.1f} s for all pairs "
          f"(timed on {len(sample)} pairs): search speed-up x{numpy_total / search_t:.0f}, "
          f"end-to-end speed-up x{(numpy_total + end_to_end - search_t) / end_to_end:.0f}")
    print(f"dtaidistance dtw_ndim.distance per pair (C): {1e6 * dtai_per_pair:.0f} us/pair -> {dtai_total:.2f} s "
          f"for all pairs: search speed-up x{dtai_total / search_t:.1f}")


if __name__ == "__main__":
    main()

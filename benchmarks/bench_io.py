"""Reading and writing a long clip in each format, against the bare library calls.

Run: ``python benchmarks/bench_io.py [--frames 10000] [--joints 65] [--repeat 3]``

For each format, one function ``bench_<format>(clip, folder, repeat)`` returns rows of
(format, operation, usdhands seconds, baseline seconds, ratio). The baseline moves the
same arrays with the format library alone, in the same run (these machines are noisy:
read the ratios). Times are the best of ``repeat`` runs.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def make_clip(frames: int, joints: int, seed: int = 0):
    """A random ``frames`` x ``joints`` clip on a random tree, centimetres."""
    from usdhands.model.clip import Clip
    from usdhands.model.skeleton import Skeleton

    rng = np.random.default_rng(seed)
    parents = np.array([-1] + [int(rng.integers(0, j)) for j in range(1, joints)])
    names = [f"mixamorig:Joint{j}" for j in range(joints)]
    q = rng.normal(size=(frames, joints, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    rest_q = rng.normal(size=(joints, 4))
    rest_q /= np.linalg.norm(rest_q, axis=-1, keepdims=True)
    sk = Skeleton(names, parents, rng.normal(size=(joints, 3)) * 10, rest_q, meters_per_unit=0.01, name="Rig")
    return Clip(sk, 30.0, q, rng.normal(size=(frames, joints, 3)) * 10, name="Take")


def best_of(repeat: int, fn) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


# --------------------------------------------------------------------------- USD
def bench_usd(clip, folder: Path, repeat: int) -> list[tuple]:
    """usdhands' USD write/read against FromNumpy + Set / Get per time sample."""
    from pxr import Usd, UsdSkel, Vt

    from usdhands.formats.usd import HANDLER
    from usdhands.formats.usd_common import joint_tokens_for
    from usdhands.model.asset import Asset

    ours = folder / "ours.usdc"
    bare = folder / "bare.usdc"
    asset = Asset("bench", (clip.skeleton,), (clip,))
    tokens = joint_tokens_for(clip.skeleton.joint_names, clip.skeleton.parents)
    rot32 = np.ascontiguousarray(clip.rotations, dtype=np.float32)
    tr32 = np.ascontiguousarray(clip.translations, dtype=np.float32)
    T = clip.num_frames

    def write_ours():
        HANDLER.write(asset, ours)

    def write_bare():
        stage = Usd.Stage.CreateInMemory()
        stage.SetTimeCodesPerSecond(clip.fps)
        anim = UsdSkel.Animation.Define(stage, "/Anim")
        anim.CreateJointsAttr().Set(tokens)
        r, t = anim.CreateRotationsAttr(), anim.CreateTranslationsAttr()
        anim.CreateScalesAttr().Set(Vt.Vec3hArray.FromNumpy(np.ones((clip.num_joints, 3), np.float16)))
        for f in range(T):
            r.Set(Vt.QuatfArray.FromNumpy(rot32[f]), float(f))
            t.Set(Vt.Vec3fArray.FromNumpy(tr32[f]), float(f))
        stage.GetRootLayer().Export(str(bare))

    def read_ours():
        return HANDLER.read(ours)

    def read_bare():
        stage = Usd.Stage.Open(str(bare))
        anim = UsdSkel.Animation(stage.GetPrimAtPath("/Anim"))
        r, t = anim.GetRotationsAttr(), anim.GetTranslationsAttr()
        out_r = np.empty((T, clip.num_joints, 4), np.float32)
        out_t = np.empty((T, clip.num_joints, 3), np.float32)
        for f, code in enumerate(r.GetTimeSamples()):
            out_r[f] = np.asarray(r.Get(code))
            out_t[f] = np.asarray(t.Get(code))
        anim.GetScalesAttr().Get()
        return out_r, out_t

    rows = []
    w_ours, w_bare = best_of(repeat, write_ours), best_of(repeat, write_bare)
    rows.append(("usd", "write", w_ours, w_bare))
    r_ours, r_bare = best_of(repeat, read_ours), best_of(repeat, read_bare)
    rows.append(("usd", "read", r_ours, r_bare))
    back = read_ours().clips[0]
    err = float(np.abs(np.abs((back.rotations * clip.rotations).sum(-1)) - 1).max())
    rows.append(("usd", f"check: max |1-|q.q'|| = {err:.1e}", None, None))
    return rows


# -------------------------------------------------------------------------- glTF
def bench_gltf(clip, folder: Path, repeat: int) -> list[tuple]:
    """usdhands' glTF write/read (.glb) against pygltflib building and loading the same accessors.

    The baseline writes one input accessor and one rotation and one translation
    accessor per joint (what usdhands writes for this clip: scales stay at rest and
    are left out), saves with ``save_binary`` and reads back with ``GLTF2.load`` and
    ``np.frombuffer`` per accessor, with no sampling.
    """
    import pygltflib

    from usdhands.formats.gltf import HANDLER
    from usdhands.model.asset import Asset

    ours = folder / "ours.glb"
    bare = folder / "bare.glb"
    asset = Asset("bench", (clip.skeleton,), (clip,))
    T, J = clip.num_frames, clip.num_joints
    times = (np.arange(T) / clip.fps).astype(np.float32)
    rot32 = np.ascontiguousarray(clip.rotations.transpose(1, 0, 2), dtype=np.float32)
    tr32 = np.ascontiguousarray(clip.translations.transpose(1, 0, 2) * clip.skeleton.meters_per_unit,
                                dtype=np.float32)

    def write_ours():
        HANDLER.write(asset, ours)

    def write_bare():
        g = pygltflib.GLTF2()
        blob = bytearray()

        def accessor(arr, type_):
            g.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=arr.nbytes))
            blob.extend(arr.tobytes())
            g.accessors.append(pygltflib.Accessor(bufferView=len(g.bufferViews) - 1, componentType=pygltflib.FLOAT,
                                                  count=arr.shape[0], type=type_))
            return len(g.accessors) - 1

        inp = accessor(times, "SCALAR")
        g.accessors[inp].min, g.accessors[inp].max = [float(times[0])], [float(times[-1])]
        anim = pygltflib.Animation(name=clip.name)
        for j in range(J):
            g.nodes.append(pygltflib.Node(name=f"j{j}"))
            for path, arr, type_ in (("rotation", rot32[j], "VEC4"), ("translation", tr32[j], "VEC3")):
                anim.samplers.append(pygltflib.AnimationSampler(input=inp, output=accessor(arr, type_)))
                anim.channels.append(pygltflib.AnimationChannel(
                    sampler=len(anim.samplers) - 1, target=pygltflib.AnimationChannelTarget(node=j, path=path)))
        g.animations.append(anim)
        g.buffers.append(pygltflib.Buffer(byteLength=len(blob)))
        g.set_binary_blob(bytes(blob))
        g.save_binary(str(bare))

    def read_ours():
        return HANDLER.read(ours)

    def read_bare():
        g = pygltflib.GLTF2().load(str(bare))
        blob = g.binary_blob()
        out_r = np.empty((T, J, 4), np.float32)
        out_t = np.empty((T, J, 3), np.float32)
        anim = g.animations[0]
        for ch in anim.channels:
            acc = g.accessors[anim.samplers[ch.sampler].output]
            view = g.bufferViews[acc.bufferView]
            n = 4 if ch.target.path == "rotation" else 3
            arr = np.frombuffer(blob, np.float32, acc.count * n, view.byteOffset + (acc.byteOffset or 0))
            (out_r if n == 4 else out_t)[:, ch.target.node] = arr.reshape(-1, n)
        return out_r, out_t

    rows = []
    w_ours, w_bare = best_of(repeat, write_ours), best_of(repeat, write_bare)
    rows.append(("gltf", "write", w_ours, w_bare))
    r_ours, r_bare = best_of(repeat, read_ours), best_of(repeat, read_bare)
    rows.append(("gltf", "read", r_ours, r_bare))
    back = read_ours().clips[0]
    err = float(np.abs(np.abs((back.rotations * clip.rotations).sum(-1)) - 1).max())
    rows.append(("gltf", f"check: max |1-|q.q'|| = {err:.1e}", None, None))
    return rows


# --------------------------------------------------------------------------- BVH
def bench_bvh(clip, folder: Path, repeat: int) -> list[tuple]:
    """usdhands' BVH write/read against numpy writing and reading the same numbers as text.

    The baseline is the motion block alone: ``np.savetxt`` of the (T, C) channel values
    with the same ``%.6f`` format, and ``np.loadtxt`` of it, so the ratio is what the
    hierarchy, the Euler <-> quaternion conversions and the checks cost on top of
    moving the text.
    """
    from usdhands.formats.bvh import HANDLER
    from usdhands.model.asset import Asset

    ours = folder / "ours.bvh"
    bare = folder / "bare.txt"
    asset = Asset("bench", (clip.skeleton,), (clip,))
    HANDLER.write(asset, ours)
    text = ours.read_text()  # the channel values as written, for the baseline
    motion = np.loadtxt(text.split("Frame Time:", 1)[1].split("\n", 1)[1].splitlines())

    def write_ours():
        HANDLER.write(asset, ours)

    def write_bare():
        np.savetxt(bare, motion, fmt="%.6f")

    def read_ours():
        return HANDLER.read(ours)

    def read_bare():
        return np.loadtxt(bare)

    rows = []
    w_ours, w_bare = best_of(repeat, write_ours), best_of(repeat, write_bare)
    rows.append(("bvh", "write", w_ours, w_bare))
    r_ours, r_bare = best_of(repeat, read_ours), best_of(repeat, read_bare)
    rows.append(("bvh", "read", r_ours, r_bare))
    back = read_ours().clips[0]
    order = [back.skeleton.index(n) for n in clip.skeleton.short_names]  # BVH is depth-first
    err = float(np.abs(np.abs((back.rotations[:, order] * clip.rotations).sum(-1)) - 1).max())
    rows.append(("bvh", f"check: max |1-|q.q'|| = {err:.1e}", None, None))
    return rows


BENCHES = {"usd": bench_usd, "gltf": bench_gltf, "bvh": bench_bvh}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--joints", type=int, default=65)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--formats", nargs="*", default=list(BENCHES), choices=list(BENCHES))
    args = ap.parse_args(argv)
    clip = make_clip(args.frames, args.joints)
    print(f"clip: {args.frames} frames x {args.joints} joints, best of {args.repeat}")
    print(f"{'format':<7}{'operation':<34}{'usdhands s':>11}{'bare s':>9}{'ratio':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.formats:
            for fmt, op, ours, bare in BENCHES[name](clip, Path(tmp), args.repeat):
                if ours is None:
                    print(f"{fmt:<7}{op}")
                else:
                    print(f"{fmt:<7}{op:<34}{ours:>11.3f}{bare:>9.3f}{ours / bare:>7.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

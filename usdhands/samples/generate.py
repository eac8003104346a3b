"""Write the sample assets to a folder, deterministically.

Two layouts:

- ``"committed"`` (the default, what ``sample_assets/`` in the repository holds): every
  asset in at least one format, kept small (under 15 MB). The ground truth (the 64
  gesture takes and the conversation with fingers) is written in one format only
  (glTF ``.glb``, the most compact), the rig and the body-only synthesis inputs in
  every requested format.
- ``"full"``: every clip in every requested format (about 40 MB with all three).

Files (``<ext>`` is ``.usda``/``.usdc`` for USD, ``.glb`` for glTF, ``.bvh``):

- ``humanoid.usda`` / ``.glb`` / ``.bvh``: the rig, its skinned mesh (USD and glTF)
  and a 3-second idle-and-wave animation;
- ``gestures/<type>_<take>.<ext>``: the labelled database, 8 types x 8 takes; the label
  is the file name up to the take number (regex ``^([a-z_]+)_\\d+``), also listed in
  ``gestures/labels.csv`` with the hands each take uses;
- ``gestures_bodyonly/<type>_<take>_bodyonly.<ext>``: a few takes with the fingers
  frozen at rest (synthesis inputs);
- ``conversation.<ext>``: about 29 s of chained gestures with ground-truth fingers, and
  ``conversation.labels.csv`` (type, hands, start and end in seconds);
  ``conversation_bodyonly.<ext>``: the same with the fingers frozen at rest;
- ``props/cup.obj`` and ``props/cup.usda``: the cup prop;
- ``interaction/<name>.glb``: clips with full fingers that touch things (``cup_grasp``,
  ``scratch_head``, ``table_rest``; :mod:`usdhands.samples.interaction`) and their
  ``_bodyonly`` versions (the cup's only in the committed layout), with the props they
  touch in world metres like the glTF clips: ``props/table.obj``, ``props/cup_on_table.obj``.

The same call writes byte-identical files: fixed seeds, no time stamps.
"""

from __future__ import annotations

import csv
import fnmatch
import io
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from usdhands.model.asset import Asset
from usdhands.model.clip import Clip
from usdhands.samples.gestures import (
    GESTURE_TYPES, TAKES_PER_TYPE, body_only, conversation_annotations, conversation_clip, gesture_hands,
    gesture_take, wave_clip,
)
from usdhands.samples.humanoid import humanoid_mesh, humanoid_skeleton
from usdhands.samples.props import cup_mesh, cup_obj_text, cup_usda_text

__all__ = ["FORMATS", "LAYOUTS", "BODYONLY_TAKES", "SampleFile", "plan_samples", "generate_samples"]

FORMATS = ("usd", "gltf", "bvh")
LAYOUTS = ("committed", "full")

# Takes written body-only as synthesis inputs (besides the conversation).
BODYONLY_TAKES = (("ok", 0), ("attention", 3), ("turn", 5))


@dataclass(frozen=True)
class SampleFile:
    """One file of the plan: where it goes and how to make it."""

    relpath: str
    make: Callable[[], object]  # returns an Asset (written by the format writers) or str (text)
    kind: str  # "asset" or "text"


def _ext(fmt: str, small: bool) -> str:
    return {"usd": ".usda" if small else ".usdc", "gltf": ".glb", "bvh": ".bvh"}[fmt]


def _clip_asset(clip: Clip, name: str, with_mesh: bool = False) -> Asset:
    meshes = (humanoid_mesh(clip.skeleton),) if with_mesh else ()
    return Asset(path=name, skeletons=(clip.skeleton,), clips=(clip,), meshes=meshes)


def _labels_csv(seed: int, fmt_ext: str) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["file", "label", "take", "hands"])
    for g in GESTURE_TYPES:
        for k in range(TAKES_PER_TYPE):
            w.writerow([f"{g}_{k:02d}{fmt_ext}", g, k, "+".join(gesture_hands(g, k))])
    return buf.getvalue()


def _conversation_csv(seed: int) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["gesture", "hands", "start_s", "end_s"])
    for s in conversation_annotations(seed):
        w.writerow([s.gesture, "+".join(s.hands), f"{s.start:.3f}", f"{s.end:.3f}"])
    return buf.getvalue()


def plan_samples(formats=FORMATS, layout: str = "committed", seed: int = 0) -> list[SampleFile]:
    """The files :func:`generate_samples` writes, in order (nothing is computed yet).

    Parameters
    ----------
    formats : sequence of {"usd", "gltf", "bvh"}
    layout : {"committed", "full"}
    seed : int
    """
    formats = tuple(formats)
    bad = [f for f in formats if f not in FORMATS]
    if bad or not formats:
        raise ValueError(f"Expected formats among {FORMATS}, got {list(formats)}")
    if layout not in LAYOUTS:
        raise ValueError(f"Expected layout one of {LAYOUTS}, got {layout!r}")
    cache: dict[str, Clip] = {}

    def cached(key: str, make: Callable[[], Clip]) -> Callable[[], Clip]:
        def get() -> Clip:
            if key not in cache:
                cache[key] = make()
            return cache[key]
        return get

    wave = cached("wave", lambda: wave_clip(seed))
    conv = cached("conversation", lambda: conversation_clip(seed))
    plan: list[SampleFile] = []
    for fmt in formats:
        plan.append(SampleFile(f"humanoid{_ext(fmt, True)}",
                               lambda: _clip_asset(wave(), "humanoid", with_mesh=True), "asset"))
    db_formats = formats if layout == "full" else (("gltf",) if "gltf" in formats else formats[:1])
    for fmt in db_formats:
        for g in GESTURE_TYPES:
            for k in range(TAKES_PER_TYPE):
                plan.append(SampleFile(f"gestures/{g}_{k:02d}{_ext(fmt, False)}",
                                       (lambda g=g, k=k: _clip_asset(gesture_take(g, k, seed), f"{g}_{k:02d}")),
                                       "asset"))
    plan.append(SampleFile("gestures/labels.csv", lambda: _labels_csv(seed, _ext(db_formats[0], False)), "text"))
    bodyonly_formats = formats
    for i, (g, k) in enumerate(BODYONLY_TAKES):
        fmts = bodyonly_formats if layout == "full" else (bodyonly_formats[i % len(bodyonly_formats)],)
        for fmt in fmts:
            plan.append(SampleFile(f"gestures_bodyonly/{g}_{k:02d}_bodyonly{_ext(fmt, False)}",
                                   (lambda g=g, k=k: _clip_asset(body_only(gesture_take(g, k, seed)),
                                                                 f"{g}_{k:02d}_bodyonly")), "asset"))
    for fmt in (formats if layout == "full" else db_formats):
        plan.append(SampleFile(f"conversation{_ext(fmt, False)}", lambda: _clip_asset(conv(), "conversation"), "asset"))
    plan.append(SampleFile("conversation.labels.csv", lambda: _conversation_csv(seed), "text"))
    for fmt in formats:
        plan.append(SampleFile(f"conversation_bodyonly{_ext(fmt, False)}",
                               lambda: _clip_asset(body_only(conv()), "conversation_bodyonly"), "asset"))
    plan.append(SampleFile("props/cup.obj", lambda: cup_obj_text(cup_mesh()), "text"))
    plan.extend(_interaction_plan(formats, layout, seed))
    if "usd" in formats:
        plan.append(SampleFile("props/cup.usda", lambda: cup_usda_text(cup_mesh()), "text"))
    return plan


def _interaction_plan(formats, layout: str, seed: int) -> list[SampleFile]:
    """The interaction clips (glTF, metres like their OBJ props; USD or BVH when glTF is not asked
    for), their body-only versions (all in the full layout, the cup's only when committed) and the
    props (in metres)."""
    from usdhands.samples.interaction import (
        cup_grasp_clip, cup_on_table_mesh, mesh_obj_text, scratch_head_clip, table_mesh, table_rest_clip,
    )

    ext = ".glb" if "gltf" in formats else (".usdc" if "usd" in formats else ".bvh")
    makers = {"cup_grasp": cup_grasp_clip, "scratch_head": scratch_head_clip, "table_rest": table_rest_clip}
    plan = []
    for name, make in makers.items():
        plan.append(SampleFile(f"interaction/{name}{ext}", (lambda make=make, name=name: _clip_asset(make(seed), name)),
                               "asset"))
        if layout == "full" or name == "cup_grasp":
            plan.append(SampleFile(f"interaction/{name}_bodyonly{ext}",
                                   (lambda make=make, name=name: _clip_asset(body_only(make(seed)), f"{name}_bodyonly")),
                                   "asset"))
    plan.append(SampleFile("props/table.obj", lambda: mesh_obj_text(table_mesh(), "Table top", 0.01), "text"))
    plan.append(SampleFile("props/cup_on_table.obj",
                           lambda: mesh_obj_text(cup_on_table_mesh(), "Cup on the table", 0.01), "text"))
    return plan


def generate_samples(outdir: str | os.PathLike, formats=FORMATS, layout: str = "committed", seed: int = 0,
                     progress: Callable[[int, int, str], None] | None = None,
                     only: tuple[str, ...] | None = None) -> list[Path]:
    """Write the sample assets under ``outdir`` (created if missing).

    Parameters
    ----------
    outdir : path
    formats : sequence of {"usd", "gltf", "bvh"}
    layout : {"committed", "full"}
        See the module docstring.
    seed : int
        0 gives the committed assets.
    progress : callable ``(done, total, label)``, optional
    only : tuple of str, optional
        Glob patterns (``fnmatch``) of relative paths: write only the files that match.

    Returns
    -------
    list of Path
        The files written, in plan order.
    """
    from usdhands.formats.io import atomic_output, write_asset

    out = Path(outdir)
    plan = plan_samples(formats, layout, seed)
    if only is not None:
        plan = [p for p in plan if any(fnmatch.fnmatchcase(p.relpath, pat) for pat in only)]
    written = []
    # the skeleton is the same object for every clip: build it once so meshes share it
    humanoid_skeleton()
    for i, item in enumerate(plan):
        path = out / item.relpath
        path.parent.mkdir(parents=True, exist_ok=True)
        value = item.make()
        if item.kind == "text":
            with atomic_output(path) as tmp:
                Path(tmp).write_text(value, encoding="utf-8", newline="\n")
        else:
            write_asset(value, path)
        written.append(path)
        if progress is not None:
            progress(i + 1, len(plan), item.relpath)
    return written

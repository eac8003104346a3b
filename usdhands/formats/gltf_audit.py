"""The ``usdhands check`` rules on a glTF file, from its accessors as they are.

The reader refuses a sampler whose output does not fit its input and normalises
rotations; the audit reports those instead, one finding per broken rule, naming the
animation and node. Finger-motion provenance is the animation's
``extras.usdhands.provenance`` (``{"method", "database", "parameters", "version"}``).
"""

from __future__ import annotations

import os

import numpy as np

from usdhands.errors import AssetReadError, NoHandsError
from usdhands.formats.gltf_container import load_gltf
from usdhands.formats.gltf_read import animation_channels, channel_keys, scan_scene
from usdhands.formats.hands import hands_for
from usdhands.model.findings import Finding, provenance_problem

__all__ = ["audit_gltf"]

ZERO_NORM = 1e-6
EXTRAS_KEY = "usdhands"


def audit_gltf(path: str | os.PathLike, *, require_provenance: bool = False) -> list[Finding]:
    """The findings of a ``.gltf``/``.glb`` file; AssetReadError when it cannot be read at all."""
    name = str(path)
    doc = load_gltf(path)
    scene = scan_scene(doc)
    gltf = doc.gltf
    out: list[Finding] = []
    fingers_of = []  # per binding: {node: joint name} of its finger joints
    for binding in scene.bindings:
        sk = binding.skeleton
        where = f"skin {binding.skins[0]}" if binding.skins else f"skeleton {sk.name}"
        try:
            hands = hands_for(path, sk)[0]
        except NoHandsError:
            out.append(Finding(name, where, "hands", f"no hand detected by joint names among {sk.num_joints} joints "
                                                     "(glTF records no hand map)"))
            fingers_of.append({})
            continue
        names = set(j for h in hands.sides for j in h.finger_joints)
        fingers_of.append({binding.nodes[sk.index(j)]: j for j in names})
    for a, anim in enumerate(gltf.animations or []):
        where = f"animations[{a}]" + (f" {anim.name!r}" if anim.name else "")
        rotated: set[int] = set()
        for b, binding in enumerate(scene.bindings):
            for c, _, path_ in animation_channels(doc, a, binding):
                node = anim.channels[c].target.node
                try:
                    _, values, _ = channel_keys(doc, a, c)
                except AssetReadError as e:
                    out.append(Finding(name, f"{where} channels[{c}]", "array-lengths", e.message))
                    continue
                if path_ != "rotation":
                    continue
                rotated.add(node)
                norms = np.linalg.norm(values, axis=1)
                bad = np.flatnonzero(~np.isfinite(norms) | (norms < ZERO_NORM))
                if bad.size:
                    what = "NaN or infinite" if not np.isfinite(norms[bad[0]]) else "zero-length"
                    node_name = gltf.nodes[node].name or f"node {node}"
                    out.append(Finding(name, f"{where} channels[{c}]", "quaternions",
                                       f"{what} rotation of node {node_name!r} at key {int(bad[0])} "
                                       f"({bad.size} of {len(norms)} keys)"))
        animates = [b for b, binding in enumerate(scene.bindings) if rotated & set(binding.nodes)]
        finger_motion = False
        for b in animates:
            fingers = fingers_of[b]
            if not fingers:
                continue
            missing = [j for n, j in fingers.items() if n not in rotated]
            finger_motion = finger_motion or len(missing) < len(fingers)
            if missing:
                out.append(Finding(name, where, "finger-coverage",
                                   f"rotates {len(fingers) - len(missing)} of the {len(fingers)} finger joints; not: "
                                   f"{', '.join(sorted(missing)[:6])}{', ...' if len(missing) > 6 else ''}"))
        extras = anim.extras if isinstance(anim.extras, dict) else {}
        ours = extras.get(EXTRAS_KEY) if isinstance(extras.get(EXTRAS_KEY), dict) else {}
        record = ours.get("provenance")
        if record is not None:
            problem = provenance_problem(record)
            if problem:
                out.append(Finding(name, where, "provenance", problem))
        elif require_provenance and finger_motion:
            out.append(Finding(name, where, "provenance",
                               f"finger joints are animated but extras.{EXTRAS_KEY}.provenance records no method"))
    return out

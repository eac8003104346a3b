"""The ``usdhands check`` rules on a BVH file.

The motion block is scanned as text first (the reader refuses a short line or a NaN):
every frame line must hold one number per channel of the hierarchy, as many lines as
``Frames:`` says, every number finite (a NaN angle gives a NaN rotation). Then the file is
read and its hands detected. Every BVH joint has channels, so an animation covers every
joint it has; BVH records no provenance.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from usdhands.errors import AssetReadError, NoHandsError
from usdhands.model.findings import Finding

__all__ = ["audit_bvh"]


def audit_bvh(path: str | os.PathLike) -> list[Finding]:
    """The findings of a BVH file; AssetReadError when it cannot be read at all."""
    name = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as e:
        raise AssetReadError(f"cannot read: {e.strerror or e}", path=path) from None
    lines = text.splitlines()
    out = _motion_findings(name, lines)
    if out:
        return out
    from usdhands.formats.hands import hands_for
    from usdhands.formats.io import read_asset

    asset = read_asset(path)
    for sk in asset.skeletons:
        try:
            hands_for(path, sk)
        except NoHandsError:
            out.append(Finding(name, sk.joint_names[0] if sk.joint_names else "HIERARCHY", "hands",
                               f"no hand detected by joint names among {sk.num_joints} joints; give --handmap"))
    return out


def _motion_findings(name: str, lines: list[str]) -> list[Finding]:
    channels = []  # (joint, count) in file order
    joint = None
    motion = None
    for i, line in enumerate(lines):
        words = line.split()
        if not words:
            continue
        if words[0] in ("ROOT", "JOINT") and len(words) > 1:
            joint = words[1]
        elif words[0] == "CHANNELS" and len(words) > 1 and words[1].isdigit():
            channels.append((joint, int(words[1])))
        elif words[0] == "MOTION":
            motion = i
            break
    if motion is None or not channels:
        raise AssetReadError("no HIERARCHY with CHANNELS and MOTION block", path=name)
    total = sum(n for _, n in channels)
    declared = None
    rows = []
    for i in range(motion + 1, len(lines)):
        words = lines[i].split()
        if not words:
            continue
        if words[0] == "Frames:" and len(words) > 1:
            declared = int(words[1]) if words[1].isdigit() else None
        elif words[0] == "Frame" and len(words) > 1 and words[1] == "Time:":
            continue
        else:
            rows.append((i + 1, words))
    if declared is not None and len(rows) == declared + 1 and rows and all(_zero(w) for w in rows[0][1]):
        rows = rows[1:]  # the reader's one tolerance: a rest line of zeros before the frames (Leap exporter)
    out = []
    if declared is not None and declared != len(rows):
        out.append(Finding(name, "MOTION", "array-lengths", f"Frames: says {declared}, the block has {len(rows)} lines"))
    short = [(n, len(w)) for n, w in rows if len(w) != total]
    if short:
        n, k = short[0]
        out.append(Finding(name, f"line {n}", "array-lengths",
                           f"{k} values for {total} channels ({len(short)} such line(s))"))
    for n, words in rows:
        bad = [c for c, w in enumerate(words) if not _finite(w)]
        if bad:
            c = bad[0]
            owner, acc = None, 0
            for j, k in channels:
                if c < acc + k:
                    owner = j
                    break
                acc += k
            out.append(Finding(name, f"line {n}", "quaternions",
                               f"value {c + 1} ({words[c]!r}, joint {owner}) is not a finite number: the rotation "
                               "is NaN"))
            break
    return out


def _zero(word: str) -> bool:
    try:
        return float(word) == 0.0
    except ValueError:
        return False


def _finite(word: str) -> bool:
    try:
        return math.isfinite(float(word))
    except ValueError:
        return False

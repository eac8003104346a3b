"""World transforms of the few joints splicing reads (the arm chains), computed alone.

Splicing reads the wrist, forearm, shoulder and root of each hand; forward kinematics of
a whole 60-joint character costs more than the alignment. :func:`chain_xforms` computes
those joints and their ancestors only, one ``(T, 4, 4)`` array per joint;
:func:`partial_world_xforms` lays them out as a clip's ``(T, J, 4, 4)`` world array.

The local transforms come from a compiled kernel doing the arithmetic of
:func:`usdhands.model.rotations.trs_to_xform` in the same order (the same bits; a test
holds it to it); the products along the chain stay NumPy's ``matmul`` (its 4x4 products
go through BLAS, whose rounding a hand-written product would not repeat).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from usdhands.jit import njit
from usdhands.model.clip import Clip

__all__ = ["chain_xforms", "partial_world_xforms", "local_xforms"]


@njit(cache=True)
def _local_xforms_kernel(t, q, s, out):  # pragma: no cover - compiled
    """``trs_to_xform`` of ``t (T, K, 3)``, ``q (T, K, 4)``, ``s (T, K, 3)`` into ``out (K, T, 4, 4)``.

    The operations of ``_unit_quats``, ``quat_to_matrix`` and ``trs_to_xform``, one by
    one in their order. Returns False when a quaternion has zero norm (nothing else
    is promised of ``out`` then).
    """
    T = q.shape[0]
    K = q.shape[1]
    for k in range(K):
        for f in range(T):
            x0 = q[f, k, 0]
            y0 = q[f, k, 1]
            z0 = q[f, k, 2]
            w0 = q[f, k, 3]
            nrm = np.sqrt(x0 * x0 + y0 * y0 + z0 * z0 + w0 * w0)
            if nrm == 0.0:
                return False
            x = x0 / nrm
            y = y0 / nrm
            z = z0 / nrm
            w = w0 / nrm
            x2 = x * x
            y2 = y * y
            z2 = z * z
            w2 = w * w
            xy = x * y
            zw = z * w
            xz = x * z
            yw = y * w
            yz = y * z
            xw = x * w
            sx = s[f, k, 0]
            sy = s[f, k, 1]
            sz = s[f, k, 2]
            o = out[k, f]
            o[0, 0] = (x2 - y2 - z2 + w2) * sx
            o[0, 1] = (2 * (xy - zw)) * sy
            o[0, 2] = (2 * (xz + yw)) * sz
            o[0, 3] = t[f, k, 0]
            o[1, 0] = (2 * (xy + zw)) * sx
            o[1, 1] = (-x2 + y2 - z2 + w2) * sy
            o[1, 2] = (2 * (yz - xw)) * sz
            o[1, 3] = t[f, k, 1]
            o[2, 0] = (2 * (xz - yw)) * sx
            o[2, 1] = (2 * (yz + xw)) * sy
            o[2, 2] = (-x2 - y2 + z2 + w2) * sz
            o[2, 3] = t[f, k, 2]
            o[3, 0] = 0.0
            o[3, 1] = 0.0
            o[3, 2] = 0.0
            o[3, 3] = 1.0
    return True


def local_xforms(clip: Clip, joints: Sequence[int]) -> np.ndarray:
    """Local transforms of ``joints``, ``(len(joints), T, 4, 4)`` (joint-major), asset units.

    ``trs_to_xform(clip.translations[:, joints], clip.rotations[:, joints],
    clip.scales[:, joints])`` to the bit, with the joint axis first.

    Raises
    ------
    ValueError
        A rotation of zero norm (as ``trs_to_xform``).
    """
    idx = np.asarray(joints, dtype=np.int64)
    out = np.empty((len(idx), clip.num_frames, 4, 4))
    if not _local_xforms_kernel(clip.translations[:, idx], clip.rotations[:, idx], clip.scales[:, idx], out):
        raise ValueError("Found zero norm quaternions in `quat`.")
    return out


def chain_xforms(clip: Clip, joints: Sequence[int]) -> dict[int, np.ndarray]:
    """World transforms of ``joints`` and their ancestors: joint index to ``(T, 4, 4)``, asset units.

    The same numbers as ``clip.world_xforms()[:, j]`` for those joints, without the others.
    """
    sk = clip.skeleton
    need = sorted({a for j in joints for a in sk.chain_to_root(int(j))})  # parents come before children
    xf = local_xforms(clip, need)  # turned into world transforms in place, parents first
    world: dict[int, np.ndarray] = {}
    for k, j in enumerate(need):
        p = int(sk.parents[j])
        if p >= 0:
            np.matmul(world[p], xf[k], out=xf[k])
        world[j] = xf[k]
    return world


def partial_world_xforms(clip: Clip, joints: Sequence[int]) -> np.ndarray:
    """World transforms ``(T, J, 4, 4)`` computed only for ``joints`` and their ancestors.

    Other joints are left zero; pass the result as ``world=`` to the marker functions.
    The array is a joint-major block seen time-major: each joint's transforms are
    contiguous, so only the computed joints' pages are ever written.
    """
    sk = clip.skeleton
    world = np.zeros((sk.num_joints, clip.num_frames, 4, 4))
    for j, x in chain_xforms(clip, joints).items():
        world[j] = x
    return world.transpose(1, 0, 2, 3)

"""numba kernel behind the sign of a distance to a closed shell.

:func:`closed_shell_signs` is the compiled twin of the side test of
:meth:`usdhands.algorithms.interaction.proximity._Part.signed_distance` (the nearest face's side,
an edge's pseudonormal, and what is left to the winding number), one pass over the points with
the same formulas. Its dot products are summed x, y, z in order, where ``einsum`` may round the
last bit otherwise; they only decide a sign against thresholds (``1e-12 * (1 + d)`` off the
plane, ``1e-6`` in barycentric coordinates) and every answer is the distance igl measured, so the
answers are the same (tests hold it to the NumPy code on points at faces, edges and vertices).
Its twin compiled ahead of time (``_interaction_compiled``, :mod:`usdhands.compiled`) runs where it
was built; this one where it was not and a kernel of the package already runs
(:func:`usdhands.jit.kernels_running`). Kept apart so importing the algorithms compiles nothing.
"""

from __future__ import annotations

import numpy as np

from usdhands.jit import njit


@njit(cache=True)
def closed_shell_signs(p, closest, face, d, normals, vertices, faces, neighbours, flat):
    """Signed distances ``(N,)`` (``d`` negated where the point is behind its nearest face or edge) and
    whether each is left undecided ``(N,)`` bool (on a vertex, a flat face or exactly on a plane: the
    winding number decides those).

    Parameters
    ----------
    p, closest : (N, 3) float
        The points and their nearest points on the shell.
    face : (N,) int
        The nearest face of each.
    d : (N,) float
        Distances ``|p - closest|``.
    normals : (F, 3) float
        Unit face normals (outward).
    vertices : (V, 3) float
    faces : (F, 3) int
    neighbours : (F, 3) int
        The face across the edge opposite each corner.
    flat : (F,) bool
        Faces without a usable normal.
    """
    n = p.shape[0]
    out = np.empty(n)
    undecided = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        f = face[i]
        r0 = p[i, 0] - closest[i, 0]
        r1 = p[i, 1] - closest[i, 1]
        r2 = p[i, 2] - closest[i, 2]
        side = r0 * normals[f, 0] + r1 * normals[f, 1] + r2 * normals[f, 2]
        a = faces[f, 0]
        b = faces[f, 1]
        c = faces[f, 2]
        e00 = vertices[b, 0] - vertices[a, 0]
        e01 = vertices[b, 1] - vertices[a, 1]
        e02 = vertices[b, 2] - vertices[a, 2]
        e10 = vertices[c, 0] - vertices[a, 0]
        e11 = vertices[c, 1] - vertices[a, 1]
        e12 = vertices[c, 2] - vertices[a, 2]
        q0 = closest[i, 0] - vertices[a, 0]
        q1 = closest[i, 1] - vertices[a, 1]
        q2 = closest[i, 2] - vertices[a, 2]
        d00 = e00 * e00 + e01 * e01 + e02 * e02
        d01 = e00 * e10 + e01 * e11 + e02 * e12
        d11 = e10 * e10 + e11 * e11 + e12 * e12
        d20 = q0 * e00 + q1 * e01 + q2 * e02
        d21 = q0 * e10 + q1 * e11 + q2 * e12
        den = d00 * d11 - d01 * d01
        if den > 0:
            v = (d11 * d20 - d01 * d21) / den
            w = (d00 * d21 - d01 * d20) / den
        else:
            v = -1.0
            w = -1.0
        u = 1.0 - v - w
        on0 = u <= 1e-6
        on1 = v <= 1e-6
        on2 = w <= 1e-6
        count = int(on0) + int(on1) + int(on2)
        di = d[i]
        decided = count == 0 and abs(side) > 1e-12 * (1.0 + di) and not flat[f]
        inside = side < 0
        if count == 1 and di > 0:
            k = 0 if on0 else (1 if on1 else 2)
            g = neighbours[f, k]
            s = r0 * (normals[f, 0] + normals[g, 0]) + r1 * (normals[f, 1] + normals[g, 1]) + \
                r2 * (normals[f, 2] + normals[g, 2])
            if abs(s) > 1e-12 * (1.0 + di) and not flat[f] and not flat[g]:
                decided = True
                inside = s < 0
        if not decided and di > 0:
            undecided[i] = True
        out[i] = -di if inside else di
    return out, undecided

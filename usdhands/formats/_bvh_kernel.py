"""numba kernels behind reading BVH motion: the text of the ``MOTION`` block to ``(T, C)`` floats
(:func:`parse_rows`), and those values to a clip's rotations and translations (:func:`clip_arrays`).

:func:`parse_rows` is the compiled twin of ``np.loadtxt`` on the motion lines, for the
numbers a BVH file holds. It reads only what it can read exactly as ``float()`` does
(and ``np.loadtxt``, which gives ``float()``'s numbers) and hands everything else back
to the caller, which then reads the block with ``np.loadtxt`` (and names a bad line):

- a number is ``[+-]digits[.digits][(e|E)[+-]digits]`` (either side of the point may be
  empty, not both), at most 19 significant digits, exponent at most 6 digits;
- its value is made with one correctly rounded operation (Clinger's fast path): the
  significant digits ``w`` as an integer and the power of ten ``e`` they are scaled by,
  ``w * 10**e`` or ``w / 10**-e``, when ``w <= 2**53`` and ``|e| <= 22`` (both operands
  exact: one rounding, the correctly rounded value, which is ``float()``'s); zero
  whatever its exponent, signed as written (``-0.000000`` is ``-0.0``); any other
  number is handed back;
- numbers are separated by spaces and tabs; lines end with ``\\n`` or ``\\r\\n``
  (a lone ``\\r`` is handed back); lines holding only spaces and tabs are skipped, as
  ``np.loadtxt`` skips them; every other line must hold exactly ``C`` numbers.

Tests hold it to ``float()`` on random decimal strings (exponents, long mantissas,
negative zero) and to ``np.loadtxt`` on every real BVH file, and :func:`clip_arrays`
to the NumPy conversion. Kept apart so importing the BVH reader imports no numba.
"""

from __future__ import annotations

import math

import numpy as np

from usdhands.jit import njit

#: 10**0 .. 10**22: the powers of ten a double holds exactly.
POW10 = np.array([10.0 ** k for k in range(23)])
_TWO_53 = 2 ** 53


@njit(cache=True, nogil=True)
def parse_rows(buf, start, columns, out, pow10):
    """Parse ``buf[start:]`` (uint8, the motion lines) into ``out (rows, columns)`` float64.

    Returns the number of rows read (``<= out.shape[0]``), or ``-1`` when the text holds
    anything outside the forms above, a row of another length, or more rows than ``out``.
    """
    n = buf.shape[0]
    cap = out.shape[0]
    i = start
    row = 0
    col = 0
    while i < n:
        b = buf[i]
        if b == 32 or b == 9:  # space, tab
            i += 1
            continue
        if b == 10 or b == 13:  # \n, \r\n
            if b == 13:
                if i + 1 < n and buf[i + 1] == 10:
                    i += 1
                else:
                    return -1
            if col != 0:
                if col != columns:
                    return -1
                row += 1
                col = 0
            i += 1
            continue
        if col >= columns or (col == 0 and row >= cap):
            return -1
        neg = False
        if b == 45 or b == 43:  # - +
            neg = b == 45
            i += 1
        w = np.uint64(0)
        significant = 0
        digits = 0
        frac = 0
        point = False
        while i < n:
            c = buf[i]
            if 48 <= c <= 57:
                digits += 1
                if point:
                    frac += 1
                if w != 0 or c != 48:
                    significant += 1
                    if significant > 19:
                        return -1
                    w = w * np.uint64(10) + np.uint64(c - 48)
                i += 1
            elif c == 46 and not point:  # .
                point = True
                i += 1
            else:
                break
        if digits == 0:
            return -1
        e = 0
        if i < n and (buf[i] == 101 or buf[i] == 69):  # e E
            i += 1
            eneg = False
            if i < n and (buf[i] == 45 or buf[i] == 43):
                eneg = buf[i] == 45
                i += 1
            edigits = 0
            while i < n and 48 <= buf[i] <= 57:
                edigits += 1
                if edigits > 6:
                    return -1
                e = e * 10 + (buf[i] - 48)
                i += 1
            if edigits == 0:
                return -1
            if eneg:
                e = -e
        if i < n:
            c = buf[i]
            if not (c == 32 or c == 9 or c == 10 or c == 13):
                return -1
        e -= frac
        v = 0.0
        if w != 0:
            if w > np.uint64(_TWO_53) or e < -22 or e > 22:
                return -1
            v = float(w)
            if e < 0:
                v = v / pow10[-e]
            elif e > 0:
                v = v * pow10[e]
        out[row, col] = -v if neg else v
        col += 1
    if col != 0:
        if col != columns:
            return -1
        row += 1
    return row


#: For each axis a (X, Y, Z), ``q * e_a`` as a signed permutation of q's xyzw components:
#: component k of the product is ``SIGN[a, k] * q[PERM[a, k]]`` (the NumPy twin's ``_AXIS_PRODUCT``).
PERM = np.array([[3, 2, 1, 0], [2, 3, 0, 1], [1, 0, 3, 2]], dtype=np.int64)
SIGN = np.array([[1.0, 1.0, -1.0, -1.0], [-1.0, 1.0, 1.0, -1.0], [1.0, -1.0, 1.0, -1.0]])


#: Radians a degree, as ``np.radians`` multiplies by it.
_RADIANS = math.pi / 180.0


#: Frames converted together, joint after joint: their rows of values and rotations stay in cache.
_BLOCK = 64


@njit(cache=True, nogil=True)
def clip_arrays(values, offsets, first, count, axes, cols, pjoint, paxis, pcol, perm, sign, rot, trans):
    """A clip's rotations ``rot (T, J, 4)`` (xyzw) and translations ``trans (T, J, 3)`` from BVH motion values.

    ``values (T, C)``: the motion values, degrees in the rotation columns. Joint ``j`` has
    rotation channels ``first[j] .. first[j] + count[j] - 1`` (none where ``count[j]`` is
    0: the identity), about axes ``axes[...]`` (0 X, 1 Y, 2 Z), read from columns
    ``cols[...]``; its rotation is the product of its axis rotations in channel order.
    Translations are the ``offsets (J, 3)``, with position channel ``p`` (in file order:
    a channel given twice, the last wins) putting column ``pcol[p]`` in place of component
    ``paxis[p]`` of joint ``pjoint[p]``.

    The NumPy twin's numbers (``bvh._rotations_numpy``): the half angle is
    ``radians(x) * 0.5`` as NumPy computes it, its cosine and sine the C library's
    (``math.cos``/``math.sin``, which NumPy's float64 ``cos``/``sin`` call; an angle of
    zero gives ``1`` and the signed zero without the call, as they do), and the axis
    rotations are multiplied with the same operations in the same order, skipping the
    same zero components. Which components are zero depends on the axes alone: each
    joint's operations are planned once (``plan``), then run for every frame.
    """
    T = values.shape[0]
    J = first.shape[0]
    width = 1
    for j in range(J):
        width = max(width, count[j])
    # plan[j, i, k]: how step i makes component k of joint j: 0 zero, 1 kept * c, 2 moved * s,
    # 3 -(moved * s), 4 kept * c + moved * s, 5 kept * c - moved * s (moved = component perm[axis, k])
    plan = np.zeros((J, width, 4), dtype=np.int64)
    has = np.zeros(4, dtype=np.bool_)
    nhas = np.zeros(4, dtype=np.bool_)
    for j in range(J):
        f = first[j]
        if count[j] == 0:
            continue
        for k in range(4):
            has[k] = k == 3 or k == axes[f]
        for i in range(1, count[j]):
            a = axes[f + i]
            for k in range(4):
                m = perm[a, k]
                if not has[m]:
                    plan[j, i, k] = 1 if has[k] else 0
                    nhas[k] = has[k]
                elif not has[k]:
                    plan[j, i, k] = 3 if sign[a, k] < 0 else 2
                    nhas[k] = True
                else:
                    plan[j, i, k] = 5 if sign[a, k] < 0 else 4
                    nhas[k] = True
            for k in range(4):
                has[k] = nhas[k]
    q = np.empty(4)
    nq = np.empty(4)
    for t0 in range(0, T, _BLOCK):
        t1 = min(T, t0 + _BLOCK)
        for j in range(J):
            f = first[j]
            n = count[j]
            if n == 0:
                for t in range(t0, t1):
                    rot[t, j, 0] = 0.0
                    rot[t, j, 1] = 0.0
                    rot[t, j, 2] = 0.0
                    rot[t, j, 3] = 1.0
                continue
            a0 = axes[f]
            for t in range(t0, t1):
                for k in range(4):
                    q[k] = 0.0
                h = values[t, cols[f]] * _RADIANS * 0.5
                q[3] = 1.0 if h == 0.0 else math.cos(h)
                q[a0] = h if h == 0.0 else math.sin(h)
                for i in range(1, n):
                    a = axes[f + i]
                    h = values[t, cols[f + i]] * _RADIANS * 0.5
                    ci = 1.0 if h == 0.0 else math.cos(h)
                    si = h if h == 0.0 else math.sin(h)
                    for k in range(4):
                        op = plan[j, i, k]
                        if op == 0:
                            nq[k] = 0.0
                        elif op == 1:
                            nq[k] = q[k] * ci
                        elif op == 2:
                            nq[k] = q[perm[a, k]] * si
                        elif op == 3:
                            nq[k] = -(q[perm[a, k]] * si)
                        elif op == 4:
                            nq[k] = q[k] * ci + q[perm[a, k]] * si
                        else:
                            nq[k] = q[k] * ci - q[perm[a, k]] * si
                    for k in range(4):
                        q[k] = nq[k]
                for k in range(4):
                    rot[t, j, k] = q[k]
        for t in range(t0, t1):
            for j in range(J):
                trans[t, j, 0] = offsets[j, 0]
                trans[t, j, 1] = offsets[j, 1]
                trans[t, j, 2] = offsets[j, 2]
            for p in range(pjoint.shape[0]):
                trans[t, pjoint[p], paxis[p]] = values[t, pcol[p]]

"""numba kernel behind the RTS smoother's steady stretch: a second-order linear recursion.

:func:`second_order` runs ``y_n = x_n - a1 y_(n-1) - a2 y_(n-2)`` down the columns of an
array, from a given state, with the very operations of ``scipy.signal.lfilter([1], [1, a1, a2],
x, axis=0, zi=zi)`` (its transposed direct form II, the numerator padded with zeros), so the
results are equal to the bit; tests hold it to ``lfilter``. It replaces ``lfilter`` so that a
correction does not import ``scipy.signal`` (about 0.3 s of a fresh process). Its twin compiled ahead
of time (``_interaction_compiled``, :mod:`usdhands.compiled`) runs where it was built; this one where it
was not and a kernel of the package already runs (:func:`usdhands.jit.kernels_running`; loading numba and the kernel cost about as much as ``scipy.signal``); elsewhere
its NumPy twin :func:`usdhands.algorithms.interaction.smoothing.second_order_steps` runs.
Kept apart so importing the algorithms compiles nothing.
"""

from __future__ import annotations

import numpy as np

from usdhands.jit import njit


@njit(cache=True)
def second_order(x, a1, a2, zi):
    """``lfilter([1.0], [1.0, a1, a2], x, axis=0, zi=zi)[0]`` for ``x`` ``(n, C)`` float64 and
    ``zi`` ``(2, C)``: a new ``(n, C)`` array."""
    n, C = x.shape
    y = np.empty((n, C))
    b1 = 0.0
    b2 = 0.0
    for c in range(C):
        z0 = zi[0, c]
        z1 = zi[1, c]
        for k in range(n):
            xn = x[k, c]
            yn = z0 + 1.0 * xn
            z0 = z1 + xn * b1 - yn * a1
            z1 = xn * b2 - yn * a2
            y[k, c] = yn
    return y


"""The compiled joint-transform kernels (``usdhands.model._transforms_compiled``) against their NumPy
references, to the bit: ``xform_to_trs`` (translations, quaternions, scales) and the USD reader's
check of a skeleton's transforms; and the calls they leave to NumPy (mirrors near singular, shears,
determinants near the bound), which must give NumPy's answers and errors."""

from __future__ import annotations

import numpy as np
import pytest

from usdhands.compiled import kernel_module
from usdhands.formats import usd_read
from usdhands.model import rotations
from usdhands.model.rotations import trs_to_xform, xform_to_trs

KERNEL = kernel_module("model._transforms_compiled")
needs_built = pytest.mark.skipif(KERNEL is None, reason="the compiled kernels were not built (no C compiler)")


def _transforms(rng, trial: int) -> np.ndarray:
    """Random ``(n, 4, 4)`` transforms: rotations (random, and about one axis: ties in Markley's choice)
    times scales (uniform, non-uniform, mirrored), some made slightly or much less than orthogonal, a
    column zeroed, a NaN."""
    n = int(rng.integers(1, 30))
    q = rng.normal(size=(n, 4))
    if trial % 5 == 0:
        q[:] = 0.0
        q[np.arange(n), rng.integers(0, 4, n)] = 1.0
    s = rng.uniform(0.01, 100, (n, 3))
    if trial % 3 == 0:
        s[:] = s[:, :1]
    if trial % 7 == 0:
        s[:, 0] *= -1.0
    m = trs_to_xform(rng.normal(size=(n, 3)) * 50, q, s)
    if trial % 11 == 0:
        m[:, :3, :3] += rng.normal(size=(n, 3, 3)) * 10.0 ** rng.uniform(-16, -8)
    if trial % 13 == 0:
        m[0, :3, 0] = 0.0
    if trial % 17 == 0:
        m[0, 1, 1] = np.nan
    return m


@needs_built
def test_compiled_split_is_numpys_to_the_bit():
    """Where the kernel answers, its translations, quaternions and scales are NumPy's bit for bit; where
    it does not (None), NumPy's function decides; both outcomes occur, and ordinary transforms (rotations
    times positive scales) are the kernel's."""
    rng = np.random.default_rng(21)
    answered = deferred = 0
    for trial in range(6000):
        m = _transforms(rng, trial)
        split = KERNEL.xform_to_trs(np.ascontiguousarray(m))
        if split is None:
            deferred += 1
            continue
        answered += 1
        reference = rotations._xform_to_trs(m)
        for ours, theirs in zip(split, reference):
            assert ours.dtype == np.float64 and ours.tobytes() == theirs.tobytes(), trial
    assert answered > 4000 and deferred > 100
    plain = trs_to_xform(rng.normal(size=(50, 3)), rng.normal(size=(50, 4)), rng.uniform(0.1, 10, (50, 3)))
    assert KERNEL.xform_to_trs(np.ascontiguousarray(plain)) is not None


@needs_built
@pytest.mark.parametrize("shape", [(4, 4), (7, 4, 4), (3, 5, 4, 4)])
def test_xform_to_trs_gives_the_same_with_the_kernel_off(shape, monkeypatch):
    """The public function, any leading shape, a non-contiguous input: the same arrays (shapes, bits) with
    and without the kernel; a mirrored transform keeps its reflection in the x scale."""
    rng = np.random.default_rng(22)
    m = trs_to_xform(rng.normal(size=shape[:-2] + (3,)), rng.normal(size=shape[:-2] + (4,)),
                     rng.uniform(0.1, 10, shape[:-2] + (3,)) * np.array([-1.0, 1.0, 1.0]))
    m = np.swapaxes(np.swapaxes(m, -1, -2).copy(), -1, -2)  # the same values, not C-contiguous
    fast = xform_to_trs(m)
    monkeypatch.setattr(rotations, "_TRANSFORMS_KERNEL", [None])
    slow = xform_to_trs(m)
    for a, b in zip(fast, slow):
        assert a.shape == b.shape and a.tobytes() == b.tobytes()
    assert (fast[2][..., 0] < 0).all()


@needs_built
def test_calls_left_to_numpy_raise_numpys_errors(monkeypatch):
    """A singular transform: the kernel does not answer, and the function raises NumPy's error."""
    m = np.eye(4)
    m[:3, 1] = m[:3, 0]
    assert KERNEL.xform_to_trs(m[None]) is None
    with pytest.raises(ValueError, match="Non-positive determinant"):
        xform_to_trs(m)


@needs_built
def test_compiled_transform_check_is_the_readers():
    """The USD reader's check of joint transforms: the kernel's answer is NumPy's on transforms made to
    pass and to fail each test (a projective or non-affine last row, NaN and infinities, zero and
    tiny columns, columns nearly dependent around the 1e-6 bound, huge scales)."""
    rng = np.random.default_rng(23)
    seen = {True: 0, False: 0}
    for trial in range(6000):
        n = int(rng.integers(1, 40))
        m = trs_to_xform(rng.normal(size=(n, 3)), rng.normal(size=(n, 4)), rng.uniform(1e-3, 1e3, (n, 3)))
        k, case = int(rng.integers(n)), trial % 10
        if case == 1:
            m[k, 3, int(rng.integers(3))] = rng.choice([1e-7, 1e-6, 2e-6, 0.5])
        elif case == 2:
            m[k, 3, 3] = 1 + rng.choice([1e-7, 1e-6, 3e-6])
        elif case == 3:
            m[k, int(rng.integers(4)), int(rng.integers(4))] = rng.choice([np.nan, np.inf, -np.inf])
        elif case == 4:
            m[k, :3, int(rng.integers(3))] = rng.choice([0.0, 1e-13, 1e-11])
        elif case == 5:
            c = m[k, :3, 0] / np.linalg.norm(m[k, :3, 0])
            m[k, :3, 1] = c * 3 + rng.normal(size=3) * 10.0 ** rng.uniform(-8, -4)
        elif case == 6:
            m[k, :3, :3] *= 1e200
        ours = KERNEL.xforms_ok(np.ascontiguousarray(m))
        if ours is None:
            continue
        assert ours == usd_read._numpy_xforms_ok(m), trial
        seen[ours] += 1
    assert seen[True] > 1000 and seen[False] > 1000

"""The kernels compiled ahead of time: built from Cython when the package is installed (``setup.py``).

Six modules, each the twin of a numba (or Python) kernel module with the same functions, arguments
and results to the bit:

- ``algorithms.synthesis._search_compiled``: the synthesis search and one pair's warp
  (:mod:`usdhands.algorithms.synthesis._dtw_kernel`);
- ``algorithms.synthesis._play_compiled``: playing, stitching and step-limiting the chosen
  fragments (:mod:`usdhands.algorithms.synthesis._play_kernel`);
- ``formats._bvh_compiled``: reading BVH motion (:mod:`usdhands.formats._bvh_kernel`);
- ``formats._crate_compiled``: the LZ4 blocks and coded integers the check of a USD crate file
  reads, and its walks of the values and of the path tree (:mod:`usdhands.formats.usdc_crate`,
  whose Python functions and methods are its twins); and whether every child the crate's specs
  list has a spec, where the bytes show it simply (else the Sdf walk of ``usd_common.check_children``
  decides, as it does where the module was not built);
- ``algorithms.interaction._interaction_compiled``: the sign of a distance to a closed shell and the
  RTS smoother's recursion (:mod:`usdhands.algorithms.interaction._proximity_kernel`,
  :mod:`usdhands.algorithms.interaction._recursion_kernel`), which ``correct`` and ``synthesize --props``
  run; and the props' geometry that lets those commands import neither libigl nor SciPy against
  closed props: a triangle tree for exact nearest points (libigl's ``AABB``: the same distances to
  rounding), the corner side test, the shells' union-find (SciPy's components) and the bounded
  smoother's banded Cholesky (``scipy.linalg.solveh_banded``: the same solutions to rounding). An
  install without it runs libigl and SciPy there;
- ``model._transforms_compiled``: joint transforms taken apart into translations, quaternions and
  scales, and the USD reader's check of a skeleton's transforms
  (:func:`usdhands.model.rotations.xform_to_trs`, ``usdhands.formats.usd_read._xforms_ok``), which
  every reader of a skeleton runs: NumPy's small calls on a skeleton's few joints cost more than
  their arithmetic.

A process that runs these never imports numba: nothing to start (numba's import, CPU target
and cached kernels cost about 0.35 s of CPU a process, measured), one thread each where
numba's search and play run in parallel. So a command on one clip, and every worker of
``usdhands batch``, runs them; a process that searches much more than a batch clip's work
loads numba's parallel twins instead (see ``segment_cost.COMPILED_SEARCH_MAX_CELLS``).

They are optional: an install without a C compiler (the build is allowed to fail) gives
``None`` here, and the package runs the numba and NumPy twins (the same results); so does
``USDHANDS_COMPILED_KERNELS=0`` in the environment.
"""

from __future__ import annotations

import importlib
import os
from types import ModuleType

__all__ = ["kernel_module", "kernel_file_built", "ENABLED", "KERNEL_MODULES"]

#: The compiled modules, by their names under ``usdhands``.
KERNEL_MODULES = ("algorithms.synthesis._search_compiled", "algorithms.synthesis._play_compiled",
                  "formats._bvh_compiled", "algorithms.interaction._interaction_compiled", "formats._crate_compiled",
                  "model._transforms_compiled")
#: ``False``: never use them (as an install without a C compiler does), for tests and comparisons;
#: set from the environment variable ``USDHANDS_COMPILED_KERNELS=0`` (the processes a batch starts
#: inherit it).
ENABLED = os.environ.get("USDHANDS_COMPILED_KERNELS", "1").strip() != "0"
_loaded: dict[str, ModuleType | None] = {}


def kernel_module(name: str) -> ModuleType | None:
    """The compiled module ``usdhands.<name>`` (one of :data:`KERNEL_MODULES`), or None where it was
    not built (no C compiler at install) or :data:`ENABLED` is False. Imports no numba."""
    if name not in KERNEL_MODULES:
        raise ValueError(f"unknown compiled kernel module {name!r}; expected one of {KERNEL_MODULES}")
    if not ENABLED:
        return None
    if name not in _loaded:
        try:
            _loaded[name] = importlib.import_module(f"usdhands.{name}")
        except ImportError:
            _loaded[name] = None
    return _loaded[name]


def kernel_file_built(name: str) -> bool:
    """Whether the compiled module ``usdhands.<name>`` (one of :data:`KERNEL_MODULES`) was built: its
    extension file is in the package (False where :data:`ENABLED` is False). Imports nothing (neither
    the module nor NumPy, nor the packages above it): for a guess made before they load, which
    :func:`kernel_module` confirms (a file that fails to import gives None there)."""
    if name not in KERNEL_MODULES:
        raise ValueError(f"unknown compiled kernel module {name!r}; expected one of {KERNEL_MODULES}")
    if not ENABLED:
        return False
    from importlib.machinery import EXTENSION_SUFFIXES
    from pathlib import Path

    *package, stem = name.split(".")
    folder = Path(__file__).parent.joinpath(*package)
    return any((folder / (stem + suffix)).is_file() for suffix in EXTENSION_SUFFIXES)

"""Build of usdhands' kernels compiled ahead of time (Cython); everything else is in pyproject.toml.

The kernels a batch worker or a one-clip command runs (the synthesis search, playing and
stitching the chosen fragments, reading BVH motion, the interaction's side test and smoother
recursion, the props' nearest-point tree and banded solves, joint transforms taken apart;
:mod:`usdhands.compiled`) are
compiled here, at install, so that a process using them never starts numba (about 0.35 s of
CPU a process) and a correction against closed props imports neither libigl nor SciPy. They
are optional: where no C compiler is found, the install goes on and the package runs the
numba and NumPy twins of the same kernels (the same results), and libigl's tree and SciPy's
banded solve for the props (the same distances and solutions to rounding).

Floating point: no fused multiply-add contraction (``-ffp-contract=off``), so that each
kernel gives its numba twin's numbers to the bit on every CPU.
"""

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

KERNELS = {
    "usdhands.algorithms.synthesis._search_compiled": "usdhands/algorithms/synthesis/_search_compiled.pyx",
    "usdhands.algorithms.synthesis._play_compiled": "usdhands/algorithms/synthesis/_play_compiled.pyx",
    "usdhands.formats._bvh_compiled": "usdhands/formats/_bvh_compiled.pyx",
    "usdhands.formats._crate_compiled": "usdhands/formats/_crate_compiled.pyx",
    "usdhands.algorithms.interaction._interaction_compiled": "usdhands/algorithms/interaction/_interaction_compiled.pyx",
    "usdhands.model._transforms_compiled": "usdhands/model/_transforms_compiled.pyx",
}


class BuildKernels(build_ext):
    """``build_ext`` with the floating-point flags of the compiler in use."""

    def build_extensions(self):
        flags = ["/fp:precise"] if self.compiler.compiler_type == "msvc" else ["-O2", "-ffp-contract=off"]
        for ext in self.extensions:
            ext.extra_compile_args = flags
        super().build_extensions()


setup(
    ext_modules=[Extension(name, [source], optional=True) for name, source in KERNELS.items()],
    cmdclass={"build_ext": BuildKernels},
)

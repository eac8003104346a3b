"""Installing the package: the README's two installs, in order, in one fresh environment.

A fresh virtual environment (its own site-packages; numpy, scipy, usd-core, Cython ... come
from the running interpreter's, so nothing is downloaded) gets a non-editable
``pip install .`` of a copy of the checkout's sources (which builds the kernels compiled
ahead of time into the installed package), runs ``usdhands synthesize`` and ``usdhands
splice`` (which compiles and caches numba kernels), then ``pip install -e .`` (the kernels
built again, in place) and ``usdhands --version``.
numba's own ``cache=True`` wrote ``.nbi``/``.nbc`` files into the installed package; the
uninstall left that folder behind and it then imported as an empty namespace package
(``ImportError: cannot import name '__version__'``).

Takes about 20-40 s (a venv, two installs, one kernel compilation).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _run(cmd, **kw) -> subprocess.CompletedProcess:
    out = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=300, **kw)
    assert out.returncode == 0, f"{' '.join(map(str, cmd))} failed:\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}"
    return out


def _venv_site_packages(venv: Path) -> Path:
    return Path(sysconfig.get_path("purelib", vars={"base": str(venv), "platbase": str(venv)}))


def _files_under(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()} if folder.exists() else set()


@pytest.mark.slow
def test_install_then_editable_install_keeps_a_working_command(tmp_path):
    pytest.importorskip("setuptools", minversion="77")  # the build backend, used without isolation
    # the kernels compiled at install need Cython (a build requirement) and a C compiler; without them
    # the install goes on without those kernels, which is what this test then checks
    compiler = importlib.util.find_spec("Cython") is not None and shutil.which(
        sysconfig.get_config_var("CC").split()[0] if sysconfig.get_config_var("CC") else "cc") is not None
    if os.environ.get("USDHANDS_REQUIRE_COMPILED") == "1":
        assert compiler, "CI installs Cython (the test extra) and has a C compiler"
    src = tmp_path / "src"
    shutil.copytree(ROOT / "usdhands", src / "usdhands",  # the sources only, as a fresh clone has them
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc", "*.egg-info", "*.so", "*.pyd", "*.c"))
    for name in ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "LICENSE"):
        if (ROOT / name).exists():
            shutil.copy2(ROOT / name, src / name)
    venv = tmp_path / "venv"
    # without pip (and the old setuptools ensurepip would put beside it): the running pip
    # installs into it with --python. The running interpreter's packages (setuptools, numpy,
    # usd-core...) are seen through a .pth file, not --system-site-packages: run from a virtual
    # environment, that option gives the base interpreter's packages (an old setuptools, no numpy)
    _run([sys.executable, "-m", "venv", "--without-pip", venv])
    bindir = venv / ("Scripts" if os.name == "nt" else "bin")
    python = bindir / "python"
    site = _venv_site_packages(venv)
    site.mkdir(parents=True, exist_ok=True)
    (site / "running_interpreter.pth").write_text("\n".join(_running_site_packages()) + "\n")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR")}
    env["USDHANDS_CACHE_DIR"] = str(tmp_path / "user-cache")
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    work = tmp_path / "work"  # not the checkout: its usdhands must not be on sys.path
    work.mkdir()
    pip = [sys.executable, "-m", "pip", "--python", python, "install", "--quiet", "--no-deps", "--no-build-isolation"]

    _run(pip + [src], env=env, cwd=work)
    installed = site / "usdhands"
    assert (installed / "__init__.py").is_file()
    files_before = _files_under(installed)
    where = _run([python, "-c", "import usdhands; print(usdhands.__file__)"], env=env, cwd=work).stdout.strip()
    assert Path(where).resolve() == (installed / "__init__.py").resolve()
    if compiler:  # the install built the kernels compiled ahead of time, into the installed package
        assert _run([python, "-c", BUILT], env=env, cwd=work).stdout.split() == [str(installed)] * KERNELS

    sample = ROOT / "sample_assets" / "conversation_bodyonly.bvh"
    out = _run([bindir / "usdhands", "synthesize", sample, "-o", work / "out.bvh"], env=env, cwd=work)
    assert (work / "out.bvh").is_file(), out.stdout
    # a synthesis this small searches in NumPy; splicing compiles its numba kernels
    out = _run([bindir / "usdhands", "splice", sample, ROOT / "sample_assets" / "conversation.glb",
                "-o", work / "spliced.bvh"], env=env, cwd=work)
    assert (work / "spliced.bvh").is_file(), out.stdout
    written = sorted(_files_under(installed) - files_before)
    # compiled Python (.pyc) is the interpreter's business; anything else is ours
    assert [f for f in written if not f.endswith(".pyc")] == []
    cached = _files_under(tmp_path / "user-cache")
    assert any(f.endswith(".nbi") for f in cached) and any(f.endswith(".nbc") for f in cached), cached

    _run(pip + ["-e", src], env=env, cwd=work)
    assert not installed.exists() or _files_under(installed) == set(), sorted(_files_under(installed))[:10]
    version = _run([bindir / "usdhands", "--version"], env=env, cwd=work).stdout.strip()
    assert version == f"usdhands {_package_version()}"
    where = _run([python, "-c", "import usdhands; print(usdhands.__file__)"], env=env, cwd=work).stdout.strip()
    assert Path(where).resolve() == (src / "usdhands" / "__init__.py").resolve()
    if compiler:  # built again, in place
        assert _run([python, "-c", BUILT], env=env, cwd=work).stdout.split() == [str(src / "usdhands")] * KERNELS


#: How many kernel modules are compiled ahead of time (usdhands.compiled.KERNEL_MODULES)
KERNELS = len(__import__("usdhands.compiled", fromlist=["KERNEL_MODULES"]).KERNEL_MODULES)
#: Prints, for each kernel module compiled ahead of time, the package folder it was loaded from
BUILT = ("from pathlib import Path\n"
         "from usdhands.compiled import KERNEL_MODULES, kernel_module\n"
         "for name in KERNEL_MODULES:\n"
         "    m = kernel_module(name)\n"
         "    print(Path(m.__file__).parents[name.count('.')].resolve() if m else None)\n")


def _running_site_packages() -> list[str]:
    """The folders the running interpreter imports installed packages from (its venv's, or the global ones)."""
    import site

    folders = [sysconfig.get_path("purelib"), sysconfig.get_path("platlib")] + site.getsitepackages()
    return list(dict.fromkeys(f for f in folders if Path(f).is_dir()))


def _package_version() -> str:
    for line in (ROOT / "pyproject.toml").read_text().splitlines():
        if line.startswith("version"):
            return line.split("=", 1)[1].strip().strip('"')
    raise AssertionError("no version in pyproject.toml")

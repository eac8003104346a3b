"""usdhands.jit: kernels cached in the user's cache folder, compilation reported to a listener."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from usdhands import jit

ROOT = Path(__file__).resolve().parent.parent

KERNEL = textwrap.dedent('''
    import sys
    from usdhands.jit import compile_listener, njit

    @njit
    def twice(x):
        return 2 * x

    heard = []
    with compile_listener(heard.append):
        value = twice(21)
    print(value, heard)
''')


def _run_kernel(tmp_path: Path, env_extra: dict) -> str:
    """Run KERNEL from a module file in tmp_path/mod in a fresh process; its stdout."""
    mod = tmp_path / "mod"
    mod.mkdir(exist_ok=True)
    (mod / "kernel_twice.py").write_text(KERNEL)
    env = {k: v for k, v in os.environ.items() if k not in ("USDHANDS_CACHE_DIR", "NUMBA_CACHE_DIR")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    env.update(env_extra)
    out = subprocess.run([sys.executable, str(mod / "kernel_twice.py")], capture_output=True, text=True,
                         env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_kernels_cache_in_the_user_folder_and_compile_once(tmp_path):
    cache = tmp_path / "cache"
    assert _run_kernel(tmp_path, {"USDHANDS_CACHE_DIR": str(cache)}) == "42 ['twice']"
    cached = sorted(p.name for p in (cache / "kernels").rglob("*") if p.is_file())
    assert any(n.startswith("kernel_twice.twice") and n.endswith(".nbi") for n in cached), cached
    assert not (tmp_path / "mod" / "__pycache__").exists() or not any(
        p.suffix in (".nbi", ".nbc") for p in (tmp_path / "mod" / "__pycache__").iterdir())
    # second run: loaded from the cache, no compilation heard
    assert _run_kernel(tmp_path, {"USDHANDS_CACHE_DIR": str(cache)}) == "42 []"


def test_unwritable_cache_compiles_in_memory_and_writes_nothing(tmp_path):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file where the cache folder would go")
    assert _run_kernel(tmp_path, {"USDHANDS_CACHE_DIR": str(blocker)}) == "42 ['twice']"
    assert _run_kernel(tmp_path, {"USDHANDS_CACHE_DIR": str(blocker)}) == "42 ['twice']"
    written = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.suffix in (".nbi", ".nbc"))
    assert written == []


@pytest.mark.parametrize("env,expected", [
    ({"USDHANDS_CACHE_DIR": "/x/uh", "NUMBA_CACHE_DIR": "/x/nb"}, "/x/uh/kernels"),
    ({"NUMBA_CACHE_DIR": "/x/nb"}, "/x/nb"),
    ({"XDG_CACHE_HOME": "/x/xdg"}, "/x/xdg/usdhands/kernels"),
])
def test_kernel_cache_dir_order(monkeypatch, env, expected):
    if sys.platform in ("win32", "darwin") and "XDG_CACHE_HOME" in env:
        pytest.skip("XDG_CACHE_HOME is the Linux location")
    for k in ("USDHANDS_CACHE_DIR", "NUMBA_CACHE_DIR", "XDG_CACHE_HOME"):
        monkeypatch.delenv(k, raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    assert jit.kernel_cache_dir() == Path(expected)


def test_default_cache_is_under_the_home_cache_on_linux(monkeypatch):
    if sys.platform != "linux":
        pytest.skip("Linux location")
    for k in ("USDHANDS_CACHE_DIR", "NUMBA_CACHE_DIR", "XDG_CACHE_HOME"):
        monkeypatch.delenv(k, raising=False)
    assert jit.kernel_cache_dir() == Path.home() / ".cache" / "usdhands" / "kernels"


def test_compile_listener_does_not_import_numba():
    code = ("import sys; from usdhands.jit import compile_listener\n"
            "with compile_listener(print):\n    pass\n"
            "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert out.stdout.strip() == "False", out.stderr

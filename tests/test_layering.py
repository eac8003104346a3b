"""The layering rules of DESIGN.md as checked facts, and the library's lint."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parent.parent / "usdhands"


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module)
    return out


@pytest.mark.parametrize("layer,forbidden", [
    ("model", ("pxr", "pygltflib", "usdhands.algorithms", "usdhands.formats", "usdhands.jobs", "usdhands.commands",
               "usdhands.pipeline", "matplotlib", "trimesh")),
    ("algorithms", ("pxr", "pygltflib", "usdhands.formats", "usdhands.jobs", "usdhands.commands", "usdhands.cli",
                    "usdhands.pipeline")),
    ("formats", ("usdhands.commands", "usdhands.cli", "usdhands.jobs", "usdhands.algorithms")),
    ("jobs", ("pxr", "pygltflib", "usdhands.commands", "usdhands.cli")),
])
def test_layer_imports_only_layers_below(layer, forbidden):
    bad = []
    for path in sorted((PKG / layer).rglob("*.py")):
        for mod in imported_modules(path):
            if any(mod == f or mod.startswith(f + ".") for f in forbidden):
                bad.append(f"{path.relative_to(PKG.parent)} imports {mod}")
    assert bad == []


#: every command: they parse, call a job and print (usd_plugin calls the schema plugin's registration)
JOB_COMMANDS = tuple(sorted(p.stem for p in (PKG / "commands").glob("*.py")
                            if p.stem not in ("__init__", "_common", "usd_plugin")))


def test_every_command_is_backed_by_a_job():
    assert {"synthesize", "correct", "evaluate", "db", "inspect", "handmap", "samples", "batch"} <= set(JOB_COMMANDS)


@pytest.mark.parametrize("command", JOB_COMMANDS)
def test_job_commands_only_parse_call_a_job_and_print(command):
    mods = imported_modules(PKG / "commands" / f"{command}.py")
    assert any(m.startswith("usdhands.jobs.") for m in mods)
    assert sorted(m for m in mods if m.startswith(("usdhands.algorithms", "usdhands.formats", "pxr"))) == []


def test_no_command_imports_the_algorithms():
    """Every command, job-backed or not, reaches the methods through a job (usdhands/jobs)."""
    bad = [f"{path.name} imports {m}" for path in sorted((PKG / "commands").glob("*.py"))
           for m in imported_modules(path) if m == "usdhands.algorithms" or m.startswith("usdhands.algorithms.")]
    assert bad == []


def test_algorithms_are_rooms_by_method():
    """algorithms/ holds one room per paper and the shared DTW beside them, no flat modules."""
    algorithms = PKG / "algorithms"
    flat = sorted(p.name for p in algorithms.glob("*.py") if p.name not in ("__init__.py", "dtw.py"))
    assert flat == []
    rooms = {p.name for p in algorithms.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert {"synthesis", "splicing", "reduction"} <= rooms


def test_pxr_and_pygltflib_only_where_allowed():
    allowed_pxr = ("formats/usd", "pipeline/", "commands/")
    bad = []
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG).as_posix()
        mods = imported_modules(path)
        if any(m == "pxr" or m.startswith("pxr.") for m in mods) and not rel.startswith(allowed_pxr):
            bad.append(f"{rel} imports pxr")
        if "pygltflib" in mods and not rel.startswith("formats/gltf"):
            bad.append(f"{rel} imports pygltflib")
    assert bad == []


def test_importing_usdhands_imports_neither_pxr_nor_pygltflib():
    code = ("import sys, usdhands, usdhands.model, usdhands.algorithms, usdhands.formats, usdhands.cli; "
            "print(sorted(m for m in ('pxr', 'pygltflib', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_importing_usdhands_and_its_command_line_loads_neither_numpy_nor_the_model():
    """``import usdhands`` (which ``python -m usdhands`` and the console script run first) loads its names
    on first use, so that a command loads only what it uses; every name and subpackage still resolves, an
    unknown one does not."""
    code = ("import sys, usdhands, usdhands.cli\n"
            "print(sorted(m for m in ('numpy', 'usdhands.model', 'usdhands.formats', 'usdhands.jobs.synthesis')"
            " if m in sys.modules))\n"
            "from usdhands import Clip\n"
            "print([Clip.__module__, usdhands.read_clip.__module__, usdhands.detect_hands.__module__, usdhands.FINGERS[0],"
            " usdhands.SynthesizeOptions.__module__, usdhands.formats.io.__name__, hasattr(usdhands, 'no_such_name')])\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.splitlines() == [
        "[]", "['usdhands.model.clip', 'usdhands.formats.io', 'usdhands.model.hand_detection', 'thumb', "
        "'usdhands.jobs.synthesis', 'usdhands.formats.io', False]"]


def test_ruff_clean():
    ruff = shutil.which("ruff")
    if ruff is None:
        pytest.skip("ruff is not installed (pip install -e '.[test]')")
    root = PKG.parent
    out = subprocess.run([ruff, "check", "usdhands", "tests", "benchmarks"], cwd=root,
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stdout


def test_numba_only_through_usdhands_jit():
    """Kernels compile through usdhands.jit.njit, which caches them in the user's cache folder:
    numba's own cache=True writes into the installed package (issue 9)."""
    bad = [path.relative_to(PKG).as_posix() for path in sorted(PKG.rglob("*.py"))
           if path.name != "jit.py" and any(m == "numba" or m.startswith("numba.") for m in imported_modules(path))]
    assert bad == []

"""The format registry: handlers found by extension, extended by entry points and at run time."""

from __future__ import annotations

import sys
import textwrap

import numpy as np
import pytest

from usdhands.errors import AssetReadError, OutputPathError
from usdhands.formats import registry
from usdhands.formats.io import read_asset, read_clip, write_asset


@pytest.fixture
def fresh_registry(monkeypatch):
    """A registry whose additions vanish after the test."""
    monkeypatch.setattr(registry, "_extra", [])
    monkeypatch.setattr(registry, "_outside", None)
    yield registry
    registry._outside = None


def test_builtins_by_extension_any_case():
    assert registry.handler_for("a.USDZ").name == "usd"
    assert registry.handler_for("a.glb").name == "gltf"
    assert registry.handler_for("a.Bvh", "write").name == "bvh"
    with pytest.raises(OutputPathError) as e:
        registry.handler_for("a.usdz", "write")  # USD packages are read, not written
    assert str(e.value) == "a.usdz: unknown file extension '.usdz'; writable: .bvh, .glb, .gltf, .usd, .usda, .usdc"
    with pytest.raises(AssetReadError) as e:
        registry.handler_for("notes.txt")
    assert str(e.value).startswith("notes.txt: unknown file extension '.txt'; readable: .bvh, .glb, .gltf, .usd,")


@pytest.mark.parametrize("fmt", registry.BUILTIN_FORMATS, ids=lambda f: f.name)
def test_builtin_extensions_are_the_handlers_own(fmt):
    """The registry lists the built-ins' extensions so it need not import them; the lists must agree."""
    h = fmt.load()
    assert (h.name, h.read_extensions, h.write_extensions) == (fmt.name, fmt.read_extensions, fmt.write_extensions)


@pytest.mark.parametrize("name,expected", [
    ("conversation_bodyonly.bvh", []),
    ("conversation_bodyonly.glb", ["pygltflib"]),
    ("conversation_bodyonly.usdc", ["pxr"]),
])
def test_reading_a_file_imports_only_its_format_library(name, expected):
    """The registry imported every handler (pxr: 0.2 s) on the first lookup, even for a BVH file."""
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    code = (f"import sys, usdhands; usdhands.read_clip({str(root / 'sample_assets' / name)!r}); "
            "print(sorted(m for m in ('pxr', 'pygltflib', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == str(expected)


PLUGIN = '''
import json
import numpy as np
from pathlib import Path
from usdhands.model.asset import Asset
from usdhands.model.clip import Clip
from usdhands.model.skeleton import Skeleton


class JsonRig:
    """A toy format: {"names": [...], "parents": [...], "offsets": [[x,y,z]...], "fps": f, "quats": [...]}"""

    name = "jsonrig"
    read_extensions = (".rig",)
    write_extensions = (".rig",)

    def read(self, path, *, fps=None):
        d = json.loads(Path(path).read_text())
        sk = Skeleton(d["names"], d["parents"], d["offsets"], np.tile([0, 0, 0, 1.0], (len(d["names"]), 1)),
                      name=Path(path).stem)
        return Asset(str(path), (sk,), (Clip(sk, d["fps"], d["quats"], name="take"),))

    def write(self, asset, path, **options):
        sk, clip = asset.skeletons[0], asset.clips[0]
        Path(path).write_text(json.dumps({"names": list(sk.joint_names), "parents": sk.parents.tolist(),
                                          "offsets": sk.rest_translations.tolist(), "fps": clip.fps,
                                          "quats": clip.rotations.tolist()}))

    def write_clip(self, source, clip, path, **options):
        raise NotImplementedError


def make():
    return JsonRig()
'''


def test_entry_point_group_adds_a_format(fresh_registry, tmp_path, monkeypatch):
    (tmp_path / "usdhands_jsonrig.py").write_text(textwrap.dedent(PLUGIN))
    dist = tmp_path / "usdhands_jsonrig-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: usdhands-jsonrig\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[usdhands.formats]\njsonrig = usdhands_jsonrig:make\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "usdhands_jsonrig", raising=False)
    assert "jsonrig" in fresh_registry.handlers()  # a factory is called once
    assert fresh_registry.handler_for("x.rig").name == "jsonrig"

    src = tmp_path / "arm.rig"
    q = np.tile([0, 0, np.sin(0.25), np.cos(0.25)], (3, 2, 1))
    src.write_text('{"names": ["root", "tip"], "parents": [-1, 0], "offsets": [[0, 0, 0], [0, 1, 0]], '
                   f'"fps": 25, "quats": {q.tolist()}}}')
    clip = read_clip(src)  # through the same read_asset as every built-in format
    np.testing.assert_allclose(clip.world_positions()[0, 1], [-np.sin(0.5), np.cos(0.5), 0], atol=1e-12)
    # and converted to a built-in format and back
    usd = write_asset(read_asset(src), tmp_path / "arm.usda")
    out = write_asset(read_asset(usd), tmp_path / "back.rig")
    np.testing.assert_allclose(read_clip(out).world_positions(), clip.world_positions(), atol=1e-6)


def test_register_handler_takes_precedence(fresh_registry):
    class Shadow:
        name = "shadow-bvh"
        read_extensions = (".bvh",)
        write_extensions = ()

        def read(self, path, *, fps=None):
            raise AssetReadError("shadowed", path=path)

    fresh_registry.register_handler(Shadow())
    assert fresh_registry.handler_for("a.bvh").name == "shadow-bvh"
    assert fresh_registry.handler_for("a.bvh", "write").name == "bvh"

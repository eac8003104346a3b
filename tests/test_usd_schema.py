"""The usdHands codeless schema plugin: shipped files, registration order, what USD knows of it.

USD builds its schema registry once per process, so every check that registers runs in
a fresh subprocess where the order of events is the test's.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from usdhands.pipeline.usd_plugin import plugin_path

ROOT = Path(__file__).resolve().parent.parent


def run_python(code: str, env_extra: dict | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.pop("PXR_PLUGINPATH_NAME", None)
    env.update(env_extra or {})
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                          cwd=ROOT)


def test_plugin_files_ship_in_the_package():
    folder = plugin_path()
    assert folder == ROOT / "usdhands" / "plugin" / "usdHands" / "resources"
    text = (folder / "plugInfo.json").read_text()
    assert "@PLUG_INFO" not in text
    info = json.loads(text[text.index("{"):])
    (plugin,) = info["Plugins"]
    assert plugin["Name"] == "usdHands" and plugin["Type"] == "resource"
    assert plugin["ResourcePath"] == "." and plugin["Root"] == "." and "LibraryPath" not in plugin
    assert set(plugin["Info"]["Types"]) == {"UsdHandsHandMapAPI", "UsdHandsFingerMotionAPI"}
    assert (folder / "generatedSchema.usda").is_file()


def test_import_does_not_import_pxr_or_register():
    out = run_python("""
        import sys
        from usdhands.pipeline.usd_plugin import plugin_path
        import usdhands, usdhands.formats.io
        print(plugin_path().is_dir(), "pxr" in sys.modules)
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "False"]


def test_register_is_explicit_idempotent_and_schemas_apply():
    out = run_python("""
        from pxr import Plug
        from usdhands.pipeline import usd_plugin
        assert Plug.Registry().GetPluginWithName("usdHands") is None   # importing registered nothing
        print(usd_plugin.register(), usd_plugin.register(), usd_plugin.is_registered())
        from pxr import Sdf, Usd
        reg = Usd.SchemaRegistry()
        hand = Usd.SchemaRegistry.GetTypeFromSchemaTypeName("UsdHandsHandMapAPI")
        motion = Usd.SchemaRegistry.GetTypeFromSchemaTypeName("UsdHandsFingerMotionAPI")
        print(Usd.SchemaRegistry.IsMultipleApplyAPISchema(hand), Usd.SchemaRegistry.IsAppliedAPISchema(motion),
              Usd.SchemaRegistry.IsMultipleApplyAPISchema(motion))
        stage = Usd.Stage.CreateInMemory()
        skel = stage.DefinePrim("/Skel", "Skeleton")
        anim = stage.DefinePrim("/Anim", "SkelAnimation")
        mesh = stage.DefinePrim("/Mesh", "Mesh")
        can = lambda prim, *a: bool(prim.CanApplyAPI(*a))  # noqa: E731 (a result object that may carry a reason)
        print(can(skel, hand, "left"), can(skel, hand, "right"), can(skel, hand, "middle"), can(mesh, hand, "left"))
        print(can(anim, motion), can(skel, motion), can(mesh, motion))
        assert skel.ApplyAPI(hand, "left") and anim.ApplyAPI(motion)
        print(skel.HasAPI(hand, "left"), skel.HasAPI(hand, "right"))
        wrist = skel.GetAttribute("usdhands:hand:left:wrist")
        thumb = skel.GetAttribute("usdhands:hand:left:thumb")
        print(bool(wrist), str(wrist.GetTypeName()), str(thumb.GetTypeName()),
              bool(skel.GetAttribute("usdhands:hand:right:wrist")))
        method = anim.GetAttribute("usdhands:fingerMotion:method")
        print(method.Get(), list(method.GetMetadata("allowedTokens")),
              str(anim.GetAttribute("usdhands:fingerMotion:database").GetTypeName()))
    """)
    assert out.returncode == 0, out.stderr
    lines = [ln.split() for ln in out.stdout.strip().splitlines()]
    assert lines[0] == ["True", "False", "True"]
    assert lines[1] == ["True", "True", "False"]
    assert lines[2] == ["True", "True", "False", "False"]
    assert lines[3] == ["True", "True", "False"]
    assert lines[4] == ["True", "False"]
    assert lines[5] == ["True", "token", "token[]", "False"]
    assert lines[6][0] == "none" and "synthesis" in out.stdout and lines[6][-1] == "string"


def test_plugin_path_on_pxr_pluginpath_name():
    out = run_python("""
        from pxr import Usd
        from usdhands.pipeline import usd_plugin
        print(Usd.SchemaRegistry().FindAppliedAPIPrimDefinition("UsdHandsFingerMotionAPI") is not None,
              usd_plugin.register())
    """, {"PXR_PLUGINPATH_NAME": str(plugin_path())})
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "False"]


def test_register_after_schema_registry_use_is_refused():
    out = run_python("""
        from pxr import Usd
        Usd.Stage.CreateInMemory().DefinePrim("/Skel", "Skeleton")
        Usd.SchemaRegistry().FindAppliedAPIPrimDefinition("SkelBindingAPI")
        from usdhands.pipeline import usd_plugin
        try:
            usd_plugin.register()
        except RuntimeError as e:
            print(e)
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == (
        "the usdHands plugin was registered after USD's schema registry was first used, so its schemas are "
        "unknown in this process: call usdhands.pipeline.usd_plugin.register() before opening any stage, or "
        f"set PXR_PLUGINPATH_NAME={plugin_path()}")


@pytest.mark.skipif(importlib.util.find_spec("jinja2") is None, reason="usdGenSchema needs jinja2")
def test_generated_files_match_the_schema_source():
    out = subprocess.run([sys.executable, str(ROOT / "schemas" / "generate_plugin.py"), "--check"],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.strip() == "up to date"


def test_authored_hand_map_is_the_registered_schema():
    out = run_python("""
        from usdhands.pipeline import usd_plugin
        usd_plugin.register()
        from pxr import Usd, UsdSkel
        from usdhands.formats.usd_schema_data import write_finger_motion, write_hand_map, read_hand_map
        from usdhands.model.handmap import HandMap, HandSide
        stage = Usd.Stage.CreateInMemory()
        skel = UsdSkel.Skeleton.Define(stage, "/Skel")
        skel.CreateJointsAttr().Set(["Hips", "Hips/Hand_R", "Hips/Hand_R/Thumb1"])
        write_hand_map(skel.GetPrim(), HandMap(right=HandSide("right", wrist="Hand_R",
                                                              fingers={"thumb": ("Thumb1",)})))
        anim = UsdSkel.Animation.Define(stage, "/Anim").GetPrim()
        write_finger_motion(anim, "reduction", parameters={"range_deg": 5})
        hand = Usd.SchemaRegistry.GetTypeFromSchemaTypeName("UsdHandsHandMapAPI")
        motion = Usd.SchemaRegistry.GetTypeFromSchemaTypeName("UsdHandsFingerMotionAPI")
        prim = skel.GetPrim()
        print(prim.HasAPI(hand, "right"), prim.HasAPI(hand, "left"), anim.HasAPI(motion))
        # every authored property is one the schema defines, with the schema's type
        defn = Usd.SchemaRegistry().FindAppliedAPIPrimDefinition("UsdHandsHandMapAPI")
        names = [n.replace("__INSTANCE_NAME__", "right") for n in defn.GetPropertyNames()]
        authored = [a.GetName() for a in prim.GetAuthoredAttributes() if a.GetName().startswith("usdhands:")]
        print(sorted(authored) == sorted(names),
              all(prim.GetAttribute(n).GetTypeName() == defn.GetSchemaAttributeSpec(
                  n.replace("right", "__INSTANCE_NAME__")).typeName for n in authored))
        print(read_hand_map(prim).right.fingers["thumb"])
    """)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert lines == ["True False True", "True True", "('Hips/Hand_R/Thumb1',)"]


def test_command_prints_the_plugin_folder():
    out = run_python("""
        from usdhands.cli import main
        raise SystemExit(main(["usd-plugin", "--check"]))
    """)
    assert out.returncode == 0, out.stderr
    assert out.stdout == f"{plugin_path()}\n"
    assert out.stderr.splitlines() == ["usdHands plugin registered now",
                                       "  UsdHandsHandMapAPI: multiple-apply API schema",
                                       "  UsdHandsFingerMotionAPI: single-apply API schema"]

"""``usdhands usd-plugin [--check]``: where the usdHands USD schema plugin is."""

from __future__ import annotations

import sys

from usdhands.pipeline.usd_plugin import FINGER_MOTION_API, HAND_MAP_API, plugin_path


def register(sub) -> None:
    p = sub.add_parser("usd-plugin", help="print the USD schema plugin folder (for PXR_PLUGINPATH_NAME)",
                       description="Print the folder of the usdHands codeless USD schema plugin, for "
                                   "PXR_PLUGINPATH_NAME: export PXR_PLUGINPATH_NAME=$(usdhands usd-plugin). "
                                   "With --check, also register it in this process and report what USD knows.")
    p.add_argument("--check", action="store_true", help="register the plugin and list the schemas USD knows")
    p.set_defaults(func=run)


def run(args) -> int:
    print(plugin_path())
    if args.check:
        from usdhands.pipeline import usd_plugin

        new = usd_plugin.register()
        from pxr import Usd

        how = "registered now" if new else "already registered (PXR_PLUGINPATH_NAME)"
        print(f"usdHands plugin {how}", file=sys.stderr)
        for name in (HAND_MAP_API, FINGER_MOTION_API):
            t = Usd.SchemaRegistry.GetTypeFromSchemaTypeName(name)
            kind = "multiple-apply" if Usd.SchemaRegistry.IsMultipleApplyAPISchema(t) else "single-apply"
            print(f"  {name}: {kind} API schema", file=sys.stderr)
    return 0

"""The usdHands codeless USD schema plugin: where it is, and registering it.

The plugin (``usdhands/plugin/usdHands/resources``: ``plugInfo.json`` and
``generatedSchema.usda``, generated from ``schemas/usdhands_schema.usda``) defines two
applied API schemas:

- ``UsdHandsHandMapAPI`` (multiple-apply, instances ``left`` and ``right``, on Skeleton
  prims): which joints are the hand — ``usdhands:hand:<side>:wrist``, ``forearm``,
  ``shoulder``, ``root`` (tokens) and ``thumb``, ``index``, ``middle``, ``ring``,
  ``pinky`` (token arrays, proximal to distal);
- ``UsdHandsFingerMotionAPI`` (on SkelAnimation or Skeleton prims): how the finger
  motion was made — ``usdhands:fingerMotion:method``, ``database``, ``parameters``
  (JSON), ``version``.

USD builds its schema registry once, the first time anything asks for it, so the
plugin must be known before that. Two ways, neither a side effect of importing
usdhands:

- the host puts :func:`plugin_path` on ``PXR_PLUGINPATH_NAME`` before USD starts
  (``export PXR_PLUGINPATH_NAME=$(python -c "from usdhands.pipeline.usd_plugin import
  plugin_path; print(plugin_path())")``); :func:`plugin_path` does not import ``pxr``;
- the host calls :func:`register` early, before any stage is opened.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["PLUGIN_NAME", "HAND_MAP_API", "FINGER_MOTION_API", "plugin_path", "register", "is_registered"]

PLUGIN_NAME = "usdHands"
HAND_MAP_API = "UsdHandsHandMapAPI"
FINGER_MOTION_API = "UsdHandsFingerMotionAPI"


def plugin_path() -> Path:
    """The folder holding the plugin's ``plugInfo.json`` (for ``PXR_PLUGINPATH_NAME``).

    Found from this package's files; does not import ``pxr``.
    """
    return Path(__file__).resolve().parent.parent / "plugin" / "usdHands" / "resources"


def is_registered() -> bool:
    """Whether USD's plugin registry knows the usdHands plugin (imports ``pxr``)."""
    from pxr import Plug

    return Plug.Registry().GetPluginWithName(PLUGIN_NAME) is not None


def register() -> bool:
    """Register the plugin with USD; safe to call any number of times.

    Returns
    -------
    bool
        True when this call registered it, False when USD already knew it (an earlier
        call, or ``PXR_PLUGINPATH_NAME``).

    Raises
    ------
    RuntimeError
        The plugin is registered but USD's schema registry was built before it was,
        so it does not know the schemas: call :func:`register` before any stage is
        opened, or use ``PXR_PLUGINPATH_NAME``.
    """
    from pxr import Plug, Usd

    registry = Plug.Registry()
    new = registry.GetPluginWithName(PLUGIN_NAME) is None
    if new:
        registry.RegisterPlugins(str(plugin_path()))
        if registry.GetPluginWithName(PLUGIN_NAME) is None:
            raise RuntimeError(f"USD did not register the plugin at {plugin_path()}")
    if Usd.SchemaRegistry().FindAppliedAPIPrimDefinition(HAND_MAP_API) is None:
        raise RuntimeError(
            "the usdHands plugin was registered after USD's schema registry was first used, so its "
            "schemas are unknown in this process: call usdhands.pipeline.usd_plugin.register() before "
            f"opening any stage, or set PXR_PLUGINPATH_NAME={plugin_path()}")
    return new

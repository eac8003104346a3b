"""The hand map of a skeleton read from a file: override, recorded in the file, or detected."""

from __future__ import annotations

import os
from pathlib import Path

from usdhands.errors import NoHandsError
from usdhands.formats.registry import handler_for
from usdhands.model.hand_detection import detect_hands, load_handmap, side_from_name
from usdhands.model.handmap import HandMap
from usdhands.model.skeleton import Skeleton

__all__ = ["hands_for", "recorded_handmap"]


def recorded_handmap(path: str | os.PathLike, skeleton: Skeleton) -> HandMap | None:
    """The hand map ``path`` records for ``skeleton``, or None.

    USD files record hand maps on Skeleton prims through the ``UsdHandsHandMapAPI``
    schema (``skeleton.name`` is the prim path); other formats record none.
    """
    path = Path(path)
    if handler_for(path, "read").name != "usd":
        return None
    from usdhands.formats.usd_schema_data import read_hand_maps

    return read_hand_maps(path).get(skeleton.name)


def hands_for(path: str | os.PathLike, skeleton: Skeleton, override: str | os.PathLike | None = None,
              side_hint: str | None = None) -> tuple[HandMap, str]:
    """The hand map to use for ``skeleton`` of the file ``path``.

    In order: the JSON ``override`` when given; the hand map recorded in the file (USD
    ``UsdHandsHandMapAPI``); else :func:`~usdhands.model.hand_detection.detect_hands`,
    with ``side_hint`` or, failing that, the side the file name says (``left.glb``).

    Returns
    -------
    (HandMap, str)
        The map and where it came from: ``"override"``, ``"file"`` or ``"detected"``.

    Raises
    ------
    ConfigError
        A bad override file, or a recorded map naming joints the skeleton lacks.
    NoHandsError
        Detection found no hand; carries ``path``.
    """
    if override is not None:
        return load_handmap(override, skeleton), "override"
    recorded = recorded_handmap(path, skeleton)
    if recorded is not None:
        return recorded, "file"
    hint = side_hint or side_from_name(Path(path).name)
    try:
        return detect_hands(skeleton, side_hint=hint), "detected"
    except NoHandsError as e:
        raise NoHandsError(e.message, path=path) from None

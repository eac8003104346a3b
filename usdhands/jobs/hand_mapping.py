"""The handmap job: the hands of a skeleton (a hand map), written as JSON or authored on a USD Skeleton.

Finds the wrist, forearm, shoulder, root and five finger chains of each hand: from the
hand map JSON given, the map a USD file records (``UsdHandsHandMapAPI``), or detection by
joint names. Writes them as a hand map JSON (schemas/handmap.schema.json) and, for USD, onto
the Skeleton prim as ``UsdHandsHandMapAPI`` in a copy of the file or a sparse layer over it.

::

    from usdhands.jobs.hand_mapping import HandMapOptions, map_hands

    result = map_hands("take.usda", "take_hands.json")
    print(result.source, result.handmap.left.wrist)
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from usdhands.errors import AssetReadError, NoSkeletonError, UsdHandsError


@dataclass(frozen=True)
class HandMapOptions:
    """Options of :func:`map_hands`; the defaults are ``usdhands handmap``'s.

    Attributes
    ----------
    animation : str or None
        Use the skeleton of this animation (name or 0-based index); default the first skeleton.
    skeleton : str or None
        Skeleton name or 0-based index (files with several).
    side : str or None
        ``"left"`` or ``"right"``: the side of a single hand whose joint names give none (WebXR);
        default from the file name.
    handmap : Path or None
        Check this hand map JSON against the skeleton instead of detecting.
    as_layer : bool
        With ``schema_output``: a sparse USD layer over the input instead of a full copy.
    """

    animation: str | None = None
    skeleton: str | None = None
    side: str | None = None
    handmap: Path | None = None
    as_layer: bool = False


@dataclass(frozen=True)
class HandMapResult:
    """The hands found.

    Attributes
    ----------
    file : Path
    skeleton : str
        The skeleton's name.
    num_joints : int
    joint_names : tuple of str
    handmap : HandMap
    source : str
        ``"override"`` (the JSON given), ``"file"`` (recorded in the USD file) or ``"detected"``.
    written : tuple of Path
        The hand map JSON and the USD file written, if asked.
    """

    file: Path
    skeleton: str
    num_joints: int
    joint_names: tuple[str, ...]
    handmap: object
    source: str
    written: tuple[Path, ...] = field(default=())

    def to_json(self) -> dict:
        """The ``usdhands handmap --json`` report (the JSON file's content, with the file and the source)."""
        return {"file": str(self.file), "source": self.source, "num_joints": self.num_joints,
                **self.handmap_json()}

    def handmap_json(self) -> dict:
        """The hand map JSON (schemas/handmap.schema.json)."""
        return {"skeleton": self.skeleton, **self.handmap.to_dict()}


def map_hands(source: str | os.PathLike, output: str | os.PathLike | None = None,
              options: HandMapOptions = HandMapOptions(),
              schema_output: str | os.PathLike | None = None) -> HandMapResult:
    """The hands of a skeleton of ``source``; the hand map JSON written to ``output`` and, for
    USD, ``UsdHandsHandMapAPI`` authored in a copy of ``source`` (or a layer over it) at ``schema_output``.

    Raises
    ------
    UsdHandsError
        Unreadable file, no skeleton, no hand found, bad outputs (checked before any work).
    """
    from usdhands.formats.hands import hands_for
    from usdhands.formats.io import read_asset
    from usdhands.formats.registry import atomic_output
    from usdhands.jobs.outputs import MAIN_INPUT, check_paths

    source = Path(source)
    output = None if output is None else Path(output)
    schema_output = None if schema_output is None else Path(schema_output)
    check_paths({MAIN_INPUT: source, "--handmap": options.handmap}, {"-o": output, "--write-schema": schema_output})
    if schema_output is not None:
        _check_schema_output(source, schema_output, options.as_layer)
    elif options.as_layer:
        raise UsdHandsError("--as-layer goes with --write-schema OUT", path=source)
    asset = read_asset(source)
    sk = _pick_skeleton(asset, source, options.animation, options.skeleton)
    hm, where = hands_for(source, sk, options.handmap, side_hint=options.side)
    result = HandMapResult(source, sk.name, sk.num_joints, tuple(sk.joint_names), hm, where)
    written = []
    if output is not None:
        with atomic_output(output) as tmp:
            tmp.write_text(json.dumps(result.handmap_json(), indent=2) + "\n", encoding="utf-8")
        written.append(output)
    if schema_output is not None:
        from usdhands.formats.usd_write import write_usd_hand_map

        with atomic_output(schema_output) as tmp:
            write_usd_hand_map(source, sk.name, hm, tmp, final_path=schema_output, as_layer=options.as_layer)
        written.append(schema_output)
    return HandMapResult(source, sk.name, sk.num_joints, tuple(sk.joint_names), hm, where, tuple(written))


def _pick_skeleton(asset, path: Path, animation, skeleton):
    from usdhands.model.skeleton import short_joint_name

    if not asset.skeletons:
        raise NoSkeletonError("no skeleton in file", path=path)
    if animation is not None:
        try:
            return asset.clip(animation).skeleton
        except KeyError as e:
            raise AssetReadError(str(e.args[0]).split(": ", 1)[-1], path=path) from None
    if skeleton is None:
        return asset.skeletons[0]
    for i, sk in enumerate(asset.skeletons):
        if sk.name == skeleton or short_joint_name(sk.name) == skeleton or str(i) == str(skeleton):
            return sk
    names = ", ".join(repr(s.name) for s in asset.skeletons)
    raise AssetReadError(f"no skeleton named {skeleton!r}; there are {names}", path=path)


def _check_schema_output(source: Path, schema_output: Path, as_layer: bool) -> None:
    """``--write-schema`` needs USD in and out (checked before any work)."""
    from usdhands.jobs.outputs import USD_LAYER_SUFFIXES, layer_options

    if source.suffix.lower() not in USD_LAYER_SUFFIXES + (".usdz",):
        raise UsdHandsError("--write-schema needs a USD input (the schema is authored on its Skeleton prim)",
                            path=source)
    if schema_output.suffix.lower() not in USD_LAYER_SUFFIXES:
        raise UsdHandsError("--write-schema needs a USD output (.usd, .usda, .usdc)", path=schema_output)
    layer_options(as_layer, source, schema_output)

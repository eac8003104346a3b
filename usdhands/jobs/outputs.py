"""Output options and checks shared by the jobs and commands: ``as_layer`` (splice, reduce, expand, synthesize)
and :func:`check_paths`, which keeps every output off every input (every job and command)."""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Iterable, Mapping, Union

from usdhands.errors import AssetReadError, OutputPathError, UsdHandsError
from usdhands.formats.registry import check_output_path, same_file

#: the label of a command's main input(s) in :func:`check_paths`
MAIN_INPUT = "input"

#: one path, several (the files of a folder, nargs="*"), or None for an option not given
PathArg = Union[str, os.PathLike, Iterable[Union[str, os.PathLike]], None]


def each_path(value) -> list[Path]:
    """The paths of a check_paths value: None, one path, or several."""
    if value is None:
        return []
    if isinstance(value, (str, os.PathLike)):
        return [Path(value)]
    return [Path(v) for v in value if v is not None]


def _inside(path: Path, folder: Path) -> bool:
    """Whether ``path`` is ``folder`` or lies under it, as spelled or once symlinks are resolved."""
    if Path(os.path.abspath(path)).is_relative_to(os.path.abspath(folder)):
        return True
    try:
        return path.resolve().is_relative_to(folder.resolve())
    except (OSError, RuntimeError):  # a symlink loop
        return False


def check_paths(inputs: Mapping[str, PathArg], outputs: Mapping[str, PathArg] | None = None, *,
                replaced_folders: Mapping[str, PathArg] | None = None) -> None:
    """Refuse, before any work, inputs that cannot be read safely and outputs that would land on an input.

    Parameters
    ----------
    inputs : mapping label -> path, list of paths or None
        Every file or folder the command reads, side files included (hand maps,
        configs, models, label and marker CSVs, databases); label
        :data:`MAIN_INPUT` for the main input(s), else the option (``"--handmap"``).
    outputs : mapping label -> path or None
        Files the command writes (``"-o"``, ``"--model"``).
    replaced_folders : mapping label -> path or None
        Folders the command replaces whole (``db build -o DB``): they may neither be
        nor hold an input.

    Raises
    ------
    AssetReadError
        An input that exists and is neither a regular file nor a folder (a FIFO would
        block the read forever, a device such as ``/dev/zero`` never ends); missing
        inputs are left to the readers, which say so in their own words.
    OutputPathError
        An output that is an input or another output, by any spelling, symlink or
        hard link (:func:`~usdhands.formats.registry.same_file`); an output whose
        folder does not exist or that is a folder.
    """
    given = [(label, p) for label, value in inputs.items() for p in each_path(value)]
    for _, p in given:
        try:
            mode = os.stat(p).st_mode
        except OSError:  # missing or unreachable: the reader says which
            continue
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            raise AssetReadError("not a regular file", path=p)

    def refuse(out: Path, label: str, what: str = "file") -> OutputPathError:
        if label == MAIN_INPUT:
            return OutputPathError(f"output path equals the input; choose another {what}", path=out)
        return OutputPathError(f"output path equals the {label} file; choose another {what}", path=out)

    written: list[tuple[str, Path]] = []
    for label, value in (outputs or {}).items():
        for out in each_path(value):
            for other, p in given + written:
                if same_file(out, p):
                    raise refuse(out, other)
            check_output_path(out)
            written.append((label, out))
    for label, value in (replaced_folders or {}).items():
        for folder in each_path(value):
            for other, p in given + written:
                if same_file(folder, p):
                    raise refuse(folder, other, "folder")
                if _inside(p, folder):
                    raise OutputPathError(f"output folder holds {'an input' if other == MAIN_INPUT else other} "
                                          f"{str(p)!r}, and is replaced whole; choose another folder", path=folder)

USD_LAYER_SUFFIXES = (".usd", ".usda", ".usdc")


def layer_options(layer: bool, source: Path, output: Path) -> dict:
    """``write_clip`` options for ``--as-layer``; checked before any work.

    Raises
    ------
    UsdHandsError
        ``--as-layer`` with an input or an output that is not USD (a layer sublayers its
        input, so both must be USD; ``.usdz`` packages cannot hold a layer).
    """
    if not layer:
        return {}
    if Path(output).suffix.lower() not in USD_LAYER_SUFFIXES:
        raise UsdHandsError("--as-layer needs a USD output (.usd, .usda, .usdc)", path=output)
    if Path(source).suffix.lower() not in USD_LAYER_SUFFIXES + (".usdz",):
        raise UsdHandsError("--as-layer needs a USD input: the layer sublayers it", path=source)
    return {"as_layer": True}

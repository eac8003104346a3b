"""Output options shared by the commands that write an edited copy of their input (splice, reduce, expand)."""

from __future__ import annotations

from pathlib import Path

from usdhands.errors import UsdHandsError

USD_LAYER_SUFFIXES = (".usd", ".usda", ".usdc")


def add_layer_argument(parser, what: str = "the input") -> None:
    """Add ``--as-layer`` (alias ``--as-layer``) (a sparse USD override layer instead of a full copy) to a subcommand."""
    parser.add_argument("--as-layer", "--layer", dest="layer", action="store_true",
                        help=f"USD: write a sparse override layer over {what} instead of a full copy")


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

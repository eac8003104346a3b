"""Checks for the optional dependencies of the extras (``pip install "usdhands[plot]"``)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from usdhands.errors import UsdHandsError

__all__ = ["require_matplotlib"]


def require_matplotlib(folder: str | Path | None = None) -> None:
    """Refuse ``--plot`` in one line when matplotlib is not installed (checked without importing it).

    Raises
    ------
    UsdHandsError
        ``--plot needs matplotlib, which is not installed: pip install "usdhands[plot]"``.
    """
    missing = "matplotlib" in sys.modules and sys.modules["matplotlib"] is None
    if not missing and "matplotlib" not in sys.modules:
        missing = importlib.util.find_spec("matplotlib") is None
    if missing:
        raise UsdHandsError('--plot needs matplotlib, which is not installed: pip install "usdhands[plot]"',
                            path=folder)

"""Exceptions raised for bad assets and bad input.

Programming mistakes (wrong shapes, wrong types) raise :class:`ValueError` or
:class:`TypeError` quoting the actual value. Problems with a user's files raise a
subclass of :class:`UsdHandsError`, which carries the file and the prim, node or
joint it came from so the command line can print one clear line.
"""

from __future__ import annotations

from pathlib import Path


def one_line(text: str) -> str:
    """``text`` with control characters escaped (a file name holding a newline stays on one line)."""
    return "".join(c if c.isprintable() or c == " " else repr(c)[1:-1] for c in text)


class UsdHandsError(Exception):
    """Root of the project's errors about assets and user input.

    Parameters
    ----------
    message : str
        What is wrong, in one line.
    path : str or Path, optional
        The file the problem was found in.
    location : str, optional
        The prim path, node, joint or line inside the file.
    """

    def __init__(self, message: str, *, path: str | Path | None = None, location: str | None = None):
        self.message = message
        self.path = None if path is None else str(path)
        self.location = location
        super().__init__(self.__str__())

    def __str__(self) -> str:
        parts = []
        if self.path:
            parts.append(self.path)
        if self.location:
            parts.append(self.location)
        prefix = ": ".join(parts)
        return f"{prefix}: {self.message}" if prefix else self.message


class AssetReadError(UsdHandsError):
    """A file could not be read: missing, truncated, corrupt or of an unknown format."""


class NoSkeletonError(UsdHandsError):
    """A file holds no skeleton."""


class NoHandsError(UsdHandsError):
    """No hand (wrist and finger chains) could be found on a skeleton."""


class JointMismatchError(UsdHandsError):
    """An animation names joints the skeleton does not have, or arrays do not match."""


class InvalidAnimationError(UsdHandsError):
    """An animation holds NaN, zero-length quaternions or no frames."""


class OutputPathError(UsdHandsError):
    """An output path is not usable (equals the input, unknown extension, ...)."""


class ConfigError(UsdHandsError):
    """A configuration, hand map, model or database file is invalid."""


class UnsupportedRigError(UsdHandsError):
    """A rig the algorithms cannot handle as it is (mirrored joint frames from a negative scale, ...)."""

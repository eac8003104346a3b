"""The samples job: write the generated sample assets (humanoid, gesture database, conversation, cup).

Deterministic: the same options write the same bytes. See :mod:`usdhands.samples.generate`.

::

    from usdhands.jobs.sample_assets import SamplesOptions, write_samples

    result = write_samples("assets", SamplesOptions(formats=("gltf",)))
    print(len(result.files), result.total_bytes)
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable


@dataclass(frozen=True)
class SamplesOptions:
    """Options of :func:`write_samples`; the defaults are ``usdhands samples``'s.

    Attributes
    ----------
    formats : tuple of str
        Among ``"usd"``, ``"gltf"``, ``"bvh"``.
    layout : str
        ``"committed"``: the compact set of sample_assets/ (ground truth in .glb only);
        ``"full"``: every clip in every format (about 40 MB).
    seed : int
        Random seed of the variations (0: the committed set).
    """

    formats: tuple[str, ...] = ("usd", "gltf", "bvh")
    layout: str = "committed"
    seed: int = 0


@dataclass(frozen=True)
class SamplesResult:
    """The files written: ``files`` as ``(path relative to outdir, bytes)``."""

    outdir: Path
    files: tuple[tuple[str, int], ...]

    @property
    def total_bytes(self) -> int:
        return sum(n for _, n in self.files)

    def to_json(self) -> dict:
        """The ``usdhands samples --json`` report."""
        return {"outdir": str(self.outdir), "files": [{"path": p, "bytes": n} for p, n in self.files],
                "total_bytes": self.total_bytes}


def write_samples(outdir: str | os.PathLike, options: SamplesOptions = SamplesOptions(),
                  progress: Callable[[int, int, str], None] | None = None) -> SamplesResult:
    """Write the sample assets into ``outdir`` (made when missing; its parent must exist).

    Raises
    ------
    UsdHandsError
        No or an unknown format, a bad seed or layout, an ``outdir`` that cannot be a folder.
    """
    from usdhands.errors import OutputPathError, UsdHandsError
    from usdhands.jobs.option_checks import check_seed, parse_list
    from usdhands.samples.generate import FORMATS, generate_samples

    out = Path(outdir)
    check_seed(options.seed)
    formats = parse_list(",".join(options.formats), FORMATS)
    if not formats:
        raise OutputPathError("no format given; use --formats usd,gltf,bvh", path=out)
    if options.layout not in ("committed", "full"):
        raise UsdHandsError(f"layout must be 'committed' or 'full', got {options.layout!r}")
    if out.exists() and not out.is_dir():
        raise OutputPathError("exists and is not a folder", path=out)
    if not out.parent.resolve().is_dir():
        raise OutputPathError(f"parent folder {str(out.parent)!r} does not exist", path=out)
    try:
        out.mkdir(exist_ok=True)
    except OSError as e:
        raise OutputPathError(f"cannot create the folder: {e.strerror}", path=out) from None
    files = generate_samples(out, formats, options.layout, options.seed, progress=progress)
    return SamplesResult(out, tuple((f.relative_to(out).as_posix(), f.stat().st_size) for f in files))

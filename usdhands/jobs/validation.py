"""The check job: the ``usdhands check`` rules on USD, glTF and BVH files.

Rules (:data:`usdhands.model.findings.RULES`): ``hands`` (mapped or detectable),
``finger-coverage`` (an animation animates the finger joints of its skeleton),
``quaternions`` (no NaN or zero-length rotation), ``array-lengths`` (joint counts and
array lengths agree), ``provenance`` (finger-motion records well-formed; with
``require_provenance`` present wherever finger joints are animated). Each format's audit
lives beside its reader (:mod:`usdhands.formats.usd_audit`, ``gltf_audit``, ``bvh_audit``).

::

    import usdhands
    result = usdhands.check(["a.usda", "b.glb"])
    for finding in result.findings:
        print(finding)            # file: where: rule: message
    raise SystemExit(result.exit_status)

On an open stage: :func:`usdhands.usd.check_stage`; inside USD's own validation:
:func:`usdhands.pipeline.usd_validation.register_validators` (keyword ``usdhands``).

Adding a rule (``props``: fingers do not penetrate the props named with ``--props``, from
the interaction methods): a field on :class:`CheckOptions`, the rule's key in ``RULES``, and
a function ``(path, clip, options) -> list[Finding]`` called from :func:`_check_file` for
every readable file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from usdhands.errors import UsdHandsError
from usdhands.model.findings import Finding


@dataclass(frozen=True)
class CheckOptions:
    """Options of :func:`check`.

    Attributes
    ----------
    require_provenance : bool
        Every animation that animates finger joints must carry a finger-motion record
        (USD ``UsdHandsFingerMotionAPI``, glTF ``extras.usdhands.provenance``); without it,
        only the records that are there are checked.
    """

    require_provenance: bool = False


@dataclass(frozen=True)
class FileCheck:
    """One file's outcome: its findings, or the error that kept it from being read."""

    file: str
    findings: tuple[Finding, ...] = ()
    error: str | None = None

    @property
    def status(self) -> str:
        """``"ok"``, ``"failed"`` (a rule broken) or ``"unreadable"``."""
        return "unreadable" if self.error else ("failed" if self.findings else "ok")


@dataclass(frozen=True)
class CheckResult:
    """What :func:`check` found, per file."""

    files: tuple[FileCheck, ...]

    @property
    def findings(self) -> list[Finding]:
        return [f for fc in self.files for f in fc.findings]

    @property
    def exit_status(self) -> int:
        """2 when a file could not be read, else 1 when a rule failed, else 0."""
        if any(fc.error for fc in self.files):
            return 2
        return 1 if self.findings else 0

    def to_json(self) -> dict:
        """The ``usdhands check --json`` report."""
        return {
            "files": [{"file": fc.file, "status": fc.status, "findings": [f.to_json() for f in fc.findings],
                       **({"error": fc.error} if fc.error else {})} for fc in self.files],
            "checked": len(self.files),
            "failed": sum(fc.status == "failed" for fc in self.files),
            "unreadable": sum(fc.status == "unreadable" for fc in self.files),
            "findings": len(self.findings),
        }


def check(paths: Sequence[str | os.PathLike] | str | os.PathLike, options: CheckOptions = CheckOptions(),
          progress: Callable[[int, int, str], None] | None = None) -> CheckResult:
    """Check files against the rules; never raises for a bad file (it ends as ``unreadable``).

    Parameters
    ----------
    paths : path or sequence of paths
        ``.usd/.usda/.usdc/.usdz``, ``.gltf/.glb``, ``.bvh``.
    options : CheckOptions
    progress : callable, optional
        ``progress(done, total, what)``.
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    paths = [Path(p) for p in paths]
    out = []
    for i, p in enumerate(paths):
        try:
            out.append(FileCheck(str(p), tuple(_check_file(p, options))))
        except UsdHandsError as e:
            out.append(FileCheck(str(p), (), str(e)))
        if progress:
            progress(i + 1, len(paths), p.name)
    return CheckResult(tuple(out))


def check_usd_stage(stage, options: CheckOptions = CheckOptions()) -> list[Finding]:
    """The rules on an open ``Usd.Stage`` as it composes now (unsaved edits included)."""
    from usdhands.formats.usd_audit import audit_stage

    return audit_stage(stage, require_provenance=options.require_provenance)


def _check_file(path: Path, options: CheckOptions) -> list[Finding]:
    from usdhands.errors import AssetReadError
    from usdhands.formats.registry import handler_for

    if not path.is_file():
        raise AssetReadError("no such file" if not path.exists() else "not a file", path=path)
    kind = handler_for(path, "read").name
    if kind == "usd":
        from usdhands.formats.usd_audit import audit_usd

        return audit_usd(path, require_provenance=options.require_provenance)
    if kind == "gltf":
        from usdhands.formats.gltf_audit import audit_gltf

        return audit_gltf(path, require_provenance=options.require_provenance)
    from usdhands.formats.bvh_audit import audit_bvh

    return audit_bvh(path)

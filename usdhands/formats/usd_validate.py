"""Checking USD files with USD's own validators.

usd-core up to 24.x ships ``UsdUtils.ComplianceChecker`` (the engine of ``usdchecker``);
later releases replace it with the ``UsdValidation`` framework. :func:`usd_compliance_errors`
uses whichever the installed USD has.
"""

from __future__ import annotations

import os

from usdhands.formats.usd_common import quiet_diagnostics

__all__ = ["usd_compliance_errors"]


def usd_compliance_errors(path: str | os.PathLike) -> list[str]:
    """Errors USD's compliance checks report for a file (empty when it passes).

    Runs every registered validator (``UsdValidation``) but usdhands' own on the composed stage, or
    ``UsdUtils.ComplianceChecker`` on older USD. Warnings are not returned.
    """
    from pxr import Usd

    with quiet_diagnostics():
        try:
            from pxr.UsdUtils.complianceChecker import ComplianceChecker  # USD <= 24
        except ImportError:
            ComplianceChecker = None
        if ComplianceChecker is not None:
            checker = ComplianceChecker(rootPackageOnly=False, skipVariants=False, verbose=False)
            checker.CheckCompliance(str(path))
            return list(checker.GetErrors()) + list(checker.GetFailedChecks())
        from pxr import UsdValidation

        # USD's own and plugins' validators; not usdhands' rules (keyword "usdhands"), which
        # ``usdhands check`` runs and which a process may have registered
        validators = [v for v in UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
                      if "usdhands" not in v.GetMetadata().GetKeywords()]
        context = UsdValidation.ValidationContext(validators)
        stage = Usd.Stage.Open(str(path))
        errors = context.Validate(stage)
        return [f"{e.GetName()}: {e.GetMessage()}" for e in errors
                if e.GetType() == UsdValidation.ValidationErrorType.Error]

"""The ``usdhands check`` rules inside USD's own validation framework (``UsdValidation``, USD 24.11+).

USD 26 replaced ``UsdUtils.ComplianceChecker`` with ``UsdValidation``. Its registry takes
stage validators from Python at run time (``UsdValidationRegistry().RegisterStageValidator``
with a Python callable), which is what :func:`register_validators` does: one validator per
rule, named ``usdhands:<rule>``, keyword ``usdhands``. A studio's validation step then runs
them with the others::

    from pxr import Usd, UsdValidation
    from usdhands.pipeline.usd_validation import register_validators

    register_validators()
    errors = UsdValidation.ValidationContext(keywords=["usdhands"]).Validate(Usd.Stage.Open("shot.usda"))

A ``plugInfo.json`` can declare validators' metadata (``Validators`` section), but the task
function of a plugin validator is registered by the plugin's C++ library when USD loads it
(``RegisterPluginStageValidator``); a codeless or Python-only plugin has no code USD would
load, so usdhands registers from Python instead. Where the installed USD has no
``UsdValidation``, :func:`usdhands.usd.check_stage` is the function a pipeline's own
validation step calls.
"""

from __future__ import annotations

from usdhands.model.findings import RULES

#: keyword every usdhands validator carries
KEYWORD = "usdhands"
#: the rules that apply to a USD stage (``props`` needs props given on the command line)
STAGE_RULES = tuple(r for r in RULES if r != "props")


def validator_name(rule: str) -> str:
    return f"{KEYWORD}:{rule}"


def available() -> bool:
    """True when the installed USD has ``UsdValidation`` with Python-registered stage validators."""
    try:
        from pxr import UsdValidation
    except ImportError:
        return False
    return hasattr(UsdValidation.ValidationRegistry(), "RegisterStageValidator")


def register_validators(require_provenance: bool = False) -> list[str]:
    """Register one ``UsdValidation`` stage validator per rule (once per process); their names.

    Raises
    ------
    RuntimeError
        The installed USD has no ``UsdValidation`` (use :func:`usdhands.usd.check_stage`).
    """
    if not available():
        raise RuntimeError("this USD has no UsdValidation registry with Python stage validators; "
                           "call usdhands.usd.check_stage(stage) in the pipeline's validation step")
    from pxr import UsdValidation

    registry = UsdValidation.ValidationRegistry()
    names = []
    for rule in STAGE_RULES:
        name = validator_name(rule)
        names.append(name)
        if registry.HasValidator(name):
            continue
        metadata = UsdValidation.ValidatorMetadata(name=name, doc=RULES[rule], keywords=[KEYWORD], schemaTypes=[],
                                                   isTimeDependent=False, isSuite=False)
        registry.RegisterStageValidator(metadata, _task(rule, require_provenance))
    return names


def _task(rule: str, require_provenance: bool):
    def validate(stage, time_range=None):
        from pxr import Sdf, UsdValidation

        from usdhands.formats.usd_audit import audit_stage

        errors = []
        for f in audit_stage(stage, require_provenance=require_provenance, rules=(rule,)):
            path = f.where if Sdf.Path.IsValidPathString(f.where) else "/"
            site = UsdValidation.ValidationErrorSite(stage, Sdf.Path(path))
            errors.append(UsdValidation.ValidationError(rule.replace("-", "_"), UsdValidation.ValidationErrorType.Error,
                                                        [site], f.message))
        return errors

    return validate

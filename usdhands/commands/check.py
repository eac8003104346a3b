"""``usdhands check FILE... [--json]``: the validation rules on USD, glTF and BVH files.

One line per finding: ``FILE: WHERE: RULE: message``. Exit status 0 when every file
passes, 1 when a rule fails, 2 when a file cannot be read (the others are still checked).
"""

from __future__ import annotations

import sys
from pathlib import Path

from usdhands.commands._common import add_prop_arguments, print_json


def register(sub) -> None:
    p = sub.add_parser("check", help="check files against the usdhands rules (hands, finger coverage, "
                                     "quaternions, array lengths, provenance, props)",
                       description="Check USD, glTF and BVH files: hands mapped or detectable; the animation "
                                   "covers the finger joints; no NaN or zero-length quaternions; joint counts "
                                   "and array lengths consistent; finger-motion provenance well-formed; with --props, "
                                   "fingers do not penetrate the props. One line "
                                   "per finding; exit 1 when a rule fails, 2 when a file cannot be read.")
    p.add_argument("files", type=Path, nargs="+", metavar="FILE", help="files to check")
    p.add_argument("--require-provenance", action="store_true",
                   help="animated finger joints must carry a finger-motion provenance record")
    p.add_argument("--json", action="store_true", help="print the findings as JSON")
    add_prop_arguments(p, required=False, margin=False)
    p.add_argument("--tolerance", type=float, default=0.5, metavar="MM",
                   help="with --props: the deepest finger penetration let through, millimetres (default 0.5)")
    p.set_defaults(func=run)


def options_from(args):
    """The job's options from parsed arguments."""
    from usdhands.jobs.validation import CheckOptions

    return CheckOptions(require_provenance=args.require_provenance, props=tuple(args.props),
                        attach=tuple(args.attach), prop_units=args.prop_units, prop_up=args.prop_up,
                        self_collision=args.self_collision, interaction_config=args.interaction_config,
                        penetration_tolerance_mm=args.tolerance)


def run(args) -> int:
    from usdhands.jobs.validation import check

    result = check(args.files, options_from(args))
    if args.json:
        print_json(result.to_json())
        return result.exit_status
    from usdhands.errors import one_line

    for fc in result.files:
        if fc.error:
            print(f"usdhands: error: {one_line(fc.error)}", file=sys.stderr)
        for finding in fc.findings:
            print(finding)
    if not any(fc.error for fc in result.files):  # an unreadable file: its error line alone says it
        ok = sum(fc.status == "ok" for fc in result.files)
        print(f"checked {len(result.files)} file(s): {ok} passed, {len(result.findings)} finding(s)",
              file=sys.stderr)
    return result.exit_status

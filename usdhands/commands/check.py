"""``usdhands check FILE... [--json]``: the validation rules on USD, glTF and BVH files.

One line per finding: ``FILE: WHERE: RULE: message``. Exit status 0 when every file
passes, 1 when a rule fails, 2 when a file cannot be read (the others are still checked).
"""

from __future__ import annotations

import sys
from pathlib import Path

from usdhands.commands._common import print_json


def register(sub) -> None:
    p = sub.add_parser("check", help="check files against the usdhands rules (hands, finger coverage, "
                                     "quaternions, array lengths, provenance)",
                       description="Check USD, glTF and BVH files: hands mapped or detectable; the animation "
                                   "covers the finger joints; no NaN or zero-length quaternions; joint counts "
                                   "and array lengths consistent; finger-motion provenance well-formed. One line "
                                   "per finding; exit 1 when a rule fails, 2 when a file cannot be read.")
    p.add_argument("files", type=Path, nargs="+", metavar="FILE", help="files to check")
    p.add_argument("--require-provenance", action="store_true",
                   help="animated finger joints must carry a finger-motion provenance record")
    p.add_argument("--json", action="store_true", help="print the findings as JSON")
    p.set_defaults(func=run)


def run(args) -> int:
    from usdhands.jobs.validation import CheckOptions, check

    result = check(args.files, CheckOptions(require_provenance=args.require_provenance))
    if args.json:
        print_json(result.to_json())
        return result.exit_status
    for fc in result.files:
        if fc.error:
            print(f"usdhands: error: {fc.error}", file=sys.stderr)
        for finding in fc.findings:
            print(finding)
    ok = sum(fc.status == "ok" for fc in result.files)
    print(f"checked {len(result.files)} file(s): {ok} passed, {len(result.findings)} finding(s)", file=sys.stderr)
    return result.exit_status

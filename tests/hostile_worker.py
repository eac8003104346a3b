"""Run many ``usdhands`` command lines in one process; used by tests/test_hostile_corpus.py.

Reads a JSON list of argument lists on stdin and prints a JSON list of
``{"code": int, "stderr": str, "stdout_bytes": int, "stdout": str}`` (its first 4000 characters), one per command line. Everything
written to file descriptor 2 while a command runs is captured (Python's and USD's own
diagnostics alike), so a stray line from a library counts against the one-line promise.
The caller runs this under resource limits (tests/hostile.py), which bound the whole batch.
"""

from __future__ import annotations

import io
import json
import os
import sys
import tempfile


def run_one(argv: list[str]) -> dict:
    from usdhands.cli import main

    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as capture:
        os.dup2(capture.fileno(), 2)
        out = io.StringIO()
        real_stdout = sys.stdout
        sys.stdout = out
        try:
            code = main(argv)
        except SystemExit as e:  # --help and --version exit
            code = e.code if isinstance(e.code, int) else 0
        except BaseException as e:  # noqa: BLE001  (reported, not raised: the batch goes on)
            import traceback

            sys.stderr.write("Traceback (escaped the CLI)\n" + "".join(traceback.format_exception(e)))
            code = 1
        finally:
            sys.stdout = real_stdout
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        capture.seek(0)
        err = capture.read().decode("utf-8", errors="replace")
    return {"code": code, "stderr": err, "stdout_bytes": len(out.getvalue()), "stdout": out.getvalue()[:4000]}


def main() -> None:
    cases = json.loads(sys.stdin.read())
    results = [run_one(argv) for argv in cases]
    sys.stdout.write(json.dumps(results))


if __name__ == "__main__":
    main()

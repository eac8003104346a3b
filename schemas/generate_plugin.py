"""Generate the codeless USD schema plugin shipped in the package.

Run from anywhere: ``python schemas/generate_plugin.py [--check]``.

1. ``python -m pxr.Usd.usdGenSchema schemas/usdhands_schema.usda OUT`` (jinja2 needed)
   writes ``generatedSchema.usda`` and ``plugInfo.json`` into
   ``usdhands/plugin/usdHands/resources``;
2. the ``@PLUG_INFO_...@`` placeholders of ``plugInfo.json`` are replaced: a codeless
   plugin has no library (``LibraryPath`` removed), its resources are beside
   ``plugInfo.json`` (``"ResourcePath": "."``, ``"Root": "."``).

``--check`` regenerates into a temporary folder and exits 1 if the shipped files differ.
"""

from __future__ import annotations

import filecmp
import json
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "usdhands_schema.usda"
TARGET = HERE.parent / "usdhands" / "plugin" / "usdHands" / "resources"


def generate(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    done = subprocess.run([sys.executable, "-m", "pxr.Usd.usdGenSchema", "-q", str(SOURCE), str(out)],
                          capture_output=True, text=True)
    if done.returncode:  # its warnings about C++ build files do not apply to a codeless plugin
        sys.stderr.write(done.stdout + done.stderr)
        raise SystemExit(done.returncode)
    info_path = out / "plugInfo.json"
    text = info_path.read_text()
    # usdGenSchema writes a comment header before the JSON; keep it, it is valid for Plug
    head, _, body = text.partition("{")
    info = json.loads("{" + body)
    for plugin in info["Plugins"]:
        plugin.pop("LibraryPath", None)
        plugin["ResourcePath"] = "."
        plugin["Root"] = "."
    info_path.write_text(head + json.dumps(info, indent=4, sort_keys=True) + "\n")


def main(argv: list[str]) -> int:
    if "--check" in argv:
        with tempfile.TemporaryDirectory() as tmp:
            generate(Path(tmp))
            same = all(filecmp.cmp(Path(tmp) / n, TARGET / n, shallow=False)
                       for n in ("plugInfo.json", "generatedSchema.usda"))
        print("up to date" if same else f"{TARGET} differs from {SOURCE.name}: run schemas/generate_plugin.py")  # noqa: T201
        return 0 if same else 1
    generate(TARGET)
    print(f"wrote {TARGET}/plugInfo.json and generatedSchema.usda")  # noqa: T201
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

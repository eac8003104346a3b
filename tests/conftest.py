"""Shared fixtures: the third-party assets beside the project, validators, small rigs."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SHARED_ASSETS = ROOT.parent / "shared" / "assets"
SAMPLE_ASSETS = ROOT / "sample_assets"
VALIDATOR_DIR = Path(__file__).resolve().parent / "gltf_validator"


@pytest.fixture(scope="session")
def shared_assets() -> Path:
    """``../shared/assets`` beside the project; skips where that folder is absent."""
    if not SHARED_ASSETS.is_dir():
        pytest.skip(f"third-party assets not found at {SHARED_ASSETS}")
    return SHARED_ASSETS


@pytest.fixture(scope="session")
def sample_assets() -> Path:
    """The committed sample assets."""
    if not SAMPLE_ASSETS.is_dir():
        pytest.skip(f"sample assets not found at {SAMPLE_ASSETS}")
    return SAMPLE_ASSETS


@pytest.fixture()
def ok_glb(sample_assets, tmp_path) -> Path:
    """A copy of the sample gesture take ``ok_00.glb`` in a temporary folder."""
    dst = tmp_path / "ok.glb"
    shutil.copy(sample_assets / "gestures" / "ok_00.glb", dst)
    return dst


def validate_gltf(*paths: Path) -> list[dict]:
    """Run the Khronos glTF validator; returns one report per file.

    Each report has ``numErrors``, ``numWarnings`` and the first error ``messages``.
    """
    node = shutil.which("node")
    out = subprocess.run([node, str(VALIDATOR_DIR / "validate.js"), *map(str, paths)],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def validator_missing() -> str | None:
    """Why the Khronos validator cannot run here (Node.js or the npm package missing), or None."""
    if shutil.which("node") is None:
        return "Node.js is not installed (the Khronos glTF validator runs on it)"
    if not (VALIDATOR_DIR / "node_modules" / "gltf-validator").is_dir():
        return "the glTF validator is not installed: run `npm install --prefix tests/gltf_validator`"
    return None


def require_validator() -> None:
    """Skip the test, with the reason, where the validator cannot run; fail instead under
    ``USDHANDS_REQUIRE_VALIDATOR=1`` (set by .ci/run, where it must run)."""
    why = validator_missing()
    if why is not None:
        if os.environ.get("USDHANDS_REQUIRE_VALIDATOR") == "1":
            pytest.fail(f"{why} (USDHANDS_REQUIRE_VALIDATOR=1)")
        pytest.skip(why)


@pytest.fixture(scope="session")
def gltf_validator():
    """A function ``validate(*paths) -> list of reports`` (Khronos glTF validator); see require_validator."""
    require_validator()
    return validate_gltf

"""Test helper: run the Khronos glTF Validator on written files.

``validate_glb(path)`` returns the validator's JSON report as a dict;
``assert_valid_glb(path)`` fails the test if the report holds any error (warnings and infos
are allowed, and listed in the failure message for context). Both skip the calling test
with a clear reason when ``node`` or the npm package ``gltf-validator`` is missing
(``make tools`` installs it into ``.tools/``).

Other pillars import it::

    from tests.gltf_validator import assert_valid_glb
    assert_valid_glb(bm.io.write_gltf(tmp_path / "x.glb", creature))
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "tools" / "gltf_validate.mjs"


def _package_dir() -> Path:
    env = os.environ.get("GLTF_VALIDATOR_DIR")
    return Path(env) if env else ROOT / ".tools" / "node_modules" / "gltf-validator"


def validator_missing() -> str | None:
    """Why the validator cannot run here, or ``None`` when it can."""
    if shutil.which("node") is None:
        return "node is not installed; the Khronos glTF validator needs Node.js"
    if not (_package_dir() / "package.json").exists():
        return (
            f"npm package gltf-validator not found at {_package_dir()}; "
            "run `make tools` (npm install --prefix .tools gltf-validator)"
        )
    return None


def validate_many(paths: list[str | os.PathLike[str]]) -> list[dict[str, Any]]:
    """Validate several files in one Node process (faster); one report per file."""
    reason = validator_missing()
    if reason is not None:
        pytest.skip(reason)
    if not paths:
        return []
    proc = subprocess.run(
        ["node", str(SCRIPT), *map(os.fspath, paths)],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "GLTF_VALIDATOR_DIR": str(_package_dir())},
    )
    if proc.returncode not in (0, 1):
        raise AssertionError(
            f"glTF validator could not run on {paths[0]} … "
            f"(exit {proc.returncode}): {proc.stderr.strip()}"
        )
    out = json.loads(proc.stdout)
    return out if len(paths) > 1 else [out]


def validate_glb(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Validate one .glb/.gltf file and return the validator's report (a dict).

    The report's ``issues`` holds ``numErrors``, ``numWarnings``, ``numInfos``,
    ``numHints`` and ``messages`` (each with ``code``, ``message``, ``severity``,
    ``pointer``); ``info`` summarises the asset.
    """
    return validate_many([path])[0]


def _format(messages: list[dict[str, Any]], limit: int = 20) -> str:
    names = {0: "error", 1: "warning", 2: "info", 3: "hint"}
    lines = [
        f"  {names.get(m.get('severity'), '?')} {m.get('code')}: {m.get('message')}"
        f" at {m.get('pointer', '')}"
        for m in messages[:limit]
    ]
    if len(messages) > limit:
        lines.append(f"  … {len(messages) - limit} more")
    return "\n".join(lines)


def assert_valid_glb(
    path: str | os.PathLike[str], *, max_warnings: int | None = None
) -> dict[str, Any]:
    """Assert the Khronos validator reports zero errors for ``path``; return the report.

    ``max_warnings`` additionally bounds the number of warnings (``None``: any number).
    """
    report = validate_glb(path)
    issues = report["issues"]
    if issues["numErrors"]:
        raise AssertionError(
            f"{path}: glTF validator found {issues['numErrors']} error(s):\n"
            + _format(issues["messages"])
        )
    if max_warnings is not None and issues["numWarnings"] > max_warnings:
        raise AssertionError(
            f"{path}: glTF validator found {issues['numWarnings']} warning(s) "
            f"(allowed {max_warnings}):\n" + _format(issues["messages"])
        )
    return report

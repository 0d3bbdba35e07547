"""The Khronos glTF validator (npm `gltf-validator`, pinned) run on a GLB file, for the viewer's tests.

It is installed once into `.venv/npm/` (ignored by git; `bash tools/dev.sh install` puts it there
too); a test that needs it skips, naming why, when node or npm is missing or the registry cannot be
reached. The validator's report is the JSON its `validateBytes` gives (`issues.numErrors`, ...).
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
VALIDATOR = "gltf-validator@2.0.0-dev.3.10"  # Apache-2.0, Khronos Group
PREFIX = ROOT / ".venv" / "npm"
_SCRIPT = """
const v = require(process.argv[1]); const fs = require('fs');
v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])), {maxIssues: 100})
  .then(r => process.stdout.write(JSON.stringify(r)))
  .catch(e => { process.stderr.write(String(e)); process.exit(1); });
"""


def validator_module() -> Path:
    """The installed validator's folder, installing it first when missing; skips when it cannot be had."""
    module = PREFIX / "node_modules" / "gltf-validator"
    if (module / "package.json").is_file():
        return module
    if not (shutil.which("node") and shutil.which("npm")):
        pytest.skip("gltf-validator needs node and npm, which are not installed (apt-get install nodejs npm)")
    r = subprocess.run(["npm", "install", "--prefix", str(PREFIX), "--no-audit", "--no-fund", VALIDATOR],
                       capture_output=True, text=True, timeout=300)
    if r.returncode != 0 or not (module / "package.json").is_file():
        pytest.skip(f"npm could not install {VALIDATOR} (registry unreachable?): {r.stderr.strip()[-200:]}")
    return module


def validate_glb(path: Path) -> dict:
    """The validator's report of the GLB at `path`."""
    module = validator_module()
    r = subprocess.run(["node", "-e", _SCRIPT, str(module), str(path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def errors_of(report: dict) -> list[str]:
    return [f"{m['code']} at {m.get('pointer', '?')}: {m['message']}" for m in report["issues"]["messages"]
            if m["severity"] == 0]

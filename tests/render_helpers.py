"""Test helpers for the renderer's pytest plugin: pytest run on a throwaway project, offscreen."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def pytest_in(project: Path, *args, cwd: Path | None = None):
    """`pytest -q ARGS...` in a child process with `project` as its root (no user config, OSMesa)."""
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    env.pop("PYTEST_ADDOPTS", None)
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", str(project),
                           "-c", os.devnull, *args], cwd=cwd or project, capture_output=True, text=True, env=env,
                          timeout=600)

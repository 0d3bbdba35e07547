"""Test helper: run the `orthosim` command line in a child process, as a user would, offscreen."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def orthosim(*args, cwd=ROOT, timeout: float = 600) -> subprocess.CompletedProcess:
    """`orthosim ARGS...` through the console entry (one-line errors, exit codes), output captured."""
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    return subprocess.run([sys.executable, "-c", "from orthosim.cli import entry; entry()", *map(str, args)],
                          cwd=cwd, capture_output=True, text=True, env=env, timeout=timeout)

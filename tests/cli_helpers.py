"""Test helper: run the `orthosim` command line in a child process, as a user would, offscreen."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def orthosim(*args, cwd=ROOT, timeout: float = 600) -> subprocess.CompletedProcess:
    """`orthosim ARGS...` through the console entry (one-line errors, exit codes), output captured."""
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    return subprocess.run([sys.executable, "-c", "from orthosim.cli import entry; entry()", *map(str, args)],
                          cwd=cwd, capture_output=True, text=True, env=env, timeout=timeout)


@contextmanager
def reaped(proc: subprocess.Popen):
    """`proc` (started with start_new_session=True) while the block runs; after it, its whole process
    group killed if it still runs, so that a test failing half-way leaves no process behind."""
    try:
        yield proc
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()

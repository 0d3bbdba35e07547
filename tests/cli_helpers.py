"""Test helper: run the `orthosim` command line in a child process, as a user would, offscreen."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent  # the repository (tests/ is one level down)


QUICK_CASE = """
[case]
name = "quick"
[model]
kind = "parametric"
resolution = "coarse"
[treatment]
extractions = [14, 24, 34, 44]
duration_days = {days}
step_days = 30
detector = "continuous"
[wire]
type = "rectangular"
[[loads]]
teeth = [16, 26, 36, 46]
force_cN = 150
direction = "mesial"
point = "bracket"
movement = "translation"
"""


def quick_case(folder: Path, steps: int = 20) -> Path:
    """A small case file in `folder` (coarse parametric teeth, 30-day steps, `steps` of them): quick.toml."""
    path = folder / "quick.toml"
    path.write_text(QUICK_CASE.format(days=30 * steps))
    return path


def orthosim_args(*args) -> list[str]:
    """The argument list that starts `orthosim ARGS...` in a child Python, through the console entry."""
    return [sys.executable, "-c", "from orthosim.cli import entry; entry()", *map(str, args)]


def orthosim(*args, cwd=ROOT, timeout: float = 600) -> subprocess.CompletedProcess:
    """`orthosim ARGS...` through the console entry (one-line errors, exit codes), output captured."""
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    return subprocess.run(orthosim_args(*args), cwd=cwd, capture_output=True, text=True, env=env, timeout=timeout)


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


def said_lines(stderr: str) -> list[str]:
    """stderr's lines but the first-run notices (`orthosim: preparing ...`, `orthosim.system.firstrun`),
    which a cold cache on a slow machine may add to any run."""
    return [line for line in stderr.strip().splitlines() if not line.startswith("orthosim: preparing ")]

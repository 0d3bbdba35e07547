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


def case3_run(folder):
    """Case 3 run by `orthosim run` into folder/run (frames, animation.glb, viewer.html) at 160x120, and
    the same simulation's step records in this process: (run folder, dentition, records, extracted FDIs)."""
    from cli_helpers import orthosim
    from orthosim.exchange.case import CASES_DIR, load_case
    from orthosim.runtime.strategies import step_records

    case_file = CASES_DIR / "case3_incisor_space_closure.toml"
    out = folder / "run"
    r = orthosim("run", case_file, "--out", out, "--frames-per-step", "1", "--size", "160x120")
    assert r.returncode == 0, r.stderr
    case = load_case(case_file)
    with step_records(case, case.detector, in_process=True) as source:
        records = list(source.records)
        dentition = source.dentition
    return out, dentition, records, frozenset(case.extractions)

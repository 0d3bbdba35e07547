"""A drawn run on a machine whose caches are empty (its first run) builds the model and its sphere
trees inside the simulation child and finishes like any other run."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from cli_helpers import ROOT
from cli_helpers import quick_case


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_a_drawn_run_with_empty_caches_builds_its_trees_in_the_child_and_finishes(tmp_path):
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa", "ORTHOSIM_CACHE": str(tmp_path / "empty-cache")}
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-c", "from orthosim.cli import entry; entry()", "run",
                        quick_case(tmp_path, steps=2), "--out", out, "--size", "96x64", "--frames-per-step", "1"],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr and "daemonic" not in r.stderr
    assert (out / "run.json").is_file() and len(list((out / "frames").glob("*.png"))) == 3
    assert any((tmp_path / "empty-cache").rglob("*")), "the trees were built into the cache"

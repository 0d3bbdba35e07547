"""What `orthosim run` does before its first step: help and refused options answer before any heavy
import, and a drawn run's simulation child is a fork that needs no second import or model load."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("numba", "OpenGL", "pyrender", "trimesh", "fcl", "scipy")

# runs the CLI as the console script does, then reports which heavy modules the process imported
_PROBE = """
import atexit, json, sys
atexit.register(lambda: print(json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)), file=sys.stderr))
sys.argv = ["orthosim"] + sys.argv[1:]
from orthosim.cli import entry
entry()
"""


def _probe(*args, tmp_path: Path) -> tuple[int, str, list[str]]:
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    r = subprocess.run([sys.executable, "-c", _PROBE.format(heavy=HEAVY), *map(str, args)], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=300)
    *lines, imported = r.stderr.strip().splitlines()
    return r.returncode, "\n".join(lines), json.loads(imported)


@pytest.mark.parametrize("args, expected", [
    (["--help"], None),
    (["cases/case1_first_premolar_extraction.toml", "--view", "sideways"], "--view: sideways: is not a camera preset"),
    (["cases/case1_first_premolar_extraction.toml", "--fps", "500"], "--fps: 500: is not 1 to 120 frames per second"),
    (["cases/case1_first_premolar_extraction.toml", "--detector", "nosuch"], "orthosim: error: --detector: 'nosuch' is not one of"),
    (["cases/no_such_case.toml"], "no_such_case.toml"),
    pytest.param(["cases/open_full_jaw_case3_diastema.toml", "--view", "sideways"], "--view: sideways: is not a camera preset",
                 marks=pytest.mark.real_data, id="real-teeth case, bad view"),
    pytest.param(["cases/open_full_jaw_case3_diastema.toml", "--export-steps", "99"], "--export-steps: 99: is not a step",
                 marks=pytest.mark.real_data, id="real-teeth case read, bad step"),
])
def test_help_and_refused_options_answer_before_any_heavy_import(tmp_path, args, expected):
    code, stderr, imported = _probe("run", *args, "--out", tmp_path / "o", tmp_path=tmp_path)
    assert imported == []  # none of numba, OpenGL, pyrender, trimesh, FCL, scipy
    if expected is None:
        assert code == 0
    else:
        assert code == 2 and expected in stderr and "Traceback" not in stderr
        assert not (tmp_path / "o").exists()


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.skipif(sys.platform != "linux", reason="reads /proc to see the child's command line")
def test_a_drawn_run_simulates_in_a_forked_child_that_neither_imports_nor_loads_the_teeth_again(tmp_path):
    # the child of `orthosim run` is a copy of the drawing process made after the imports both sides
    # use and the teeth's load: it reports the teeth as given, where a spawned child loads them itself
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    r = subprocess.run([sys.executable, "-c", "from orthosim.cli import entry; entry()", "run",
                        "cases/case3_incisor_space_closure.toml", "--out", tmp_path / "o", "--verbose",
                        "--size", "64x48", "--frames-per-step", "1"], cwd=ROOT, env=env, capture_output=True,
                       text=True, timeout=900)
    assert r.returncode == 0, r.stderr
    model_lines = [line for line in r.stderr.splitlines() if line.startswith("model ")]
    assert any("from the cache" in line or "built and cached" in line for line in model_lines)  # this process
    assert any(line.rstrip().endswith(", given") for line in model_lines)  # the child: the same teeth, not reloaded
    assert "first step after" in r.stderr

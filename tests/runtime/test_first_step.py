"""What a drawn run's two processes import before its first step (issue 42, start-up in 0.8 s):
with the caches warm, the simulation child loads the teeth (as arrays: `LazyMesh`) and their sphere
trees and takes the first step without importing trimesh (nor networkx, which it pulls), numba (its
import and typing set-up), the sphere-tree builder or anything of the drawing (pyrender, OpenGL);
the drawing process receives that step having imported none of trimesh, scipy, numba, FCL,
pyrender or OpenGL (it loads its renderer while the next steps are computed), so the first step
waits for none of them. The child's first step still imports FCL (its exact distances); the k-d
tree that cuts each touching pair's patches (scipy.spatial) only in a run whose first step's
patches no earlier run of these teeth kept (`orthosim.collision.patchcache`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from orthosim import load_case
from orthosim.collision import CollisionModel
from orthosim.runtime.strategies import SHARED_MODULES

ROOT = Path(__file__).resolve().parents[2]
CASE = ROOT / "cases" / "case1_first_premolar_extraction.toml"
NOT_BEFORE_THE_FIRST_STEP = ("numba", "orthosim.spheretree.fit", "orthosim.spheretree.outside_band", "pyrender",
                             "OpenGL", "trimesh", "networkx", "tqdm")
# what the drawing process has not imported when the first step record reaches it
NOT_BEFORE_THE_FIRST_RECORD = ("trimesh", "scipy", "numba", "fcl", "pyrender", "OpenGL", "networkx")

# the child's side of `orthosim run`: what the drawing process imports before it forks, then the
# simulation stream (orthosim.runtime.stream) up to its first step record
_CHILD = """
import importlib, json, sys
for name in {shared!r}:
    importlib.import_module(name)
from orthosim import load_case
from orthosim.movement.records import StepRecord
from orthosim.runtime.stream import simulation_stream
kinds = []
for item in simulation_stream(load_case({case!r}), {detector!r}, {out!r}):
    kinds.append(type(item).__name__)
    if isinstance(item, StepRecord):
        break
print(json.dumps({{"kinds": kinds, "imported": sorted(m for m in {heavy!r} if m in sys.modules),
                  "distances": repr(item.distances), "touching": repr(item.touching)}}))
"""


@pytest.mark.slow  # a fresh interpreter importing the simulation's libraries and taking a step
@pytest.mark.parametrize("detector", ["continuous", "discrete"])
def test_with_warm_caches_the_first_step_imports_neither_numba_nor_the_tree_builder_nor_the_drawing(tmp_path, detector):
    dent = load_case(CASE).build_dentition()  # the teeth and their trees in the cache, as after a first run
    CollisionModel.from_dentition(dent)
    code = _CHILD.format(shared=SHARED_MODULES, case=str(CASE), detector=detector, out=str(tmp_path),
                         heavy=NOT_BEFORE_THE_FIRST_STEP)
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=dict(os.environ), capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout)
    assert seen["kinds"] == ["PhaseDone", "PhaseDone", "StepRecord"]  # model, trees, then the first step
    assert seen["imported"] == []


@pytest.mark.slow  # two fresh interpreters each taking the first step
def test_the_first_steps_patches_are_kept_and_the_next_run_takes_the_same_first_step_without_scipy(tmp_path):
    """Case 1's teeth and trees come from the shipped entries; the patches from an empty cache."""
    env = {**os.environ, "ORTHOSIM_CACHE": str(tmp_path / "cache")}
    code = _CHILD.format(shared=SHARED_MODULES, case=str(CASE), detector="continuous", out=str(tmp_path),
                         heavy=("scipy.spatial",))
    runs = []
    for _ in range(2):
        done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        assert "Warning" not in done.stderr, done.stderr
        runs.append(json.loads(done.stdout))
    kept = list((tmp_path / "cache" / "patches").glob("*.npz"))
    assert runs[0]["imported"] == ["scipy.spatial"] and len(kept) >= 10  # case 1's touching and adjacent pairs
    assert runs[1]["imported"] == []
    assert runs[1]["distances"] == runs[0]["distances"] and runs[1]["touching"] == runs[0]["touching"]  # repr: every bit


# `orthosim run` as the console script runs it; when its --verbose line says the first step record
# has reached this (the drawing) process, it notes which of the heavy modules this process holds
_DRAWING = """
import json, sys
import orthosim.runtime.run as run
note = run.RunLog.note
def noting(self, text):
    if text.startswith("first step after"):
        print("imported at the first step: " + json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)), file=sys.stderr)
    note(self, text)
run.RunLog.note = noting
sys.argv = ["orthosim"] + sys.argv[1:]
from orthosim.cli import entry
entry()
"""


@pytest.mark.slow  # a drawn run of two steps in fresh processes
def test_with_warm_caches_the_drawing_process_receives_the_first_step_before_importing_trimesh_scipy_fcl_or_the_renderer(tmp_path):
    case = tmp_path / "case.toml"  # case 1, two steps
    case.write_text(CASE.read_text().replace("duration_days = 600", "duration_days = 60"))
    CollisionModel.from_dentition(load_case(case).build_dentition())  # warm caches, as after a first run
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    done = subprocess.run([sys.executable, "-c", _DRAWING.format(heavy=NOT_BEFORE_THE_FIRST_RECORD), "run", str(case),
                           "--out", str(tmp_path / "out"), "--verbose", "--size", "64x48", "--frames-per-step", "1"],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    noted = [line for line in done.stderr.splitlines() if line.startswith("imported at the first step: ")]
    assert len(noted) == 1, done.stderr  # the first step reached the drawing process, once
    assert json.loads(noted[0].split(": ", 1)[1]) == []
    assert (tmp_path / "out" / "metrics.json").is_file()  # and the run went on to draw and finish

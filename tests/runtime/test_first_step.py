"""What a drawn run's simulation child does before its first step (issue 42, start-up under a
second): with the caches warm, it loads the teeth and their sphere trees and takes the first step
without importing numba (its import and typing set-up), the sphere-tree builder or anything of the
drawing (pyrender, OpenGL), so the first step waits for none of them."""

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
                             "OpenGL")

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
print(json.dumps({{"kinds": kinds, "imported": sorted(m for m in {heavy!r} if m in sys.modules)}}))
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

"""The detectors stay off numba until their compiled descent pays (`orthosim.collision.descent.compiled_descent`):
the numpy descent (the same results) for a process's first LOADING_PAYS_AFTER_DESCENTS descents,
without importing numba; then the compiled walk if its kernels are in numba's cache, else the numpy
descent until PAYS_AFTER_DESCENTS descents, then the walk compiled once for every later run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")

TESTS = Path(__file__).resolve().parents[1]

_PROBE = """
import json, sys
from orthosim.collision import descent
descent.LOADING_PAYS_AFTER_DESCENTS = 2
descent.PAYS_AFTER_DESCENTS = 3
walks, numba_seen = [], []
for _ in range(5):
    walks.append(descent.compiled_descent(None) is not None)
    numba_seen.append("numba" in sys.modules)
from orthosim.collision import descent_compiled
print(json.dumps({"ready": descent_compiled.kernels_ready(), "walks": walks, "numba": numba_seen,
                  "asked": descent.compiled_descent(True) is not None, "refused": descent.compiled_descent(False) is None}))
"""

# compiles the walk's kernels into numba's cache (NUMBA_CACHE_DIR), as a first long run would
_COMPILE = """
import numpy as np
from collision_helpers import crown_like_mesh, median_split_tree
from orthosim.collision import Body, CollisionModel
from orthosim.collision.continuous import swept_leaves
from orthosim.collision.discrete import overlapping_leaves
bodies = [Body(k, m, median_split_tree(m), np.eye(4)) for k, m in ((1, crown_like_mesh(0)), (2, crown_like_mesh(1)))]
model = CollisionModel(bodies)
poses, pairs = model.pose_array({}), model.pair_indices([(1, 2)])
overlapping_leaves(model, poses, pairs, compiled=True)
swept_leaves(model, poses, poses, pairs, compiled=True)
"""


def _probe(numba_cache: Path) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(numba_cache)}
    done = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout)
    assert seen["asked"] and seen["refused"]  # compiled=True and False still mean what they say
    assert "preparing" not in done.stderr  # nothing was compiled: the probe never called a kernel
    return seen


@pytest.mark.slow  # a fresh interpreter importing numba
def test_a_fresh_machine_descends_with_numpy_until_compiling_pays(tmp_path):
    seen = _probe(tmp_path / "empty-numba-cache")
    assert seen["ready"] is False  # nothing compiled for this source in that cache
    assert seen["walks"] == [False, False, False, True, True]  # numpy for 3 descents, then the compiled walk
    assert seen["numba"][:2] == [False, False]  # the first descents did not even import numba


@pytest.mark.slow  # compiles the walk's kernels into a fresh numba cache
def test_with_the_kernels_cached_a_short_run_never_imports_numba_and_a_longer_one_loads_the_walk(tmp_path):
    cache = tmp_path / "numba-cache"
    path = os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])  # collision_helpers
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": path}
    compiled = subprocess.run([sys.executable, "-c", _COMPILE], env=env, capture_output=True, text=True, timeout=900)
    assert compiled.returncode == 0, compiled.stderr
    seen = _probe(cache)
    assert seen["ready"] is True
    assert seen["walks"] == [False, False, True, True, True]  # loading pays after 2 descents here, compiling after 3
    assert seen["numba"] == [False, False, True, True, True]  # numba imported when the walk is first taken

"""What keeps a drawn run's memory down (issue 12): each process forgets what it no longer reads.

The simulation side drops the teeth meshes' trimesh caches once its model is built, the drawing
side once its scene is; the drawing
process reads step records without importing the simulation's modules (numba, the collision package).
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from orthosim import load_case
from orthosim.movement.records import CollisionEvent, StepRecord

ROOT = Path(__file__).resolve().parents[2]
CASE = ROOT / "cases" / "case3_incisor_space_closure.toml"


def test_dropping_the_mesh_caches_forgets_derived_arrays_and_they_come_back_the_same():
    dent = load_case(CASE).build_dentition()
    tooth = next(iter(dent.teeth.values()))
    triangles = tooth.mesh.triangles.copy()
    edges = tooth.mesh.edges_unique.copy()
    normals = tooth.mesh.vertex_normals.copy()
    freed = dent.drop_mesh_caches()
    assert freed >= triangles.nbytes + edges.nbytes + normals.nbytes
    assert all(not t.mesh._cache.cache for t in dent.teeth.values())
    assert dent.drop_mesh_caches() == 0
    np.testing.assert_array_equal(tooth.mesh.triangles, triangles)
    np.testing.assert_array_equal(tooth.mesh.edges_unique, edges)
    np.testing.assert_array_equal(tooth.mesh.vertex_normals, normals)


@pytest.mark.parametrize("shared", [False, True])
def test_the_simulation_side_drops_the_caches_its_model_build_made_unless_another_thread_draws_the_teeth(tmp_path, shared):
    from orthosim.runtime.stream import PhaseDone, simulation_stream

    case = load_case(CASE)
    dent = case.build_dentition()
    stream = simulation_stream(case, "discrete", tmp_path, dentition=dent, shared=shared)
    phases = [next(stream), next(stream)]  # model, trees: the model is built
    assert [p.name for p in phases if isinstance(p, PhaseDone)] == ["model", "trees"]
    cached = sum(len(t.mesh._cache.cache) for t in dent.teeth.values())
    if shared:
        assert cached > 0  # the build's caches, left for the drawing thread
    else:
        assert cached == 0
    stream.close()


def test_a_step_record_unpickles_without_the_simulations_imports():
    record = StepRecord(step=3, time_days=6.0, poses={11: np.eye(4)}, moving=frozenset({11}), touching=((11, 21),),
                        contact_centers=np.zeros((1, 3)), contact_radii=np.ones(1),
                        collisions=(CollisionEvent((11, 21), 0.5, {"dv": 1.0}),), forces=None,
                        max_penetration_mm=0.01, distances=())
    code = ("import pickle, sys; r = pickle.loads(sys.stdin.buffer.read()); "
            "print(type(r).__module__, r.step, r.collisions[0].pair, 'numba' in sys.modules, "
            "'orthosim.collision' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], input=pickle.dumps(record), capture_output=True, cwd=ROOT,
                         timeout=120, check=True).stdout.decode().split()
    assert out == ["orthosim.movement.records", "3", "(11,", "21)", "False", "False"]
    from orthosim.movement.simulation import StepRecord as SimulationStepRecord

    assert SimulationStepRecord is StepRecord


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the drawn run forks its simulation child on Linux")
def test_the_drawing_process_of_a_drawn_run_never_imports_numba(tmp_path):
    # the main process (it draws) reports its imports at exit; the forked child ends with os._exit
    probe = ("import atexit, json, sys\n"
             "atexit.register(lambda: print(json.dumps([m for m in ('numba', 'orthosim.collision.detect', "
             "'orthosim.collision.model', 'orthosim.collision.queries', 'pyrender') if m in sys.modules]), file=sys.stderr))\n"
             "sys.argv = ['orthosim'] + sys.argv[1:]\n"
             "from orthosim.cli import entry\nentry()\n")
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    r = subprocess.run([sys.executable, "-c", probe, "run", str(CASE), "--out", str(tmp_path / "o"), "--size", "64x48",
                        "--frames-per-step", "1", "--verbose"], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip().splitlines()[-1] == '["pyrender"]'  # drew, and the simulation was the child's
    assert "beside the drawing" in r.stderr
    assert (tmp_path / "o" / "animation.mp4").stat().st_size > 0

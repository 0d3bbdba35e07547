"""A run's exact queries (`ExactQueries`) and the contacts of a set of poses (`collision.contacts`)."""

import os
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from collision_helpers import median_split_tree
from orthosim.collision import Body, CollisionModel, CollisionRequest, ExactQueries, contacts
from orthosim.geometry import meshquery
from orthosim.pose import translation


def boxes(offset_x: float):
    """Tooth 1: a 4 mm cube at the origin; tooth 2: a 2 mm cube centred offset_x along x."""
    a = trimesh.creation.box([4.0, 4.0, 4.0])
    b = trimesh.creation.box([2.0, 2.0, 2.0])
    model = CollisionModel([Body(1, a, median_split_tree(a), np.eye(4)),
                            Body(2, b, median_split_tree(b), translation([offset_x, 0.0, 0.0]))])
    return model, {1: np.eye(4), 2: translation([offset_x, 0.0, 0.0])}


def test_distance_intersection_and_depth_of_two_boxes():
    model, _ = boxes(0.0)
    q = ExactQueries(model)
    apart = {1: np.eye(4), 2: translation([3.5, 0, 0])}  # faces 0.5 mm apart
    sunk = {1: np.eye(4), 2: translation([2.7, 0, 0])}  # b's face 0.3 mm inside a
    assert q.distance((1, 2), apart) == pytest.approx(0.5, abs=1e-6)
    assert not q.intersects((1, 2), apart) and q.penetration((1, 2), apart) == 0.0
    assert q.intersects((1, 2), sunk) and q.distance((1, 2), sunk) == 0.0
    assert q.penetration((1, 2), sunk) == pytest.approx(0.3, abs=1e-6)
    assert q.penetrations([(1, 2)], apart) == {} and q.penetrations([(1, 2)], sunk) == {(1, 2): q.penetration((1, 2), sunk)}


def test_repeated_questions_are_answered_from_memory_with_fcls_own_numbers():
    model, poses = boxes(3.5)
    q = ExactQueries(model)
    first = q.distance((1, 2), poses)
    again = q.distance((1, 2), {k: T.copy() for k, T in poses.items()})
    assert first == again and q.queries == 1
    moved = {1: poses[1], 2: translation([np.nextafter(3.5, 4.0), 0, 0])}  # one ulp is a new question
    q.distance((1, 2), moved)
    assert q.queries == 2


def test_each_run_owns_its_fcl_objects_and_the_model_keeps_none():
    model, poses = boxes(3.5)
    q1, q2 = ExactQueries(model), ExactQueries(model)
    assert q1.object(0) is not q2.object(0)
    q1.placed(1, translation([2.7, 0, 0]))  # re-posing one run's object leaves the other's alone
    assert q2.distance((1, 2), poses) == pytest.approx(0.5, abs=1e-6)
    assert not hasattr(model, "fcl_object")


@pytest.mark.parametrize("detector", ["exact", "continuous"])
def test_contacts_count_meshes_within_the_touch_tolerance_as_touching(detector):
    model, _ = boxes(0.0)
    q = ExactQueries(model)
    request = CollisionRequest(touch_tolerance_mm=0.05)
    near = {1: np.eye(4), 2: translation([3.03, 0, 0])}  # 0.03 mm apart
    far = {1: np.eye(4), 2: translation([3.2, 0, 0])}  # 0.2 mm apart: leaf spheres may overlap, meshes do not touch
    assert contacts(model, near, request, q, [(1, 2)], detector).touching == ((1, 2),)
    found = contacts(model, far, request, q, [(1, 2)], detector)
    assert found.touching == () and found.penetration == {}
    wide = contacts(model, far, CollisionRequest(touch_tolerance_mm=0.25), q, [(1, 2)], detector)
    assert wide.touching == ((1, 2),) and wide.distance[(1, 2)] == pytest.approx(0.2, abs=1e-6)


def test_contacts_report_interpenetration_and_the_drawn_leaves():
    model, _ = boxes(0.0)
    sunk = {1: np.eye(4), 2: translation([2.7, 0, 0])}
    found = contacts(model, sunk, CollisionRequest(), ExactQueries(model), [(1, 2)], "discrete")
    assert found.touching == ((1, 2),)
    assert found.penetration[(1, 2)] == pytest.approx(0.3, abs=1e-6)
    assert len(found.centers) == len(found.radii) > 0


@pytest.mark.slow  # builds the 28 teeth from nothing (tens of seconds)
def test_building_parametric_teeth_imports_neither_the_detectors_nor_numba(tmp_path):
    code = ("import sys\n"
            "from orthosim.parametric import parametric_dentition\n"
            "assert len(parametric_dentition().teeth) == 28\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'numba' or m.startswith('orthosim.collision')))\n")
    env = dict(os.environ, ORTHOSIM_CACHE=str(tmp_path))  # an empty cache: the teeth are really built
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"


def test_meshquery_is_geometry_that_needs_no_collision_model():
    a, b = trimesh.creation.box([4.0, 4.0, 4.0]), trimesh.creation.box([2.0, 2.0, 2.0])
    oa, ob = meshquery.fcl_object(a), meshquery.fcl_object(b)
    meshquery.set_pose(oa, np.eye(4))
    meshquery.set_pose(ob, translation([3.5, 0, 0]))
    assert meshquery.distance(oa, ob) == pytest.approx(0.5, abs=1e-6)

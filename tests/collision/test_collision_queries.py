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
from orthosim.geometry.pose import translation


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


def test_edges_crossing_edges_read_their_depth_where_no_vertex_is_inside():
    """Two square bars turned 45 degrees about their axes cross at right angles, ridge against ridge,
    sunk 0.3 mm: no vertex of either lies inside the other, and the step's depth is the ridges' own,
    0.3 / sqrt(2) mm (vertex-based: 0)."""
    bar = trimesh.creation.box((10.0, 2.0, 2.0))
    lower = trimesh.transformations.rotation_matrix(np.pi / 4, [1, 0, 0])
    lower[2, 3] = -np.sqrt(2.0)
    upper = (trimesh.transformations.rotation_matrix(np.pi / 2, [0, 0, 1]) @ trimesh.transformations.rotation_matrix(np.pi, [1, 0, 0])
             @ trimesh.transformations.rotation_matrix(np.pi / 4, [1, 0, 0]))
    upper[2, 3] = np.sqrt(2.0) - 0.3
    model = CollisionModel([Body(1, bar, median_split_tree(bar), lower), Body(2, bar.copy(), median_split_tree(bar), upper)])
    poses = {1: lower, 2: upper}
    assert meshquery.penetration_depth(bar, lower, bar, upper) == 0.0
    q = ExactQueries(model)
    assert q.intersects((1, 2), poses)
    assert q.penetration((1, 2), poses) == pytest.approx(0.3 / np.sqrt(2.0), abs=0.01)
    found = contacts(model, poses, CollisionRequest(), ExactQueries(model), [(1, 2)], "discrete")
    assert found.penetration[(1, 2)] == pytest.approx(0.3 / np.sqrt(2.0), abs=0.01)


def test_meshes_without_an_inside_get_the_vertex_depth():
    """An open mesh (a box without its top) has no reliable inside for the edge measure: the
    vertex-based one answers, as it did before."""
    open_box = trimesh.creation.box([2.0, 2.0, 2.0])
    open_box = trimesh.Trimesh(open_box.vertices, open_box.faces[~np.isclose(open_box.triangles_center[:, 2], 1.0)], process=False)
    a = trimesh.creation.box([4.0, 4.0, 4.0])
    model = CollisionModel([Body(1, a, median_split_tree(a), np.eye(4)), Body(2, open_box, median_split_tree(open_box), np.eye(4))])
    sunk = {1: np.eye(4), 2: translation([2.7, 0, 0])}
    assert ExactQueries(model).penetration((1, 2), sunk) == meshquery.penetration_depth(a, sunk[1], open_box, sunk[2])


@pytest.mark.slow  # builds the 28 teeth from nothing (tens of seconds)
def test_building_parametric_teeth_imports_neither_the_detectors_nor_numba(tmp_path):
    code = ("import sys\n"
            "from orthosim.model.parametric import parametric_dentition\n"
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


def spheres():
    """Two 1,280-face spheres of radius 3 mm (curved: a close pair's patches are a few faces of each)."""
    a = trimesh.creation.icosphere(subdivisions=3, radius=3.0)
    b = trimesh.creation.icosphere(subdivisions=3, radius=3.0)
    return CollisionModel([Body(1, a, median_split_tree(a), np.eye(4)), Body(2, b, median_split_tree(b), translation([7.0, 0, 0]))])


def whole_mesh_answers(model, poses):
    """(distance, intersecting) of FCL on the two whole meshes, with objects made for this call."""
    oa, ob = (meshquery.fcl_object(body.mesh) for body in model.bodies)
    meshquery.set_pose(oa, poses[1])
    meshquery.set_pose(ob, poses[2])
    return meshquery.distance(oa, ob), meshquery.collide(oa, ob)[0]


def test_a_runs_answers_equal_fcl_on_the_whole_meshes_to_the_last_bit():
    """Patches, the separation proof and the memo change what FCL is asked, never the answer."""
    from scipy.spatial.transform import Rotation

    model = spheres()
    q = ExactQueries(model)
    rng = np.random.default_rng(7)
    gaps = [0.3, 0.05, 0.01, 0.002, 0.0005, -0.01, -0.2, 0.01, 0.6, 2.0, 0.02]  # mm between the spheres' surfaces
    for gap in gaps * 3:
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(rng.normal(size=3) * 0.05).as_matrix()
        T[:3, 3] = [6.0 + gap, *(rng.normal(size=2) * 0.05)]
        poses = {1: np.eye(4), 2: T}
        d, hit = whole_mesh_answers(model, poses)
        assert q.intersects((1, 2), poses) == hit
        assert q.distance((1, 2), poses) == d
        assert q.intersects((1, 2), poses) == hit  # after the distance: the proof of separation, when it holds
    assert q._patches, "close pairs are answered on patches"
    patch = next(iter(q._patches.values()))
    assert 0 < len(patch.faces_i) < len(model.bodies[0].mesh.faces) / 4


def test_meshes_alone_answer_as_their_collision_model_does_with_or_without_patches():
    """`ExactQueries.of_meshes`: no sphere trees built, FCL's own numbers all the same."""
    model = spheres()
    meshes = {b.key: b.mesh for b in model.bodies}
    alone, whole = ExactQueries.of_meshes(meshes), ExactQueries.of_meshes(meshes, patch_reach_mm=0.0)
    np.testing.assert_array_equal(alone.model.rho_max, model.rho_max)
    for gap in [0.3, 0.02, 0.002, -0.01, 0.6, 2.0]:
        poses = {1: np.eye(4), 2: translation([6.0 + gap, 0.01, -0.02])}
        d, hit = whole_mesh_answers(model, poses)
        for q in (alone, whole):
            assert q.distance((1, 2), poses) == d and q.intersects((1, 2), poses) == hit
    assert alone._patches and not whole._patches


def test_a_pair_proved_apart_by_its_last_distance_is_not_tested_with_fcl():
    model, _ = boxes(0.0)
    q = ExactQueries(model)
    q.distance((1, 2), {1: np.eye(4), 2: translation([3.5, 0, 0])})  # 0.5 mm apart
    asked = q.collides
    assert not q.intersects((1, 2), {1: np.eye(4), 2: translation([3.2, 0, 0])})  # moved 0.3 mm closer: still 0.2 apart
    assert q.collides == asked
    assert q.intersects((1, 2), {1: np.eye(4), 2: translation([2.9, 0, 0])})  # moved 0.6 mm: FCL is asked, and they meet
    assert q.collides == asked + 1


def test_contacts_ask_no_interpenetration_of_pairs_whose_leaves_are_apart():
    model, _ = boxes(0.0)
    q = ExactQueries(model)
    far = {1: np.eye(4), 2: translation([8.0, 0, 0])}
    found = contacts(model, far, CollisionRequest(), q, [(1, 2)], "discrete")
    assert found.touching == () and found.penetration == {} and q.collides == 0
    sunk = {1: np.eye(4), 2: translation([2.7, 0, 0])}
    assert contacts(model, sunk, CollisionRequest(), q, [(1, 2)], "discrete").penetration[(1, 2)] == pytest.approx(0.3, abs=1e-6)


def test_a_pose_path_at_time_zero_is_its_start_pose_without_finding_the_rotation():
    from scipy.spatial.transform import Rotation

    from orthosim.geometry.motion import PosePath, interpolate_pose

    T0, T1 = np.eye(4), np.eye(4)
    T0[:3, :3] = Rotation.from_rotvec([0.3, -0.2, 0.1]).as_matrix()
    T0[:3, 3] = [12.5, -3.25, 7.0]
    T1[:3, :3] = Rotation.from_rotvec([0.01, 0.0, -0.02]).as_matrix() @ T0[:3, :3]
    T1[:3, 3] = T0[:3, 3] + [0.1, 0.02, -0.05]
    path = PosePath(T0, T1)
    assert path.at(0.0).tobytes() == interpolate_pose(T0, T1, 0.0).tobytes()
    assert path._w is None
    assert path.at(0.4).tobytes() == interpolate_pose(T0, T1, 0.4).tobytes()


def test_node_centres_of_a_pose_set_are_placed_once_and_equal_the_models():
    model, poses = boxes(3.5)
    q = ExactQueries(model)
    P = model.pose_array(poses)
    W = q.world_centers(P)
    assert np.array_equal(W, model.world_centers(P)) and not W.flags.writeable
    assert q.world_centers(P.copy()) is W  # the same poses (by value): remembered
    moved = P.copy()
    moved[1, 0, 3] += 0.25
    assert np.array_equal(q.world_centers(moved), model.world_centers(moved))

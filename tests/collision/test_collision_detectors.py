"""The three detectors and the exact reference, through the one entry point the simulator and the
renderer call (`detect_step`): the paper's claims, checked against the exact mesh test."""

import numpy as np
import pytest
import trimesh

from collision_helpers import crown_like_mesh, median_split_tree, real_tooth_meshes
from orthosim.collision import DETECTORS, Body, CollisionError, CollisionModel, CollisionRequest, detect_step
from orthosim.geometry import meshquery
from orthosim.collision.circles import bounding_circles
from orthosim.geometry.motion import interpolate_pose
from orthosim.collision.validate import ToothSet, continuous_study, dense_first_contact, discrete_study, thin_root_mesh
from orthosim.geometry.pose import rotation_about_axis, translation


def octree_tree(mesh):
    """The project's octree builder (fast enough for tests; the "fit" builder takes seconds a tooth)."""
    from orthosim.spheretree.build import build_sphere_tree

    return build_sphere_tree(mesh, method="octree")


BUILDERS = {"median-split(test)": median_split_tree, "octree(project)": octree_tree}


@pytest.fixture(scope="module")
def parametric():
    from orthosim.model.parametric import parametric_dentition

    d = parametric_dentition(resolution="coarse")
    return d, CollisionModel.from_dentition(d, tree_builder=median_split_tree)


def two_body_model(mesh_a, mesh_b, rest_b=np.eye(4)):
    return CollisionModel([Body(1, mesh_a, median_split_tree(mesh_a), np.eye(4)),
                           Body(2, mesh_b, median_split_tree(mesh_b), rest_b)])


def parametric_set(parametric):
    d, _ = parametric
    fdis = [13, 14, 15, 16, 46, 47]
    return ToothSet("parametric", tuple(d.teeth[n].mesh for n in fdis), ((0, 1), (1, 2), (2, 3), (3, 4), (3, 5)))


# --- the discrete sphere-tree detector -------------------------------------------------------------

@pytest.mark.parametrize("builder", BUILDERS)
def test_discrete_sphere_trees_never_miss_an_intersection_the_exact_mesh_test_finds(parametric, builder):
    report = discrete_study([parametric_set(parametric)], n_poses=400, tree_builder=BUILDERS[builder], seed=1)
    res = report["sets"]["parametric"]
    assert res["exact_intersecting"] > 100  # the sample really holds intersecting poses
    assert res["false_negatives"] == 0


@pytest.mark.real_data
def test_discrete_sphere_trees_never_miss_an_intersection_of_real_teeth():
    meshes = real_tooth_meshes((6, 7, 8))
    report = discrete_study([ToothSet("real", tuple(meshes), ((0, 1), (1, 2)))], n_poses=60,
                            tree_builder=median_split_tree, seed=2)
    res = report["sets"]["real"]
    assert res["exact_intersecting"] > 10
    assert res["false_negatives"] == 0


def test_every_intersecting_triangle_pair_lies_in_a_reported_leaf_pair():
    a, b = crown_like_mesh(0), crown_like_mesh(1)
    model = two_body_model(a, b)
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(20):
        Tb = translation(rng.normal(size=3) * 1.5 + [7.5, 0, 0])
        Tb[:3, :3] = rotation_about_axis(rng.normal(size=3), rng.uniform(0, np.pi))
        res = detect_step(model, {2: Tb}, pairs=[(1, 2)], detector="discrete")
        oa, ob = meshquery.fcl_object(model.bodies[0].mesh), meshquery.fcl_object(model.bodies[1].mesh)
        meshquery.set_pose(oa, np.eye(4))
        meshquery.set_pose(ob, Tb)
        hit, (pts, faces) = meshquery.collide(oa, ob, all_contacts=True)
        if not hit:
            continue
        checked += 1
        reported = {tuple(p) for p in res.leaf_pairs}
        leaf_a, leaf_b = model.bodies[0].tree.leaf_of_face, model.bodies[1].tree.leaf_of_face
        assert {(leaf_a[f1], leaf_b[f2]) for f1, f2 in faces} <= reported
    assert checked >= 5


def test_reported_leaf_pairs_overlap_and_are_drawn_in_the_arch_frame(parametric):
    d, model = parametric
    res = detect_step(model, d.rest_poses(), detector="discrete")
    assert len(res.leaf_pairs) > 0
    gap = np.linalg.norm(res.centers_a - res.centers_b, axis=1) - (res.radii_a + res.radii_b)
    assert np.all(gap <= 1e-3)
    # the drawn centres are the tree's leaf centres placed by the teeth's poses
    a = res.pairs[res.pair_of_leaf[0], 0]
    tooth, tree = d.teeth[a], model.body(a).tree
    assert np.allclose(res.centers_a[0], tooth.to_world(tree.leaf_centers[res.leaf_pairs[0, 0]]))


def test_adjacent_crowns_of_the_parametric_model_touch_at_rest(parametric):
    d, model = parametric
    res = detect_step(model, d.rest_poses(), detector="discrete")
    touching = set(res.touching_pairs())
    assert all(p in touching for p in d.adjacent_pairs())  # crowns in contact (gap <= 0.05 mm)


def test_first_contact_only_agrees_with_all_leaf_pairs_on_which_teeth_touch(parametric):
    d, model = parametric
    full = detect_step(model, d.rest_poses(), detector="discrete")
    first = detect_step(model, d.rest_poses(), detector="discrete", request=CollisionRequest(all_leaf_pairs=False))
    assert np.array_equal(full.touching, first.touching)
    assert np.bincount(first.pair_of_leaf, minlength=len(first.pairs)).max() == 1


# --- the continuous sphere-tree detector ----------------------------------------------------------

@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.parametrize("builder", BUILDERS)
def test_continuous_sphere_trees_never_miss_a_contact_that_dense_exact_sampling_finds(parametric, builder):
    roots = (thin_root_mesh(12.0, 0.35),)
    d, _ = parametric
    sets = [parametric_set(parametric),
            ToothSet("thin_root", roots + (d.teeth[14].mesh, d.teeth[15].mesh), ((0, 1), (0, 2)))]
    report = continuous_study(sets, n_motions=60, tree_builder=BUILDERS[builder], seed=4, samples=200,
                              tunnelling_sets=("thin_root",))
    for name, res in report["sets"].items():
        allk = res["by_kind"]["all"]
        assert allk["exact_contacts"] > 30, name
        assert allk["missed_by_sphere_trees"] == 0, name
        assert allk["later_than_exact_sphere_trees"] == 0, name
        assert allk["missed_after_refinement"] == 0, name
        assert allk["later_than_exact_refined"] == 0, name
        assert allk["refined_within_tolerance"] == allk["exact_contacts"], name
    tunnel = report["sets"]["thin_root"]["by_kind"]["tunnelling"]
    assert tunnel["exact_contacts_unseen_at_both_ends"] > 5  # contacts the discrete test cannot see


def test_a_fast_thin_root_crossing_a_crown_is_caught_although_neither_end_pose_touches():
    root, crown = thin_root_mesh(12.0, 0.3), crown_like_mesh(2)
    model = two_body_model(crown, root)
    start, end = translation([-15, 0, 0]), translation([15, 0, 0])  # 30 mm in one step, through the crown
    for T in (start, end):
        assert not detect_step(model, {2: T}, pairs=[(1, 2)], detector="discrete").touching[0]
    res = detect_step(model, {2: start}, {2: end}, pairs=[(1, 2)], detector="continuous")
    assert res.touching[0]
    truth = dense_first_contact(meshquery.fcl_object(model.bodies[0].mesh), meshquery.fcl_object(model.bodies[1].mesh), np.eye(4), np.eye(4), start, end, 400)
    assert truth is not None and res.time_of_first_contact[0] <= truth[1]


def test_a_point_swept_by_half_a_turn_hits_what_lies_on_its_arc_and_not_on_its_chord():
    # a 10 mm rod turning half a turn about its end sweeps a half disc; a small block sits on the
    # arc at a quarter turn, 8 mm from the chord (which passes through the pivot)
    rod = trimesh.creation.box(extents=[10.0, 0.4, 0.4])
    rod.apply_translation([5.0, 0, 0])
    block = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    model = two_body_model(rod, block, translation([0, 9.0, 0]))
    T1 = np.eye(4)
    T1[:3, :3] = rotation_about_axis([0, 0, 1], np.pi * 0.999)
    truth = dense_first_contact(meshquery.fcl_object(model.bodies[0].mesh), meshquery.fcl_object(model.bodies[1].mesh), np.eye(4), T1,
                                translation([0, 9.0, 0]), translation([0, 9.0, 0]), 400)
    assert truth is not None  # the exact motion does hit the block
    res = detect_step(model, {1: np.eye(4)}, {1: T1}, pairs=[(1, 2)], detector="continuous")
    assert res.touching[0] and res.time_of_first_contact[0] <= truth[1]


def test_refined_time_of_contact_puts_the_teeth_back_just_touching():
    a, b = crown_like_mesh(0), crown_like_mesh(1)
    model = two_body_model(a, b)
    start, end = translation([14, 0.5, 0]), translation([4, 0.5, 0])
    res = detect_step(model, {2: start}, {2: end}, pairs=[(1, 2)], detector="continuous",
                      request=CollisionRequest(refine_time_of_contact=True, contact_tolerance_mm=0.05))
    t = res.time_of_first_contact[0]
    oa, ob = meshquery.fcl_object(model.bodies[0].mesh), meshquery.fcl_object(model.bodies[1].mesh)
    meshquery.set_pose(oa, np.eye(4))
    meshquery.set_pose(ob, interpolate_pose(start, end, t))
    assert not meshquery.collide(oa, ob)[0]  # not yet interpenetrating
    assert meshquery.distance(oa, ob) <= 0.05  # and within 0.05 mm of touching
    sphere_only = detect_step(model, {2: start}, {2: end}, pairs=[(1, 2)], detector="continuous")
    assert sphere_only.time_of_first_contact[0] <= t


def test_a_step_without_motion_is_the_discrete_test_at_time_zero(parametric):
    d, model = parametric
    poses = d.rest_poses()
    disc = detect_step(model, poses, detector="discrete")
    cont = detect_step(model, poses, poses, detector="continuous")
    assert np.array_equal(disc.touching, cont.touching)
    assert np.all(cont.time_of_first_contact[cont.touching] == 0.0)


# --- bounding circles -----------------------------------------------------------------------------

def test_bounding_circles_bound_each_crowns_projection_on_the_occlusal_plane(parametric):
    d, model = parametric
    rng = np.random.default_rng(5)
    poses = {}
    for n, t in d.teeth.items():
        T = t.rest_pose.copy()
        T[:3, :3] = rotation_about_axis(rng.normal(size=3), rng.uniform(0, 0.4)) @ T[:3, :3]
        poses[n] = T
    P = model.pose_array(poses)
    c, r = bounding_circles(model, P)
    for i, body in enumerate(model.bodies):
        assert body.circle_points is not None  # the paper's circles ignore the roots
        v = body.circle_points @ P[i, :3, :3].T + P[i, :3, 3]
        assert np.linalg.norm(v[:, [0, 2]] - c[i], axis=1).max() <= r[i] + 1e-9
    # and at rest each is the smallest such circle: the projection touches it
    c0, r0 = bounding_circles(model, model.pose_array(d.rest_poses()))
    for i, body in enumerate(model.bodies):
        v = body.circle_points @ body.rest_pose[:3, :3].T + body.rest_pose[:3, 3]
        assert np.linalg.norm(v[:, [0, 2]] - c0[i], axis=1).max() == pytest.approx(r0[i], abs=1e-6)


def test_bounding_circles_cannot_tell_an_upper_tooth_from_the_lower_tooth_beneath_it():
    a, b = crown_like_mesh(0), crown_like_mesh(1)
    model = two_body_model(a, b, translation([0, 20.0, 0]))  # 20 mm above: far apart in 3D
    res = {det: detect_step(model, {}, pairs=[(1, 2)], detector=det).touching[0] for det in DETECTORS}
    assert res["circles"] and not res["discrete"] and not res["exact"]


# --- one contract ---------------------------------------------------------------------------------

def test_every_detector_answers_in_the_same_result_type_for_the_same_pairs(parametric):
    d, model = parametric
    poses = d.rest_poses()
    results = {det: detect_step(model, poses, poses, detector=det) for det in DETECTORS}
    pairs = results["discrete"].pairs
    for det, res in results.items():
        assert res.detector == det
        assert np.array_equal(res.pairs, pairs)
        m = len(res.pair_of_leaf)
        assert res.leaf_pairs.shape == (m, 2) and res.centers_a.shape == (m, 3) and res.radii_b.shape == (m,)
        assert res.touching.shape == (len(pairs),)
    per_pair = results["discrete"].by_pair()
    a, b = d.adjacent_pairs()[0]
    assert per_pair[(a, b)].touching and len(per_pair[(a, b)].leaf_pairs) > 0


def test_asking_for_an_unknown_detector_or_tooth_names_the_fix(parametric):
    d, model = parametric
    with pytest.raises(CollisionError, match="detector.*use one of"):
        detect_step(model, d.rest_poses(), detector="octree")
    with pytest.raises(CollisionError, match="tooth 18"):
        detect_step(model, d.rest_poses(), pairs=[(17, 18)])
    with pytest.raises(CollisionError, match="itself"):
        detect_step(model, d.rest_poses(), pairs=[(16, 16)])


def test_asking_for_the_first_contact_only_never_delays_the_time_of_first_contact(parametric):
    from orthosim_bench.collision import perturbed_poses

    d, model = parametric
    start = {n: T for n, T in perturbed_poses(d.rest_poses(), step_mm=1.0, seed=7).items()}
    end = perturbed_poses(d.rest_poses(), step_mm=1.0, seed=8)
    full = detect_step(model, start, end, detector="continuous")
    first = detect_step(model, start, end, detector="continuous", request=CollisionRequest(all_leaf_pairs=False))
    assert full.touching.any()
    assert np.array_equal(full.touching, first.touching)
    assert np.allclose(np.nan_to_num(full.time_of_first_contact, nan=2), np.nan_to_num(first.time_of_first_contact, nan=2))


@pytest.mark.parametrize("turn", [0.0, 0.6])
def test_continuous_contact_leaves_are_drawn_where_the_teeth_are_at_first_contact(turn):
    a, b = crown_like_mesh(0), crown_like_mesh(1)
    model = two_body_model(a, b)
    start = translation([12, 0.5, 0])
    end = translation([5, 0.5, 0])
    end[:3, :3] = rotation_about_axis([0, 1, 0], turn)
    res = detect_step(model, {2: start}, {2: end}, pairs=[(1, 2)], detector="continuous")
    t = res.time_of_first_contact[0]
    assert 0 < t < 1 and len(res.leaf_pairs) > 0
    pose_b = interpolate_pose(start, end, t)
    leaves_b = model.bodies[1].tree.leaf_centers[res.leaf_pairs[:, 1]]
    expected = leaves_b @ pose_b[:3, :3].T + pose_b[:3, 3]
    assert np.abs(res.centers_b - expected).max() <= 1e-3


def test_false_positive_bands_count_each_separated_pose_once_in_its_band():
    from orthosim.collision.validate import false_positive_bands

    dist = np.array([0.0, 0.05, 0.1, 0.12, 0.2, 0.25, 0.3, 0.9, 1.5, 4.0])
    found = np.array([True, True, True, True, False, False, True, False, False, False])
    bands = false_positive_bands(dist, found)
    assert sum(b["poses"] for b in bands.values()) == 9  # the intersecting pose (distance 0) is in none
    assert bands["0.1-0.25mm"] == {"poses": 3, "rate": 1 / 3}  # 0.12 and 0.2 and 0.25; 0.1 is the band below
    assert bands["0.0-0.1mm"] == {"poses": 2, "rate": 1.0}
    assert bands[">2.0mm"] == {"poses": 1, "rate": 0.0}
    assert bands["1.0-2.0mm"]["rate"] == 0.0


def test_times_only_give_the_same_pairs_and_times_without_drawn_leaves(parametric):
    from orthosim.collision import ExactQueries
    from orthosim_bench.collision import perturbed_poses

    d, model = parametric
    start = perturbed_poses(d.rest_poses(), step_mm=1.0, seed=7)
    end = perturbed_poses(d.rest_poses(), step_mm=1.0, seed=8)
    for refine in (False, True):
        q = ExactQueries(model)
        drawn = detect_step(model, start, end, detector="continuous", queries=q,
                            request=CollisionRequest(all_leaf_pairs=False, refine_time_of_contact=refine))
        times = detect_step(model, start, end, detector="continuous", queries=q,
                            request=CollisionRequest(all_leaf_pairs=False, refine_time_of_contact=refine, drawn_leaves=False))
        assert drawn.touching.any() and len(drawn.leaf_pairs) > 0
        assert np.array_equal(times.pairs, drawn.pairs) and np.array_equal(times.touching, drawn.touching)
        assert np.array_equal(times.time_of_first_contact, drawn.time_of_first_contact, equal_nan=True)
        assert len(times.leaf_pairs) == len(times.pair_of_leaf) == len(times.centers_a) == 0


def test_pair_indices_of_a_list_or_an_array_of_pairs_agree(parametric):
    d, model = parametric
    pairs = [(13, 14), (46, 16), (21, 11)]
    expected = [[model.index[a], model.index[b]] for a, b in pairs]
    assert model.pair_indices(pairs).tolist() == expected
    assert model.pair_indices(np.array(pairs)).tolist() == expected
    assert model.pair_indices(np.array(pairs).ravel()).tolist() == expected
    assert model.pair_indices([]).shape == (0, 2)
    with pytest.raises(CollisionError, match="tooth 18"):
        model.pair_indices(np.array([(17, 18)]))

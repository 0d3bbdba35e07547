"""The exact reference (distance, vertex-based penetration depth), the generic broad phase, and the
bench record the CLI publishes."""

import numpy as np
import pytest
import trimesh

from collision_helpers import median_split_tree
from orthosim.collision import Body, CollisionModel, default_pairs, detect_step
from orthosim.geometry.meshquery import penetration_depth
from orthosim.geometry.pose import translation


def box_model(offset):
    a = trimesh.creation.box(extents=[2, 2, 2])
    b = trimesh.creation.box(extents=[2, 2, 2])
    return CollisionModel([Body(1, a, median_split_tree(a), np.eye(4)),
                           Body(2, b, median_split_tree(b), translation(offset))])


def test_the_exact_detector_reports_true_distances_between_apart_teeth():
    res = detect_step(box_model([2.7, 0, 0]), {}, pairs=[(1, 2)], detector="exact")
    assert not res.touching[0] and res.distance[0] == pytest.approx(0.7, abs=1e-6)


def test_penetration_depth_is_how_deep_a_vertex_sits_inside_the_other_mesh():
    a = trimesh.creation.box(extents=[2, 2, 2])
    b = trimesh.creation.box(extents=[2, 1, 1])
    # b's end vertices at x = 0.7 lie 0.3 mm inside a's face x = 1 (and 0.5 mm from its other faces)
    assert penetration_depth(a, np.eye(4), b, translation([1.7, 0, 0])) == pytest.approx(0.3, abs=1e-6)
    assert penetration_depth(a, np.eye(4), b, translation([2.5, 0, 0])) == 0.0


def test_bodies_that_are_not_an_arch_get_pairs_from_sweep_and_prune():
    assert default_pairs(box_model([10, 0, 0])) == []
    assert default_pairs(box_model([2.5, 0, 0])) == [(1, 2)]


def test_the_bench_record_times_every_detector_and_fcl_on_the_same_pairs():
    from orthosim_bench.collision import collision_timings
    from orthosim.model.parametric import parametric_dentition

    d = parametric_dentition(resolution="coarse")
    rec = collision_timings(d, repeats=1, tree_builder=median_split_tree)
    assert set(rec["collision_us_per_step"]) == {"circles", "discrete", "continuous", "fcl_boolean", "fcl_all_contacts"}
    assert all(v > 0 for v in rec["collision_us_per_step"].values())
    assert rec["candidate_pairs"] == len(default_pairs(CollisionModel.from_dentition(d, tree_builder=median_split_tree)))
    assert rec["collision_step"]["discrete_touching_pairs"] >= len(d.adjacent_pairs())  # crowns touch at rest


def test_the_generic_broad_phase_keeps_bodies_that_meet_only_during_the_step():
    model = box_model([10, 0, 0])
    res = detect_step(model, {2: translation([10, 0, 0])}, {2: translation([-10, 0, 0])}, detector="continuous")
    assert [tuple(p) for p in res.pairs] == [(1, 2)] and res.touching[0]


def test_the_swept_sphere_broad_phase_pairs_any_two_teeth_that_may_meet_during_the_motion():
    """Staging's broad phase: teeth of either arch, anywhere along it, whose sweeps may meet."""
    from orthosim.collision import swept_sphere_pairs

    a = trimesh.creation.box(extents=[2, 2, 2])
    b = trimesh.creation.box(extents=[2, 2, 2])
    model = CollisionModel([Body(11, a, median_split_tree(a), np.eye(4)),
                            Body(36, b, median_split_tree(b), translation([10, 0, 0]))])
    at_rest = model.pose_array({})
    closer = model.pose_array({36: translation([2.5, 0, 0])})  # 36 moves to 0.5 mm from 11
    assert default_pairs(model, at_rest, poses_end=closer) == []  # FDI teeth: neighbours and facing teeth only
    assert swept_sphere_pairs(model, at_rest, closer) == [(11, 36)]
    assert swept_sphere_pairs(model, at_rest, at_rest) == []
    assert swept_sphere_pairs(model, at_rest, at_rest, margin_mm=4.0) == [(11, 36)]  # root spheres 6.5 mm apart
    assert swept_sphere_pairs(model, closer, closer) == [(11, 36)]
    assert swept_sphere_pairs(model, closer, closer, moving_only=True) == []  # nothing moves: nothing new can meet

"""Exact time of first contact by conservative advancement: bounded by relative motion, never late."""

import numpy as np
import pytest
import trimesh

from collision_helpers import median_split_tree
from orthosim.collision.continuous import refine_time_of_contact
from orthosim.collision.model import Body, CollisionModel
from orthosim.geometry.motion import relative_speed_bound
from orthosim.geometry import meshquery
from orthosim.geometry.pose import translation


def two_boxes():
    a = trimesh.creation.box([4.0, 4.0, 4.0])
    b = trimesh.creation.box([4.0, 4.0, 4.0])
    return CollisionModel([Body(1, a, median_split_tree(a), np.eye(4)), Body(2, b, median_split_tree(b), np.eye(4))])


def count_distance_calls(monkeypatch):
    calls = {"n": 0}
    original = meshquery.distance

    def counted(a, b, **kwargs):
        calls["n"] += 1
        return original(a, b, **kwargs)

    monkeypatch.setattr(meshquery, "distance", counted)
    return calls


def test_speed_bound_is_relative_motion_plus_rotation():
    T0, T1 = np.eye(4), translation([1.0, 0.0, 0.0])
    assert relative_speed_bound(T0, T1, 5.0, T0, T1, 5.0) == pytest.approx(0.0)
    assert relative_speed_bound(T0, T1, 5.0, T0, T0, 5.0) == pytest.approx(1.0)


def test_teeth_moving_together_are_not_stopped_and_cost_few_queries(monkeypatch):
    model = two_boxes()
    calls = count_distance_calls(monkeypatch)
    # b sits 0.02 mm to the right of a; both slide 2 mm right together, b slightly faster
    start_b = translation([4.02, 0.0, 0.0])
    t = refine_time_of_contact(model, 0, 1, np.eye(4), translation([2.0, 0, 0]), start_b,
                               start_b @ translation([2.001, 0, 0]), 0.0)
    assert t is None
    assert calls["n"] <= 3


def test_head_on_contact_is_found_no_later_than_the_truth_and_within_tolerance():
    model = two_boxes()
    # a moves 3 mm toward b, whose face is 1 mm away: true contact at t = 1/3
    start_b = translation([5.0, 0.0, 0.0])
    t = refine_time_of_contact(model, 0, 1, np.eye(4), translation([3.0, 0, 0]), start_b, start_b, 0.0,
                               tolerance=0.05)
    assert t is not None and t <= 1 / 3 + 1e-9
    assert (1 / 3 - t) * 3.0 <= 0.05  # within tolerance of travel


def test_intersecting_contact_lets_teeth_end_just_apart_where_the_travel_tolerance_reports_them():
    """The staging planner's question: aligner stages end with neighbours a hundredth of a
    millimetre apart by design, which is no contact; where the speed bound is loose (a turning
    tooth), the simulator's travel tolerance reports such an end as contact, conservatively."""
    from orthosim.collision.contract import INTERSECTING
    from orthosim.geometry.motion import rotation_matrix

    model = two_boxes()
    start_b = translation([5.0, 0.0, 0.0])  # b's face 1 mm from a's
    # a moves 0.99 mm toward b, ending 0.01 mm short, spinning a radian about the axis of approach
    # (its face toward b stays square to it, but every corner counts in the speed bound)
    end_a = translation([0.99, 0, 0])
    end_a[:3, :3] = rotation_matrix(np.array([1.0, 0.0, 0.0]))
    assert refine_time_of_contact(model, 0, 1, np.eye(4), end_a, start_b, start_b, 0.0, tolerance=0.05) is not None
    assert refine_time_of_contact(model, 0, 1, np.eye(4), end_a, start_b, start_b, 0.0, tolerance=0.002,
                                  contact=INTERSECTING) is None


def test_intersecting_contact_is_found_within_one_shortest_stride_after_the_truth():
    from orthosim.collision.contract import INTERSECTING
    from orthosim.collision.queries import ExactQueries

    model = two_boxes()
    queries = ExactQueries(model)
    # a moves 3 mm toward b, whose face is 1 mm away: the meshes meet at t = 1/3
    start_b = translation([5.0, 0.0, 0.0])
    t = refine_time_of_contact(model, 0, 1, np.eye(4), translation([3.0, 0, 0]), start_b, start_b, 0.0,
                               tolerance=0.002, queries=queries, contact=INTERSECTING)
    assert t is not None and 1 / 3 - 1e-9 <= t and (t - 1 / 3) * 3.0 <= 0.002 + 1e-9
    assert queries.body_intersects(0, translation([3.0 * t, 0, 0]), 1, start_b)


def test_a_request_for_an_unknown_meaning_of_contact_is_refused():
    from orthosim.collision import CollisionRequest
    from orthosim.collision.contract import CollisionError

    with pytest.raises(CollisionError, match="contact"):
        CollisionRequest(contact="nearly")

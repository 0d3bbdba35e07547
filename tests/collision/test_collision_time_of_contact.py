"""Eq. 2 of the paper (first time of contact of two linearly moving spheres) and the step bounds
the continuous detector prunes with, against hand-worked cases and dense sampling."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from orthosim.collision.time_of_contact import (
    contact_interval,
    first_time_of_contact,
    interval_lower_bound,
    min_distance_over_step,
)


def toc(A, B, R):
    return first_time_of_contact(np.array([A], float), np.array([B], float), np.array([R], float))[0]


def test_head_on_spheres_meet_when_the_gap_is_closed():
    # centres 10 mm apart closing at 20 mm per step, radii summing to 2 mm: gap 8 mm closes at t = 0.4
    assert toc([10, 0, 0], [-20, 0, 0], 2.0) == pytest.approx(0.4)


def test_glancing_spheres_meet_where_the_offset_path_reaches_the_radius_sum():
    # passing 1 mm off-centre: (10 - 20 t)^2 + 1 = 4
    assert toc([10, 1, 0], [-20, 0, 0], 2.0) == pytest.approx((10 - math.sqrt(3)) / 20)
    # grazing exactly at 2 mm: they touch at closest approach, t = 0.5
    assert toc([10, 2, 0], [-20, 0, 0], 2.0) == pytest.approx(0.5)
    # passing 2.01 mm away: no contact
    assert np.isnan(toc([10, 2.01, 0], [-20, 0, 0], 2.0))


def test_spheres_already_overlapping_at_the_start_touch_at_time_zero():
    assert toc([1, 0, 0], [-20, 0, 0], 2.0) == 0.0
    assert toc([1, 0, 0], [20, 0, 0], 2.0) == 0.0  # even when moving apart


def test_parallel_motion_never_closes_the_gap():
    assert np.isnan(toc([0, 5, 0], [10, 0, 0], 2.0))
    assert np.isnan(toc([5, 0, 0], [10, 0, 0], 2.0))  # moving apart along the line of centres


def test_no_motion_means_contact_only_when_already_overlapping():
    assert np.isnan(toc([5, 0, 0], [0, 0, 0], 2.0))
    assert toc([1.5, 0, 0], [0, 0, 0], 2.0) == 0.0


def test_contact_at_or_after_the_end_of_the_step_is_not_in_the_step():
    assert np.isnan(toc([10, 0, 0], [-8, 0, 0], 2.0))  # exactly at t = 1
    assert np.isnan(toc([10, 0, 0], [-4, 0, 0], 2.0))  # would meet at t = 2


def test_contact_interval_ends_when_the_spheres_separate():
    enter, leave = contact_interval(np.array([[10.0, 0, 0]]), np.array([[-20.0, 0, 0]]), np.array([2.0]))
    assert enter[0] == pytest.approx(0.4) and leave[0] == pytest.approx(0.6)


vec = st.lists(st.floats(-20, 20, allow_nan=False), min_size=3, max_size=3)


@settings(max_examples=300, deadline=None)
@given(A=vec, B=vec, R=st.floats(0.01, 10))
def test_first_time_of_contact_agrees_with_dense_sampling(A, B, R):
    A, B = np.array(A), np.array(B)
    t = toc(A, B, R)
    s = np.linspace(0, 1, 2001)[:-1]
    dist = np.linalg.norm(A[None] + s[:, None] * B[None], axis=1)
    tol = 1e-6 * (1 + np.linalg.norm(A) + np.linalg.norm(B))
    if np.isnan(t):
        assert np.all(dist > R - tol)
    else:
        assert 0 <= t < 1
        assert np.linalg.norm(A + t * B) <= R + tol  # touching at t
        assert np.all(dist[s < t] > R - tol)  # and not before


@settings(max_examples=300, deadline=None)
@given(A=vec, B=vec)
def test_step_bounds_never_exceed_the_true_minimum_distance(A, B):
    A, B = np.array([A]), np.array([B])
    s = np.linspace(0, 1, 4001)
    true_min = np.linalg.norm(A + s[:, None] * B, axis=1).min()
    exact = min_distance_over_step(A, B)[0]
    assert exact <= true_min + 1e-9
    assert exact >= true_min - 1e-2 * (1 + np.linalg.norm(B))  # tight: it is the minimum itself
    assert interval_lower_bound(A, B)[0] <= exact**2 + 1e-9  # the paper's bound is looser, still valid

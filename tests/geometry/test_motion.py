"""The motion of a tooth within a step (linear translation, constant angular velocity about the
local origin) and the bound on how far it strays from the straight chord the paper interpolates."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from orthosim.geometry.motion import chord_deviation_bound, interpolate_pose, rotation_angle
from orthosim.geometry.pose import rotation_about_axis


def pose(R, p):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def test_the_step_starts_and_ends_at_the_given_poses():
    T0 = pose(rotation_about_axis([0, 1, 0], 0.3), [1, 2, 3])
    T1 = pose(rotation_about_axis([1, 1, 0], 1.1), [4, 0, -2])
    assert np.allclose(interpolate_pose(T0, T1, 0.0), T0)
    assert np.allclose(interpolate_pose(T0, T1, 1.0), T1)


def test_half_way_through_a_quarter_turn_the_tooth_has_turned_an_eighth():
    T0 = np.eye(4)
    T1 = pose(rotation_about_axis([0, 0, 1], np.pi / 2), [2, 0, 0])
    mid = interpolate_pose(T0, T1, 0.5)
    assert np.allclose(mid[:3, :3], rotation_about_axis([0, 0, 1], np.pi / 4))
    assert np.allclose(mid[:3, 3], [1, 0, 0])  # the local origin moves on a straight line
    assert rotation_angle(T0, T1) == pytest.approx(np.pi / 2)


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    angle=st.floats(0.0, np.pi),
    point=st.lists(st.floats(-20, 20), min_size=3, max_size=3),
)
def test_no_point_of_a_turning_tooth_strays_from_its_chord_beyond_the_bound(seed, angle, point):
    rng = np.random.default_rng(seed)
    R0 = Rotation.random(random_state=rng).as_matrix()
    axis = rng.normal(size=3)
    R1 = rotation_about_axis(axis, angle) @ R0
    T0, T1 = pose(R0, rng.normal(size=3) * 5), pose(R1, rng.normal(size=3) * 5)
    x = np.array(point)
    ts = np.linspace(0, 1, 201)
    path = interpolate_pose(T0, T1, ts)
    X = np.einsum("tij,j->ti", path[:, :3, :3], x) + path[:, :3, 3]
    chord = X[0] + ts[:, None] * (X[-1] - X[0])
    deviation = np.linalg.norm(X - chord, axis=1).max()
    assert deviation <= chord_deviation_bound(rotation_angle(T0, T1), np.linalg.norm(x)) + 1e-9


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_no_two_points_of_two_moving_teeth_approach_faster_than_the_relative_speed_bound(seed):
    from orthosim.geometry.motion import relative_speed_bound

    rng = np.random.default_rng(seed)
    ends = []
    for _ in range(2):
        R0 = Rotation.random(random_state=rng).as_matrix()
        R1 = rotation_about_axis(rng.normal(size=3), rng.uniform(0, np.pi)) @ R0
        ends.append((pose(R0, rng.normal(size=3) * 5), pose(R1, rng.normal(size=3) * 5)))
    (A0, A1), (B0, B1) = ends
    xa, xb = rng.normal(size=3) * 5, rng.normal(size=3) * 5
    bound = relative_speed_bound(A0, A1, np.linalg.norm(xa), B0, B1, np.linalg.norm(xb))
    ts = np.linspace(0, 1, 401)
    Pa, Pb = interpolate_pose(A0, A1, ts), interpolate_pose(B0, B1, ts)
    gap = np.linalg.norm((Pa[:, :3, :3] @ xa + Pa[:, :3, 3]) - (Pb[:, :3, :3] @ xb + Pb[:, :3, 3]), axis=1)
    assert np.all(np.abs(np.diff(gap)) <= bound * np.diff(ts) + 1e-9)

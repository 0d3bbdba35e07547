"""The movement model as the paper and the orthodontic literature state it: centres of resistance and
rotation, the moment-to-force table, the wire models and the rate of movement."""

import numpy as np
import pytest

from orthosim.errors import CaseError
from orthosim.mechanics.biomechanics import RateLaw, build_mechanics, movement_type, tooth_motion
from orthosim.mechanics.resistance import center_of_resistance, tipping_center
from orthosim.model.parametric import parametric_dentition

LAW = RateLaw()
MONTH = 30.0


@pytest.fixture(scope="module")
def dent():
    return parametric_dentition("coarse")


def _world(tooth, local, pose=None):
    return tooth.to_world(local, pose)


# --- centre of resistance -------------------------------------------------------------------

def test_the_papers_centre_of_resistance_is_a_third_of_the_root_from_the_apex(dent):
    for n in (11, 13, 15, 16, 36, 43):
        t = dent.teeth[n]
        cr = center_of_resistance(t, "paper")
        assert cr[1] - t.apex[1] == pytest.approx(t.root_length / 3)


@pytest.mark.parametrize("fraction", [1 / 3, 0.4, 0.5])
def test_the_literature_centre_lies_that_fraction_of_the_embedded_root_below_the_crest(dent, fraction):
    t = dent.teeth[13]
    crest = -1.5
    cr = center_of_resistance(t, "literature", fraction)
    assert (crest - cr[1]) / (crest - t.apex[1]) == pytest.approx(fraction)


def test_the_literature_rule_is_the_default_and_differs_from_the_papers(dent):
    t = dent.teeth[11]
    assert np.allclose(center_of_resistance(t), center_of_resistance(t, "literature", 0.4))
    assert not np.allclose(center_of_resistance(t), center_of_resistance(t, "paper"))


def test_molars_resist_near_the_furcation(dent):
    for n, furcation in ((16, -4.0), (46, -3.0)):
        cr = center_of_resistance(dent.teeth[n])
        assert furcation - 2.0 < cr[1] < furcation  # just apical of the furcation, far above the apex
        assert cr[1] > dent.teeth[n].apex[1] / 2


def test_a_fraction_outside_a_third_to_a_half_is_refused(dent):
    with pytest.raises(CaseError, match="between 0.333 and 0.5"):
        center_of_resistance(dent.teeth[11], "literature", 0.7)


# --- moment-to-force ratio -------------------------------------------------------------------

@pytest.mark.parametrize("n", [11, 15, 35])
@pytest.mark.parametrize("m_over_f, expected", [
    (0.0, "uncontrolled tipping"), (3.0, "uncontrolled tipping"), (5.0, "uncontrolled tipping"),
    (7.0, "controlled tipping"), (10.0, "translation"), (12.5, "root movement"), (15.0, "root movement")])
def test_the_moment_to_force_ratio_decides_the_movement(dent, n, m_over_f, expected):
    mech = build_mechanics(dent.teeth[n])
    assert 9.5 <= mech.bracket_lever_mm <= 11.0  # an average single-rooted tooth
    assert movement_type(mech, m_over_f) == expected


def test_the_centre_of_rotation_follows_the_moment_to_force_ratio_in_the_simulated_motion(dent):
    # a bracket force with a counter-couple: the still point of the motion is where the table says
    t = dent.teeth[15]
    mech = build_mechanics(t)
    pose = np.eye(4)
    F = np.array([-100.0, 0.0, 0.0]) * 1  # along local x (mesiodistal), at the bracket
    B = mech.bracket
    lever = B[1] - mech.center_of_resistance[1]
    for m_over_f in (2.0, 5.0, 7.0, 12.0):  # M/F = 0 is the round wire (below); a rectangular wire without couple translates
        # the couple opposing the force's tipping moment about the centre of resistance
        tip = np.cross(B - mech.center_of_resistance, F)  # about z (tipping) and y (the labial offset)
        couple = -np.sign(tip[2]) * np.array([0.0, 0.0, 100.0 * m_over_f])  # opposes the tipping
        m = tooth_motion(mech, pose, F, B, couple, "rectangular", False, LAW)
        # the point of the long axis that does not move (in the plane of tipping)
        ys = np.linspace(-40, 40, 8001)
        pts = np.stack([np.zeros_like(ys), ys, np.zeros_like(ys)], axis=1)
        still_y = ys[np.argmin(np.abs(m.displacement(pts, 1.0)[:, 0]))]
        expected = mech.center_of_resistance[1] - mech.sigma2_mm2 / (lever - m_over_f)
        assert still_y == pytest.approx(expected, abs=0.05)


# --- wire models ----------------------------------------------------------------------------

@pytest.mark.parametrize("direction", [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.6, -0.8, 0]])
def test_a_rectangular_wire_with_a_pure_force_translates_without_rotating(dent, direction):
    t = dent.teeth[13]
    mech = build_mechanics(t)
    F = 120.0 * np.asarray(direction, float)
    point = _world(t, mech.bracket)
    m = tooth_motion(mech, t.rest_pose, F, point, np.zeros(3), "rectangular", True, LAW)
    assert np.allclose(m.omega, 0.0)
    d = m.displacement(np.array([_world(t, mech.apex), _world(t, mech.crown_center)]), MONTH)
    assert np.allclose(d[0], d[1])  # every point moves alike: x, y and z
    assert np.allclose(d[0] / np.linalg.norm(d[0]), F / np.linalg.norm(F))


@pytest.mark.parametrize("direction", [[1, 0, 0], [0, 0, 1], [0, 1, 0]])
def test_a_round_wire_never_translates_a_tooth_it_turns_it_about_a_third_of_the_root(dent, direction):
    t = dent.teeth[13]
    mech = build_mechanics(t)
    F = 120.0 * np.asarray(direction, float)
    pose = t.rest_pose
    m = tooth_motion(mech, pose, F, _world(t, mech.bracket), np.zeros(3), "round", False, LAW)
    pivot = _world(t, tipping_center(t))
    assert np.allclose(m.displacement(pivot, MONTH), 0.0, atol=1e-12)  # the 1/3-root point stays
    assert np.allclose(m.velocity, 0.0)
    crown_move = m.displacement(_world(t, mech.bracket), MONTH)[0]
    apex_move = m.displacement(_world(t, mech.apex), MONTH)[0]
    if abs(np.asarray(direction) @ (pose[:3, :3] @ [0, 1, 0])) < 0.9:  # force across the long axis
        assert np.linalg.norm(m.omega) > 0
        assert crown_move @ F > 0 and apex_move @ F < 0  # crown along the force, apex the other way


def test_a_rectangular_wire_with_a_torque_turns_the_tooth_about_its_crown(dent):
    t = dent.teeth[11]
    mech = build_mechanics(t)
    couple = 1500.0 * (t.rest_pose[:3, :3] @ t.mesial)  # cN*mm about the mesiodistal axis: torque
    m = tooth_motion(mech, t.rest_pose, np.zeros(3), _world(t, mech.bracket), couple, "rectangular", False, LAW)
    assert np.linalg.norm(m.omega) > 0
    assert np.allclose(m.displacement(_world(t, mech.bracket), MONTH), 0.0, atol=1e-12)
    assert np.linalg.norm(m.displacement(_world(t, mech.apex), MONTH)) > 0.1  # the root moves


def test_a_couple_about_the_long_axis_rotates_the_tooth_about_its_long_axis(dent):
    t = dent.teeth[12]
    mech = build_mechanics(t)
    axis = t.rest_pose[:3, :3] @ t.long_axis
    m = tooth_motion(mech, t.rest_pose, np.zeros(3), _world(t, mech.bracket), 600.0 * axis, "rectangular", False, LAW)
    assert np.allclose(np.cross(m.omega, axis), 0.0, atol=1e-12) and m.omega @ axis > 0
    for local in (mech.center_of_resistance, mech.apex, np.zeros(3)):
        assert np.allclose(m.displacement(_world(t, local), MONTH), 0.0, atol=1e-9)


# --- rate -----------------------------------------------------------------------------------

def test_below_the_threshold_a_tooth_does_not_move():
    assert LAW.rate(15.0, LAW.reference_root_area_mm2) == 0.0
    assert not LAW.moves(19.9, LAW.reference_root_area_mm2)


@pytest.mark.parametrize("force", [100.0, 125.0, 150.0])
def test_bodily_movement_at_100_to_150_cN_is_half_to_one_mm_a_month(dent, force):
    for n in (15, 25, 35, 45):
        per_month = LAW.rate(force, build_mechanics(dent.teeth[n]).root_area_mm2) * MONTH
        assert 0.5 <= per_month <= 1.0 + 1e-9


def test_the_rate_grows_with_the_load_and_saturates():
    f = np.array([20.0, 40.0, 80.0, 120.0, 150.0, 300.0])
    r = LAW.rate(f, LAW.reference_root_area_mm2)
    assert np.all(np.diff(r[:5]) > 0) and r[5] == r[4]


def test_a_molar_moves_slower_than_a_premolar_under_the_same_force(dent):
    molar, premolar = build_mechanics(dent.teeth[16]), build_mechanics(dent.teeth[15])
    assert LAW.rate(150.0, molar.root_area_mm2) < LAW.rate(150.0, premolar.root_area_mm2)


def test_the_rate_of_one_force_is_the_arrays_number_to_the_last_bit():
    rng = np.random.default_rng(3)
    forces = np.concatenate([[0.0, LAW.threshold_cN, LAW.saturation_cN, 1e-300, 1e6], rng.uniform(0, 400, 500)])
    areas = rng.uniform(40.0, 600.0, len(forces))
    for law in (LAW, RateLaw(threshold_cN=7.0, saturation_cN=91.0, max_rate_mm_per_day=0.05, reference_root_area_mm2=173.0)):
        want = law.rate(forces, areas)  # the numpy path, element by element the same operations
        got = [law.rate(float(f), float(a)) for f, a in zip(forces, areas)]
        assert all(isinstance(g, float) for g in got)
        assert np.array_equal(np.array(got), want)
        assert [law.moves(float(f), float(a)) for f, a in zip(forces, areas)] == list(want > 0)


def test_a_motions_turn_is_found_once_per_step_length_and_moves_points_as_before():
    from orthosim.mechanics.biomechanics import Motion, _rotation

    m = Motion(np.array([1.0, 2.0, 3.0]), np.array([0.01, 0.0, -0.02]), np.array([0.001, 0.02, -0.003]))
    R = m.rotation(2.0)
    assert m.rotation(2.0) is R and np.array_equal(R, _rotation(m.omega * 2.0))
    assert np.array_equal(m.rotation(30.0), _rotation(m.omega * 30.0))
    p = np.array([[4.0, -1.0, 2.5]])
    expected = (p - m.pivot) @ _rotation(m.omega * 30.0).T + m.pivot + m.velocity * 30.0 - p
    assert np.array_equal(m.displacement(p, 30.0), expected)

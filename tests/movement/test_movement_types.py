"""Each movement type and wire model in the running simulator, one tooth at a time, and occlusion
stopping vertical movement. Coarse parametric teeth; a tooth's neighbours are extracted where the
claim is about the tooth's own motion, so no contact interferes."""

import numpy as np
import pytest

from collision_helpers import median_split_tree
from movement_helpers import coarse_case
from orthosim.collision import CollisionModel, ExactQueries
from orthosim.errors import CaseError
from orthosim.movement import MovementModel, simulate
from orthosim.mechanics.biomechanics import RateLaw
from orthosim.mechanics.resistance import tipping_center
from orthosim.model.parametric import parametric_dentition


@pytest.fixture(scope="module")
def built():
    dent = parametric_dentition("coarse")
    return dent, CollisionModel.from_dentition(dent, tree_builder=median_split_tree)


def _case(tmp_path, extractions, load, wire="rectangular", days=56, step=7):
    return coarse_case(tmp_path, extractions, load, wire, days, step)


def _run(built, case, detector="continuous"):
    dent, cm = built
    model = MovementModel.build(case, dent, cm)
    return model, list(simulate(model, detector))


def _world(model, n, local, pose):
    return model.dentition.teeth[n].to_world(local, pose)


def test_bodily_translation_moves_every_point_of_the_tooth_alike(built, tmp_path):
    case = _case(tmp_path, [14, 16], 'teeth = [15]\nforce_cN = 150\ndirection = "mesial"\nmovement = "translation"')
    model, recs = _run(built, case)
    T0, T1 = recs[0].poses[15], recs[-1].poses[15]
    assert np.allclose(T0[:3, :3], T1[:3, :3], atol=1e-12)  # no rotation
    t = model.dentition.teeth[15]
    moved = _world(model, 15, t.crown_center, T1) - _world(model, 15, t.crown_center, T0)
    toward_canine = _world(model, 13, model.dentition.teeth[13].crown_center, T0) - _world(model, 15, t.crown_center, T0)
    assert moved @ toward_canine > 0  # mesially, along the arch
    rate = RateLaw().rate(150, model.mechanics[15].root_area_mm2)
    assert np.linalg.norm(moved) == pytest.approx(rate * 56, rel=0.02)  # the rate law, 8 weeks
    assert np.allclose(_world(model, 15, t.apex, T1) - _world(model, 15, t.apex, T0), moved)


def test_a_round_wire_tips_the_tooth_about_a_third_of_its_root(built, tmp_path):
    case = _case(tmp_path, [14, 16], 'teeth = [15]\nforce_cN = 150\ndirection = "mesial"', wire="round")
    model, recs = _run(built, case)
    T0, T1 = recs[0].poses[15], recs[-1].poses[15]
    t = model.dentition.teeth[15]
    q = tipping_center(t)
    assert np.allclose(_world(model, 15, q, T0), _world(model, 15, q, T1), atol=1e-9)  # never translates
    crown = _world(model, 15, t.crown_center, T1) - _world(model, 15, t.crown_center, T0)
    apex = _world(model, 15, t.apex, T1) - _world(model, 15, t.apex, T0)
    assert crown @ apex < 0 and np.linalg.norm(crown) > 0.2  # crown one way, apex the other: tipping


def test_a_couple_about_the_long_axis_rotates_the_tooth_in_place(built, tmp_path):
    case = _case(tmp_path, [14, 16], 'teeth = [15]\nmoment_cNmm = 900\nmoment_axis = "long_axis"\nmovement = "rotation"')
    model, recs = _run(built, case)
    T0, T1 = recs[0].poses[15], recs[-1].poses[15]
    angle = np.degrees(np.arccos(np.clip((np.trace(T0[:3, :3].T @ T1[:3, :3]) - 1) / 2, -1, 1)))
    assert angle > 3.0
    axis0, axis1 = T0[:3, 1], T1[:3, 1]
    assert np.allclose(axis0, axis1, atol=1e-9)  # about the long axis: the axis itself stays
    cr = model.mechanics[15].center_of_resistance
    assert np.allclose(_world(model, 15, cr, T0), _world(model, 15, cr, T1), atol=1e-9)


@pytest.mark.parametrize("movement, sign", [("extrusion", 1.0), ("intrusion", -1.0)])
def test_extrusion_and_intrusion_move_the_tooth_along_its_long_axis(built, tmp_path, movement, sign):
    case = _case(tmp_path, [12, 14], f'teeth = [13]\nforce_cN = 100\nmovement = "{movement}"', days=28)
    model, recs = _run(built, case)
    T0, T1 = recs[0].poses[13], recs[-1].poses[13]
    d = T1[:3, 3] - T0[:3, 3]
    crownward = T0[:3, 1]  # local +y: apex -> crown; upper teeth point down
    assert d @ crownward == pytest.approx(sign * np.linalg.norm(d), rel=1e-9)
    assert np.linalg.norm(d) > 0.2 and np.allclose(T0[:3, :3], T1[:3, :3])


def test_occlusion_stops_extrusion_at_the_opposing_tooth_just_touching(built, tmp_path):
    # the upper canine, its neighbours out, extruded toward the lower canine 1 mm away; two-week
    # steps close more of the gap per step than is left at the step before contact (measured)
    case = _case(tmp_path, [12, 14], 'teeth = [13]\nforce_cN = 100\nmovement = "extrusion"', days=140, step=14)
    model, recs = _run(built, case, "continuous")
    first = next(r for r in recs if any(set(e.pair) == {13, 43} for e in r.collisions))
    assert ExactQueries(model.collision).distance((13, 43), first.poses) < 0.05  # stopped just touching
    assert max(r.max_penetration_mm for r in recs) < 0.05
    # the contact cut the step short: less travel than the free rate gives, at least the 1 mm gap
    moved = np.linalg.norm(first.poses[13][:3, 3] - recs[0].poses[13][:3, 3])
    free = RateLaw().rate(100, model.mechanics[13].root_area_mm2) * first.time_days
    assert 1.0 <= moved < free - 0.01
    # afterwards the canine goes no further than the lower canine gives way: they stay just touching
    for r in recs[first.step:]:
        assert ExactQueries(model.collision).distance((13, 43), r.poses) < 0.05


def test_a_load_on_an_extracted_tooth_is_refused_before_the_run(tmp_path):
    with pytest.raises(CaseError) as err:
        _case(tmp_path, [14, 24], 'teeth = [14]\nforce_cN = 100\nmovement = "translation"')
    msg = str(err.value)
    assert "loads[0].teeth[0]" in msg and "extracted" in msg and "fix:" in msg and "\n" not in msg


def test_a_wire_that_cannot_do_the_movement_is_refused_before_the_run(tmp_path):
    with pytest.raises(CaseError) as err:
        _case(tmp_path, [], 'teeth = [11]\nforce_cN = 100\nmovement = "translation"', wire="round")
    msg = str(err.value)
    assert "loads[0].movement" in msg and "round wire" in msg and "rectangular" in msg


@pytest.mark.parametrize("restitution", [0.5, 1.0])
def test_each_collision_reports_the_impact_and_the_kinetic_energy_lost(built, tmp_path, restitution):
    case = _case(tmp_path, [12, 14], 'teeth = [13]\nforce_cN = 100\nmovement = "extrusion"\n'
                 f'[simulation]\nrestitution = {restitution}', days=140)
    _, recs = _run(built, case, "continuous")
    events = [e for r in recs for e in r.collisions if set(e.pair) == {13, 43}]
    assert len(events) == 1  # one collision: afterwards the contact is held, not struck again
    hit = events[0].impact
    assert hit["restitution"] == restitution
    assert hit["impulse_g_mm_per_day"] > 0
    if restitution == 1.0:
        assert hit["kinetic_energy_lost_J"] == pytest.approx(0.0, abs=1e-12 * hit["kinetic_energy_before_J"])
    else:
        assert 0 < hit["kinetic_energy_lost_fraction"] < 1


def test_the_step_is_a_parameter_and_free_movement_does_not_depend_on_it(built, tmp_path):
    load = 'teeth = [15]\nforce_cN = 150\ndirection = "mesial"\nmovement = "translation"'
    ends = []
    for step in (7, 14, 28):
        model, recs = _run(built, _case(tmp_path, [14, 16], load, days=56, step=step))
        assert len(recs) == 56 // step + 1
        ends.append(recs[-1].poses[15])
    assert np.allclose(ends[0], ends[1], atol=1e-9) and np.allclose(ends[0], ends[2], atol=1e-9)


def test_the_exact_mesh_detector_also_runs_and_stops_a_tooth_within_one_steps_travel(built, tmp_path):
    case = _case(tmp_path, [12, 14], 'teeth = [13]\nforce_cN = 100\nmovement = "extrusion"', days=140)
    model, recs = _run(built, case, "exact")
    first = next(r for r in recs if any(set(e.pair) == {13, 43} for e in r.collisions))
    travel = RateLaw().rate(100, model.mechanics[13].root_area_mm2) * 7
    assert first.max_penetration_mm <= travel + 1e-6  # discrete: it may sink in by up to a step's travel

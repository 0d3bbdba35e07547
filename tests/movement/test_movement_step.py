"""The step's phases, each alone, on a small model: coarse parametric teeth, median-split trees.

forces -> motions -> detection -> contacts_at -> response, tied together by `step(model, state)`;
`simulate` is a loop over `step` (the shipped cases' records are guarded in test_step_guard)."""

from dataclasses import replace

import numpy as np
import pytest

from collision_helpers import median_split_tree
from movement_helpers import coarse_case
from orthosim.collision import CollisionModel
from orthosim.movement import MovementModel, simulate
from orthosim.mechanics.biomechanics import Motion
from orthosim.movement.detection import Detection, Hit, detection
from orthosim.movement.forces import forces
from orthosim.movement.motions import motions
from orthosim.movement.response import contacts_at, response
from orthosim.movement.simulation import initial_state, step
from orthosim.movement.state import StepState
from orthosim.model.parametric import parametric_dentition


@pytest.fixture(scope="module")
def built():
    dent = parametric_dentition("coarse")
    return dent, CollisionModel.from_dentition(dent, tree_builder=median_split_tree)


def _model(built, tmp_path, load, extractions=(14, 24, 34, 44), detector="continuous"):
    dent, cm = built
    return MovementModel.build(coarse_case(tmp_path, extractions, load, detector=detector), dent, cm)


MESIAL_15 = 'teeth = [15]\nforce_cN = 150\ndirection = "mesial"\nmovement = "translation"'


def _centers(model, state):
    return model.dentition.crown_centers(state.poses)


def test_the_model_is_frozen(built, tmp_path):
    model = _model(built, tmp_path, MESIAL_15)
    with pytest.raises(AttributeError):
        model.settings = None


def test_initial_state_is_the_rest_state_with_its_contacts(built, tmp_path):
    model = _model(built, tmp_path, MESIAL_15)
    state, record = initial_state(model, "continuous")
    assert state.step == 0 and state.day == 0.0 and record.step == 0
    for n, T in model.dentition.rest_poses().items():
        assert np.array_equal(state.poses[n], T)
    assert (15, 16) in state.touching or (16, 15) in state.touching  # neighbours built just touching
    assert record.touching == state.touching


def test_forces_phase_gives_each_load_with_units_and_blocks_a_push_into_a_touching_tooth(built, tmp_path):
    model = _model(built, tmp_path, 'teeth = [16]\nforce_cN = 150\ndirection = "mesial"\nmovement = "translation"',
                   extractions=(14, 24, 34, 44))
    state, _ = initial_state(model, "continuous")
    f = forces(model, state, _centers(model, state))
    (load,) = f.loads[16]
    assert np.linalg.norm(load.force_cN) == pytest.approx(150.0)
    assert load.bodily and load.point_mm.shape == (3,) and not np.any(load.couple_cNmm)
    assert 15 in f.balance.blocked_by.get(16, [])  # 16 pushes mesially into the touching 15
    assert np.linalg.norm(f.balance.received[15]) > 0  # and passes part of its push on
    assert not np.any(f.balance.free.get(16, np.zeros(3)))


def test_motions_phase_moves_only_teeth_with_a_free_force(built, tmp_path):
    model = _model(built, tmp_path, MESIAL_15)
    state, _ = initial_state(model, "continuous")
    centers = _centers(model, state)
    moves = motions(model, state, forces(model, state, centers), centers)
    assert set(moves) == {15}  # 15 faces the extraction space: nothing blocks it
    d = moves[15].displacement(centers[15], 7.0)[0]
    toward_13 = centers[13] - centers[15]
    assert d @ toward_13 > 0 and np.linalg.norm(d) < 2.0


def test_detection_phase_stops_a_tooth_driven_into_its_neighbour_just_touching(built, tmp_path):
    model = _model(built, tmp_path, MESIAL_15)
    state, _ = initial_state(model, "continuous")
    centers = _centers(model, state)
    gap = centers[13] - centers[15]
    push = Motion(centers[15], 1.5 * gap / 7.0, np.zeros(3))  # 1.5 times the way to 13's crown centre
    detected = detection(model, state, {15: push}, centers)
    (hit,) = detected.hits
    assert set(hit.pair) == {13, 15} and 0.0 < hit.time < 1.0
    assert state.queries.distance(hit.pair, detected.poses) <= 0.05 + 1e-9  # stopped within the touch tolerance
    assert not state.queries.intersects(hit.pair, detected.poses)
    assert hit.pair in detected.tested


def test_contacts_phase_sees_the_new_contact_and_the_response_phase_reports_it_once(built, tmp_path):
    model = _model(built, tmp_path, MESIAL_15)
    state, _ = initial_state(model, "continuous")
    centers = _centers(model, state)
    push = Motion(centers[15], 1.5 * (centers[13] - centers[15]) / 7.0, np.zeros(3))
    moves = {15: push}
    detected = detection(model, state, moves, centers)
    found = contacts_at(model, state, detected.poses)
    pair = detected.hits[0].pair
    assert pair in found.touching and pair not in state.touching
    twice = Detection(detected.poses, detected.hits * 2, detected.tested)  # one pair hit twice in a step
    events = response(model, state, moves, twice, found, centers)
    assert [e.pair for e in events] == [pair]  # one event per pair and step
    assert events[0].impact and events[0].time == detected.hits[0].time


def test_step_makes_the_next_state_and_simulate_is_a_loop_over_it(built, tmp_path):
    model = _model(built, tmp_path, MESIAL_15)
    state, first = initial_state(model, "continuous")
    states, records = [state], [first]
    for _ in range(3):
        state, rec = step(model, state)
        states.append(state)
        records.append(rec)
    assert [s.step for s in states] == [0, 1, 2, 3] and states[-1].day == 21.0
    assert records[-1].touching == states[-1].touching
    run = list(simulate(model, "continuous", steps=3))
    for a, b in zip(run, records):
        assert a.step == b.step and a.touching == b.touching and a.moving == b.moving
        for n in a.poses:
            assert np.array_equal(a.poses[n], b.poses[n])


def test_a_state_is_frozen(built, tmp_path):
    model = _model(built, tmp_path, MESIAL_15)
    state, _ = initial_state(model, "continuous")
    with pytest.raises(AttributeError):
        state.step = 5
    assert isinstance(replace(state, step=5), StepState)
    assert Hit((13, 15), 0.5, state.poses).time == 0.5

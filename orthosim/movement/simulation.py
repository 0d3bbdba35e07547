"""The tooth movement simulator: loads move teeth step by step until collisions stop them.

    model = MovementModel.build(case)                 # once: dentition, collision model, mechanics
    for record in simulate(model, detector="continuous"):
        ...                                           # one StepRecord per step (step 0 = initial)

As MuJoCo keeps them, the model (`MovementModel`, frozen, built once) and the state (`StepState`,
frozen: poses, touching pairs, the rest state's interpenetration, the run's exact queries and their
memos) are apart; `step(model, state) -> (state, record)` makes one step (the paper's frame) of
`step_days` in five phases, each a function of its own module:
1. `forces` (`movement/forces.py`): the case's loads (`AppliedLoad`; directions along the arch: toward the next present
   tooth, the paper's director vector) plus forces passed on by touching teeth (`propagation`): a
   tooth pushing into a touching tooth is blocked in that direction and passes a share of its
   push on, down the arch.
2. `motions` (`movement/motions.py`): each tooth's motion under its free force (`biomechanics`, wire models and rate law);
   a blocked tooth whose neighbour gives way follows it (teeth in contact move together). Between
   the step's ends a tooth moves as `geometry.motion.interpolate_pose` says, the motion the
   continuous detector sweeps.
3. `detection` (`movement/detection.py`): pairs of teeth that may meet (arch neighbours skipping extracted teeth; facing
   teeth of the other arch) are tested with the run's detector. A pair already in contact at the
   step's start (touching, or interpenetrating as a scan left it: the rest state) is tested only
   when the move takes the two into each other: for arch neighbours, when the exact meshes come
   closer or sink deeper; for facing teeth (the occlusal rule: cusps in contact may slide along
   each other), only when the exact meshes end the step interpenetrating deeper than at rest by
   more than `occlusal_slide_mm` for a pair in contact at step 0 (the bite as the model stands),
   `touch_tolerance_mm` for one the run made. Continuous: every mover is cut back to its earliest time of
   first contact (refined on the exact meshes to `contact_tolerance_mm`), so the teeth stop just
   touching; cutting one tooth may put it in another's way, so detection repeats on the cut
   motions (a few rounds). Discrete detectors (bounding circles, discrete sphere trees, exact
   meshes) test the end poses: a tooth found overlapping stops there, so it may have sunk into
   its neighbour by up to one step's travel, which is the paper's point about them.
   With the bite's closure on (`closure`; `[occlusion] closure = "hinge"`, the default for mesh
   models), facing teeth are not tested here at all: after detection the mandible, carrying the
   lower teeth, opens about its condylar axis as far as the moved cusps require and closes again
   to first contact (`closure.settle_bite`), so a tooth moving in contact with an antagonist
   glides and is stopped only by its own arch's neighbours or by a contact the closure cannot
   resolve (the tooth then keeps its start pose). The slide allowance above is then unused.
4. `contacts_at` (`movement/response.py`): the contacts at the new poses (`collision.contacts`) give the touching set of
   the next step and the exact interpenetration.
5. `response` (`movement/response.py`): each collision's rigid-body impact response (`impact`), one event per pair.
The record (`StepRecord`) adds the paper's tooth-to-tooth distances. Every exact question goes
to the run's `collision.ExactQueries`; a step never rebuilds geometry.
Units: mm, degrees in reports, cN, cN*mm, days.
"""

from __future__ import annotations

import dataclasses
from typing import Iterator, Mapping

import numpy as np

from orthosim.analysis.metrics import tooth_to_tooth_distances
from orthosim.collision import Contacts, ExactQueries, contacts
from orthosim.collision.detectors import DETECTORS, Detector, detector_named
from orthosim.errors import CaseError
from orthosim.exchange.case import Case
from orthosim.model.dentition import Dentition
from orthosim.movement.detection import detection
from orthosim.movement.forces import forces
from orthosim.movement.model import MovementModel
from orthosim.movement.motions import motions
from orthosim.movement.propagation import ForceBalance
from orthosim.movement.records import BiteRecord, CollisionEvent, StepRecord
from orthosim.movement.response import contacts_at, response, touch_request
from orthosim.movement.state import StepState


def initial_state(model: MovementModel, detector: str | Detector, queries: ExactQueries | None = None) -> tuple[StepState, StepRecord]:
    """The state before any movement (rest poses) and its record (step 0); detector: a Detector or its name."""
    detector = detector_named(detector)
    queries = queries or ExactQueries(model.collision)
    P = {n: np.asarray(T, float).copy() for n, T in model.dentition.rest_poses().items()}
    found = contacts(model.collision, P, touch_request(model), queries, model.pairs, detector)
    bite = frozenset(p for p in found.touching if p in model.facing)
    state = StepState(0, 0.0, P, found.touching, found.penetration, detector, queries, bite,
                      model.dentition.crown_centers(P))
    return state, _record(model, state, frozenset(), found, (), None)


def step(model: MovementModel, state: StepState) -> tuple[StepState, StepRecord]:
    """One step of `case.step_days`: forces, motions, detection, contacts, response."""
    centers = state.centers if state.centers is not None else model.dentition.crown_centers(state.poses)
    f = forces(model, state, centers)
    moves = motions(model, state, f, centers)
    detected = detection(model, state, moves, centers)
    P, angle, closed = detected.poses, state.mandible_deg, None
    if model.closure is not None:
        from orthosim.movement.closure import settle_bite

        closed, P = settle_bite(model.closure, model.collision, state.queries, state.poses, P, angle)
    moved = frozenset(n for n in moves if not _close(P[n], state.poses[n]))  # in the mandible, before it turns
    if closed is not None:
        P, angle = closed.poses, closed.angle_deg
    found = contacts_at(model, state, P)
    events = response(model, state, moves, detected, found, centers)
    k = state.step + 1
    new = StepState(k, k * float(model.case.step_days), P, found.touching, state.rest_depths, state.detector, state.queries,
                    state.bite, model.dentition.crown_centers(P), angle)
    record = _record(model, new, moved, found, events, f.balance)
    if closed is None:
        return new, record
    return new, dataclasses.replace(record, bite=_bite_record(model, closed, found))


def _bite_record(model: MovementModel, closed, found: Contacts) -> BiteRecord:
    incisors, molars = model.closure.opening_mm(closed.angle_deg)
    contacts = tuple(p for p in found.touching if p in model.facing)
    return BiteRecord(float(closed.angle_deg), incisors, molars, contacts, closed.unresolved)


def _record(model: MovementModel, state: StepState, moved: frozenset[int], found: Contacts,
            events: tuple[CollisionEvent, ...], balance: ForceBalance | None) -> StepRecord:
    depths = found.penetration
    return StepRecord(
        step=state.step,
        time_days=state.day,
        poses={n: T.copy() for n, T in state.poses.items()},
        moving=moved,
        touching=tuple(found.touching),
        contact_centers=found.centers,
        contact_radii=found.radii,
        collisions=events,
        forces=balance,
        max_penetration_mm=max(0.0, _deepening(depths, state.rest_depths)) if state.step else 0.0,
        distances=tuple(tooth_to_tooth_distances(model.dentition, state.poses, set(model.extracted), state.centers)),
        raw_penetration_mm=max(depths.values(), default=0.0),
        penetrating=_deepest_first(depths),
    )


def _deepening(depths: Mapping, initial: Mapping) -> float:
    """mm: the largest interpenetration the run has added to any pair (a model may start with some)."""
    return max((d - initial.get(p, 0.0) for p, d in depths.items()), default=0.0)


def _deepest_first(depths: Mapping) -> tuple[tuple[tuple[int, int], float], ...]:
    return tuple(sorted(((tuple(map(int, p)), float(d)) for p, d in depths.items()), key=lambda item: -item[1]))


def simulate(model: MovementModel, detector: str | Detector | None = None, steps: int | None = None,
             queries: ExactQueries | None = None) -> Iterator[StepRecord]:
    """Run the case of `model` with `detector` (one of `orthosim.collision.detectors.DETECTORS`; the case's by
    default) for `steps` steps of the case's step_days (the case's count by default): the initial
    record (step 0), then one per `step`. queries: the run's exact queries on `model.collision`
    when the caller has prepared them (a fresh one otherwise)."""
    chosen = detector_named(detector or model.case.detector)
    if chosen is None:
        raise CaseError(model.case.path, "treatment.detector", f"unknown detector {detector!r}",
                        f"use one of: {', '.join(DETECTORS)}")
    n_steps = model.case.steps if steps is None else int(steps)
    state, record = initial_state(model, chosen, queries)
    yield record
    for _ in range(n_steps):
        state, record = step(model, state)
        yield record


def simulate_case(case: Case, detector: str | None = None, steps: int | None = None,
                  dentition: Dentition | None = None) -> Iterator[StepRecord]:
    """`simulate(MovementModel.build(case, dentition), detector, steps)`: a whole run from the case
    (and its dentition, when the caller has built it already: building one takes seconds).

    Everything it needs pickles, so it can run in a child process beside the renderer
    (`orthosim.runtime.background.in_child_process(simulate_case, case, detector)`); the child builds the
    same model from the same case and yields the same records.
    """
    return simulate(MovementModel.build(case, dentition=dentition), detector, steps)


def _close(a: np.ndarray, b: np.ndarray) -> bool:
    """`np.allclose(a, b, atol=1e-12)` (rtol 1e-5) for finite arrays, without its per-call overhead."""
    return bool(np.all(np.abs(a - b) <= 1e-12 + 1e-5 * np.abs(b)))

"""Phases 4 and 5 of a step: the contacts at the step's end poses (touching pairs, drawn leaves,
interpenetration) and each collision's rigid-body impact response (`orthosim.movement.impact`),
one event per pair and step.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from orthosim.collision import CollisionRequest, Contacts, contacts
from orthosim.mechanics.biomechanics import Motion
from orthosim.movement.detection import Detection
from orthosim.movement.directions import contact_normal
from orthosim.movement.impact import Body, impact
from orthosim.movement.model import MovementModel
from orthosim.movement.records import CollisionEvent
from orthosim.movement.state import StepState


def touch_request(model: MovementModel) -> CollisionRequest:
    return CollisionRequest(all_leaf_pairs=True, touch_tolerance_mm=model.settings.touch_tolerance_mm)


def contacts_at(model: MovementModel, state: StepState, poses: Mapping[int, np.ndarray]) -> Contacts:
    """Phase 4: the contacts at the step's end poses with the run's detector (touching pairs, drawn
    leaves, interpenetration)."""
    return contacts(model.collision, poses, touch_request(model), state.queries, model.pairs, state.detector)


def response(model: MovementModel, state: StepState, moves: dict[int, Motion], detected: Detection, found: Contacts,
             centers: Mapping[int, np.ndarray]) -> tuple[CollisionEvent, ...]:
    """Phase 5: the step's collision events with their impact responses: each hit of the
    detection, then each pair a moving tooth newly touches without a reported hit (it stopped
    within the touching tolerance); teeth sliding over the other arch's (untested pairs) have not
    collided. One event per pair and step."""
    s = model.settings
    dt = float(model.case.step_days)
    events: list[CollisionEvent] = []
    seen: set = set()
    for h in detected.hits:
        if h.pair not in seen:
            seen.add(h.pair)
            events.append(CollisionEvent(h.pair, h.time, _impact(model, h.pair, moves, h.poses, dt, centers, s.restitution)))
    before = set(state.touching)
    for pair in found.touching:
        if pair not in before and pair not in seen and pair in detected.tested:
            events.append(CollisionEvent(pair, 1.0, _impact(model, pair, moves, detected.poses, dt, centers, s.restitution)))
    return tuple(events)


def _impact(model: MovementModel, pair, moves, P_contact, dt, centers, restitution) -> dict:
    bodies = []
    for n in pair:
        mech = model.mechanics[n]
        T = P_contact[n]
        com = T[:3, :3] @ mech.center_of_mass + T[:3, 3]
        inertia = T[:3, :3] @ mech.inertia_g_mm2 @ T[:3, :3].T
        m = moves.get(n)
        v = m.displacement(com, dt)[0] / dt if m is not None else np.zeros(3)
        w = m.omega if m is not None else np.zeros(3)
        bodies.append(Body(mech.mass_g, com, inertia, v, w))
    c = model.dentition.crown_centers(P_contact)
    hit = impact(bodies[0], bodies[1], 0.5 * (c[pair[0]] + c[pair[1]]), contact_normal(model, pair, c), restitution)
    return hit.summary()

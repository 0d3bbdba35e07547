"""Phase 3 of a step: the step's motions tested with the run's detector, and the poses the step ends in.

Every detector goes through one cut-back loop (`cut_back`): the pairs the motions may bring into
contact are asked, and each tooth at fault in a new contact stops at the time the detector found
it (a sweeping detector's time of first contact, in rounds; the step's end for a detector that
tests end poses). A pair in contact at the step's start is tested only when the move takes the two
into each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from orthosim.collision import CollisionRequest, detect_step, interpolate_pose
from orthosim.mechanics.biomechanics import Motion
from orthosim.movement.directions import contact_normal
from orthosim.movement.model import MovementModel
from orthosim.movement.state import StepState


@dataclass(frozen=True, eq=False)
class Hit:
    """A collision the detection phase found: pair, time (fraction of the step), poses at contact."""

    pair: tuple[int, int]
    time: float
    poses: Mapping[int, np.ndarray]


@dataclass(frozen=True, eq=False)
class Detection:
    """The detection phase: the poses the step ends in, the collisions met, the pairs tested."""

    poses: dict[int, np.ndarray]
    hits: tuple[Hit, ...]
    tested: frozenset[tuple[int, int]]


def detection(model: MovementModel, state: StepState, moves: dict[int, Motion], centers: Mapping[int, np.ndarray]) -> Detection:
    """Phase 3: the step's motions tested with the run's detector; the poses the step ends in.

    Continuous: every mover is cut back to its earliest time of first contact, in rounds (cutting
    one tooth may put it in another's way). Discrete detectors test the end poses; a tooth found
    overlapping stops there. A pair in contact at the step's start is tested only when the move
    takes the two into each other (`_approaching`, `_sinking`).
    """
    dt = float(model.case.step_days)
    P = state.poses
    P1 = dict(P)
    for n, m in moves.items():
        P1[n] = m.apply(P[n], dt)
    touching_set = set(state.touching)

    def approaching(pair, current, end_poses) -> bool:
        if not state.detector.exact_touch:
            return _approaching(model, pair, current, dt, centers)
        end = {n: (end_poses[n] if n in current else P[n]) for n in pair}
        return _sinking(model, state, pair, end)

    def tested(current: dict[int, Motion], skip: set, end_poses: Mapping[int, np.ndarray]) -> list[tuple[int, int]]:
        out = []
        for pair in model.pairs:
            a, b = pair
            if pair in skip or (a not in current and b not in current) or (model.closure is not None and pair in model.facing):
                continue
            if pair in touching_set and not approaching(pair, current, end_poses):
                continue
            out.append(pair)
        return out

    found = cut_back(model, state, moves, P1, tested, centers)
    if not state.detector.sweeps:
        return found
    return Detection(_hold_slides_within_allowance(model, state, found.poses), found.hits, found.tested)


def cut_back(model: MovementModel, state: StepState, moves: dict[int, Motion], intended: Mapping[int, np.ndarray],
             tested: Callable, centers: Mapping[int, np.ndarray]) -> Detection:
    """The one cut-back loop of every detector: the pairs the motions may bring into contact are
    asked, and each tooth at fault in a new contact stops at the time the detector found it: a
    sweeping detector's time of first contact (the tooth cut back to it, in rounds: cutting one
    tooth may put it in another's way), or the step's end for a detector that tests end poses (one
    round: the tooth stops where it was found overlapping, cutting nothing).

    intended: FDI -> (4, 4) pose each tooth would end the step in uncut. tested(motions, asked,
    end poses): the pairs to ask this round, given the motions still made, the pairs asked already
    and the end poses as cut so far. Returns the cut end poses, the new contacts (`Hit`) and every
    pair asked."""
    s, P, queries, detector = model.settings, state.poses, state.queries, state.detector
    dt = float(model.case.step_days)
    touching_set = set(state.touching)
    P1 = dict(intended)
    hits: list[Hit] = []
    tested_pairs: set = set()
    tcut = {n: 1.0 for n in moves}
    done: set = set()
    request = CollisionRequest(all_leaf_pairs=False, refine_time_of_contact=detector.sweeps,
                               contact_tolerance_mm=s.contact_tolerance_mm, drawn_leaves=False)
    for _ in range(s.rounds if detector.sweeps else 1):
        current = {n: m for n, m in moves.items() if tcut[n] > 0}
        pairs = tested(_scaled(current, tcut), done, P1)
        tested_pairs.update(pairs)
        if not pairs:
            break
        found = detect_step(model.collision, P, P1, pairs, detector, request, queries=queries).first_contacts()
        if not found:
            break
        for pair, t in found:
            done.add(pair)
            if pair in touching_set:
                continue  # a contact held from the last step stops the tooth; it is no new collision
            P_at = dict(P1)
            for n in pair:
                if n in tcut and t < 1.0:
                    P_at[n] = interpolate_pose(P[n], P1[n], t)
            hits.append(Hit(pair, t * _frac(tcut, pair), P_at))
        cut: dict[int, float] = {}
        scaled = _scaled(moves, tcut)
        for pair, t in found:
            for n in (_at_fault(model, pair, scaled, dt, centers) if t < 1.0 else ()):
                if n in tcut:
                    cut[n] = min(cut.get(n, 1.0), t)
        for n, t in cut.items():
            P1[n] = interpolate_pose(P[n], P1[n], t)
            tcut[n] *= t
    return Detection(P1, tuple(hits), frozenset(tested_pairs))


def _hold_slides_within_allowance(model: MovementModel, state: StepState, end: Mapping[int, np.ndarray]) -> dict:
    """The sliding allowance was checked at the intended end of each move; a move cut short by
    another contact may stop mid-way over a cusp, deeper than its end would be: such a tooth keeps
    its start pose, so the bound holds on the poses a step leaves. With a closure, the arches'
    contacts are the closure's. Returns the end poses (FDI -> (4, 4)) with those teeth held."""
    P, queries = state.poses, state.queries
    P1 = dict(end)
    for pair in set(state.touching) if model.closure is None else ():
        if pair in model.facing and any(P1[n] is not P[n] for n in pair) and \
                queries.penetration(pair, P1) - state.rest_depths.get(pair, 0.0) > state.slide_allowance(model, pair):
            for n in pair:
                P1[n] = P[n]
    return P1


def _sinking(model: MovementModel, state: StepState, pair, end: Mapping[int, np.ndarray]) -> bool:
    """Continuous detector: whether a pair touching at the step's start moves into each other.
    Touching teeth that slide along each other can still sink in, so the exact meshes decide:
    closer, or sinking deeper, at the end of the motion; teeth of the two arches may slide: only
    sinking deeper than the pair's slide allowance below the rest state counts (so steps cannot add up)."""
    s, q, P = model.settings, state.queries, state.poses
    d0, d1 = q.distance(pair, P), q.distance(pair, end)
    facing = pair in model.facing
    if d1 > 0.0:
        return not facing and d1 < d0 - 1e-6
    if facing:
        return q.penetration(pair, end) - state.rest_depths.get(pair, 0.0) > state.slide_allowance(model, pair)
    start = q.penetration(pair, P) if d0 <= 0.0 else 0.0
    deeper = q.penetration(pair, end) - start
    return deeper > (1e-6 if d0 > 0.0 else s.contact_tolerance_mm)


def _approaching(model, pair, moves, dt, centers) -> bool:
    """Discrete detectors: whether the pair's crown centres come closer along the contact normal."""
    a, b = pair
    p = 0.5 * (centers[a] + centers[b])
    n = contact_normal(model, pair, centers)
    da = moves[a].displacement(p, dt)[0] if a in moves else np.zeros(3)
    db = moves[b].displacement(p, dt)[0] if b in moves else np.zeros(3)
    return float((da - db) @ n) > 1e-9


def _at_fault(model, pair, moves, dt, centers) -> tuple[int, ...]:
    """The teeth of a colliding pair whose own motion runs into the other (both when neither
    clearly does, e.g. a contact made by turning): those are the ones a contact stops."""
    a, b = pair
    p = 0.5 * (centers[a] + centers[b])
    n = contact_normal(model, pair, centers)
    ga = float(moves[a].displacement(p, dt)[0] @ n) if a in moves else 0.0
    gb = -float(moves[b].displacement(p, dt)[0] @ n) if b in moves else 0.0
    out = tuple(t for t, g in ((a, ga), (b, gb)) if g > 1e-9)
    return out or pair


def _scaled(moves: dict[int, Motion], tcut: dict[int, float]) -> dict[int, Motion]:
    """Motions shortened to the fraction of the step each tooth still makes (for the approach test)."""
    return {n: Motion(m.pivot, m.velocity * tcut[n], m.omega * tcut[n]) for n, m in moves.items()}


def _frac(tcut: dict[int, float], pair) -> float:
    return min((tcut.get(n, 1.0) for n in pair), default=1.0)

"""The tooth movement simulator: loads move teeth step by step until collisions stop them.

    model = MovementModel.build(case)                 # once: dentition, collision model, mechanics
    for record in simulate(model, detector="continuous"):
        ...                                           # one StepRecord per step (step 0 = initial)

As MuJoCo keeps them, the model (`MovementModel`, frozen, built once) and the state (`StepState`,
frozen: poses, touching pairs, the rest state's interpenetration, the run's exact queries and their
memos) are apart; `step(model, state) -> (state, record)` makes one step (the paper's frame) of
`step_days` in five phases, each a function of its own:
1. `forces`: the case's loads (`AppliedLoad`; directions along the arch: toward the next present
   tooth, the paper's director vector) plus forces passed on by touching teeth (`propagation`): a
   tooth pushing into a touching tooth is blocked in that direction and passes a share of its
   push on, down the arch.
2. `motions`: each tooth's motion under its free force (`biomechanics`, wire models and rate law);
   a blocked tooth whose neighbour gives way follows it (teeth in contact move together). Between
   the step's ends a tooth moves as `geometry.motion.interpolate_pose` says, the motion the
   continuous detector sweeps.
3. `detection`: pairs of teeth that may meet (arch neighbours skipping extracted teeth; facing
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
4. `contacts_at`: the contacts at the new poses (`collision.contacts`) give the touching set of
   the next step and the exact interpenetration.
5. `response`: each collision's rigid-body impact response (`impact`), one event per pair.
The record (`StepRecord`) adds the paper's tooth-to-tooth distances. Every exact question goes
to the run's `collision.ExactQueries`; a step never rebuilds geometry.
Units: mm, degrees in reports, cN, cN*mm, days.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, replace
from typing import Callable, Iterator, Mapping

import numpy as np

from orthosim.model import fdi as F
from orthosim.exchange.case import Case, Load
from orthosim.collision import (CollisionModel, CollisionRequest, Contacts, ExactQueries, candidate_pairs, contacts, detect_step,
                         interpolate_pose)
from orthosim.model.dentition import Dentition
from orthosim.collision.detectors import DETECTORS, Detector, detector_named
from orthosim.errors import CaseError
from orthosim.collision.interpenetration import default_occlusal_slide_mm
from orthosim.analysis.metrics import tooth_to_tooth_distances
from orthosim.mechanics.biomechanics import (DAYS_PER_MONTH, PARAMETER_SETS, Motion, RateLaw, ToothMechanics, build_mechanics,
                                           tooth_motion)
from orthosim.movement.impact import Body, impact
from orthosim.movement.propagation import ForceBalance, propagate
from orthosim.movement.records import BiteRecord, CollisionEvent, StepRecord
from orthosim.mechanics.vec import length

@dataclass(frozen=True)
class MovementSettings:
    """Parameters of the movement model (case file table [simulation]).

    force_share: fraction (0..1) of a push passed on to the tooth it hits.
    restitution: Newton's coefficient (0..1) of the reported impacts.
    resistance_rule / resistance_fraction: centre of resistance, see `resistance`.
    contact_tolerance_mm: continuous detector: teeth stop within this travel (mm) of touching.
    touch_tolerance_mm: exact and continuous detectors: meshes this close (mm) count as touching.
    rounds: continuous detector: detection rounds on cut motions per step.
    occlusal_slide_mm: continuous detector: teeth of the two arches in contact at a step's start may
        slide along each other; the move stops only if it leaves them interpenetrating deeper than
        at rest (step 0) by more than this (mm); by default the model's (see `from_case`). Arch
        neighbours get `contact_tolerance_mm`.
    """

    force_share: float = 0.5
    restitution: float = 0.5
    resistance_rule: str = "literature"
    resistance_fraction: float = 0.4
    rate: RateLaw = RateLaw()
    contact_tolerance_mm: float = 0.02
    touch_tolerance_mm: float = 0.05
    rounds: int = 4
    occlusal_slide_mm: float = 0.05

    @classmethod
    def from_case(cls, case: Case, dentition: Dentition | None = None) -> "MovementSettings":
        """The case's [simulation] settings; an occlusal_slide_mm the case leaves out is the model's
        (`interpenetration.default_occlusal_slide_mm` of `dentition`, the touch tolerance without one)."""
        sim = getattr(case, "simulation", None)
        slide = getattr(sim, "occlusal_slide_mm", None)
        if slide is None:
            slide = default_occlusal_slide_mm(dentition) if dentition is not None else cls.occlusal_slide_mm
        rate = rate_law(getattr(case, "biomechanics", None))
        if sim is None:
            return cls(occlusal_slide_mm=slide, rate=rate)
        return cls(force_share=sim.force_share, restitution=sim.restitution,
                   resistance_rule=sim.resistance_rule, resistance_fraction=sim.resistance_fraction,
                   rate=rate, occlusal_slide_mm=slide)


def rate_law(biomechanics) -> RateLaw:
    """The rate law a case's [biomechanics] table names: its parameter set with the table's own
    numbers over it (`orthosim.exchange.case.Biomechanics`; None: the paper's set)."""
    if biomechanics is None:
        return PARAMETER_SETS["paper"]
    base = PARAMETER_SETS[biomechanics.parameters]
    changes = {k: v for k, v in biomechanics.overrides().items() if v is not None}
    if "max_rate_mm_per_month" in changes:
        changes["max_rate_mm_per_day"] = changes.pop("max_rate_mm_per_month") / DAYS_PER_MONTH
    return replace(base, **changes) if changes else base


@dataclass(frozen=True, eq=False)
class MovementModel:
    """What never changes during a run: the case, the dentition, its collision model (sphere trees),
    each tooth's mechanics, the settings, and what follows from them (present teeth, candidate pairs)."""

    case: Case
    dentition: Dentition
    collision: CollisionModel
    mechanics: dict[int, ToothMechanics]
    settings: MovementSettings
    extracted: frozenset[int] = field(default_factory=frozenset)
    present: tuple[int, ...] = ()
    pairs: tuple[tuple[int, int], ...] = ()  # broad phase: arch neighbours, then facing pairs
    facing: frozenset[tuple[int, int]] = field(default_factory=frozenset)
    total_mass_g: float = 0.0
    arch_orders: dict[F.Arch, list[int]] = field(default_factory=dict)  # present teeth, right to left
    closure: "ClosureModel | None" = None  # the bite's closure after each step (`closure`); None: the slide allowance
    # FDI -> its place along its arch among the dentition's teeth (extracted ones included), right to left
    arch_place: dict[int, int] = field(init=False, repr=False)

    def __post_init__(self):
        place = {}
        for arch in F.Arch:
            place.update((t, k) for k, t in enumerate(F.arch_order(arch, set(self.dentition.teeth))))
        object.__setattr__(self, "arch_place", place)

    @classmethod
    def build(cls, case: Case, dentition: Dentition | None = None, collision: CollisionModel | None = None,
              settings: MovementSettings | None = None, tree_builder: Callable | None = None) -> "MovementModel":
        dentition = dentition or case.build_dentition()
        settings = settings or MovementSettings.from_case(case, dentition)
        if collision is None:  # the project's cached sphere trees unless a builder is given
            collision = CollisionModel.from_dentition(dentition, tree_builder=tree_builder)
        extracted = frozenset(case.extractions)
        present = tuple(n for n in dentition.fdis if n not in extracted)
        pairs = candidate_pairs(dentition.fdis, extracted)
        neighbours = set(dentition.adjacent_pairs(set(extracted)))
        facing = frozenset(p for p in pairs if tuple(p) not in neighbours)
        mech = {n: build_mechanics(dentition.teeth[n], settings.resistance_rule, settings.resistance_fraction, settings.rate)
                for n in present}
        orders = {arch: [t for t in F.arch_order(arch, set(dentition.teeth)) if t not in extracted] for arch in F.Arch}
        return cls(case, dentition, collision, mech, settings, extracted, present, tuple(map(tuple, pairs)), facing,
                   arch_orders=orders, closure=_closure_model(case, dentition, settings, facing, extracted, orders))


def _closure_model(case: Case, dentition: Dentition, settings: MovementSettings, facing, extracted, orders):
    """The bite's closure model when the case closes the bite and both arches have teeth, else None."""
    from orthosim.movement.closure import ClosureModel, closure_settings

    chosen = closure_settings(case, settings.contact_tolerance_mm)
    if chosen.mode == "none" or not facing or min(len(orders[F.Arch.UPPER]), len(orders[F.Arch.LOWER])) < 3:
        return None
    return ClosureModel.build(chosen, dentition, sorted(facing), extracted)


# ---------------------------------------------------------------------------------------------
# loads: directions and points at the current poses


def _arch_step(fdi: int, direction: str) -> int:
    """+1 / -1: which way along `arch_order` (right to left) is `direction` for this tooth."""
    mesial = 1 if F.quadrant(fdi) in (1, 4) else -1
    return mesial if direction == "mesial" else -mesial


def _horizontal(v: np.ndarray) -> np.ndarray:
    h = np.array([v[0], 0.0, v[2]])
    n = length(h)
    return h / n if n > 0 else h


def _present_in_arch(model: MovementModel, fdi: int) -> list[int]:
    """Present teeth of fdi's arch, right distal end to left distal end."""
    arch = F.arch_of(fdi)
    order = model.arch_orders.get(arch)
    if order is None:
        order = [t for t in F.arch_order(arch, set(model.dentition.teeth)) if t not in model.extracted]
    return order


def arch_direction(model: MovementModel, poses: Mapping[int, np.ndarray], fdi: int, direction: str,
                   centers: Mapping[int, np.ndarray] | None = None) -> np.ndarray:
    """(3,) unit arch-frame vector 'mesial' or 'distal' for a tooth at `poses`: toward the crown centre
    of the next present tooth that way along the arch (the paper's director vector), or along the
    tooth's own mesiodistal axis at the end of the arch. centers: the crown centres at `poses`
    (`Dentition.crown_centers`) when the caller has them."""
    order = _present_in_arch(model, fdi)
    i = order.index(fdi)
    j = i + _arch_step(fdi, direction)
    tooth = model.dentition.teeth[fdi]
    R = poses[fdi][:3, :3]
    if 0 <= j < len(order):
        if centers is None:
            centers = model.dentition.crown_centers(poses)
        return _horizontal(centers[order[j]] - centers[fdi])
    sign = 1.0 if direction == "mesial" else -1.0
    return _horizontal(sign * (R @ tooth.mesial))


@dataclass(frozen=True, eq=False)
class AppliedLoad:
    """One load of the case on one tooth at given poses, arch frame.

    force_cN (3,), applied at point_mm (3,), plus a couple couple_cNmm (3,). bodily: the load asks
    for translation (a rectangular wire then moves the tooth without tipping)."""

    force_cN: np.ndarray
    point_mm: np.ndarray
    couple_cNmm: np.ndarray
    bodily: bool


def applied_load(model: MovementModel, poses: Mapping[int, np.ndarray], load: Load, fdi: int,
                 centers: Mapping[int, np.ndarray] | None = None) -> AppliedLoad:
    """One load on one tooth at `poses` (centers: the crown centres at `poses`,
    `Dentition.crown_centers`, when the caller has them)."""
    tooth = model.dentition.teeth[fdi]
    mech = model.mechanics[fdi]
    R, p = poses[fdi][:3, :3], poses[fdi][:3, 3]
    d = load.direction
    if load.movement == "extrusion":
        d = "occlusal"
    elif load.movement == "intrusion":
        d = "apical"
    if isinstance(d, str):
        if d in ("mesial", "distal"):
            u = arch_direction(model, poses, fdi, d, centers)
        elif d in ("labial", "lingual"):
            t = arch_direction(model, poses, fdi, "mesial", centers)
            u = _horizontal(np.cross(t, [0.0, 1.0, 0.0]))
            if u @ (R @ tooth.labial) < 0:
                u = -u
            if d == "lingual":
                u = -u
        else:
            u = R @ tooth.long_axis * (1.0 if d == "occlusal" else -1.0)
    else:
        u = np.asarray(d, float) / length(d)
    pt = load.point
    local = {"bracket": mech.bracket, "crown_center": mech.crown_center,
             "center_of_resistance": mech.center_of_resistance}.get(pt) if isinstance(pt, str) else np.asarray(pt, float)
    axis = {"mesiodistal": tooth.mesial, "labiolingual": tooth.labial, "long_axis": tooth.long_axis}[load.moment_axis]
    bodily = load.movement in ("translation", "extrusion", "intrusion") or (load.movement == "auto" and load.moment_cNmm == 0.0)
    return AppliedLoad(load.force_cN * u, R @ local + p, load.moment_cNmm * (R @ axis), bodily)


# ---------------------------------------------------------------------------------------------
# the state of a run between steps, and one step made of named phases


@dataclass(frozen=True, eq=False)
class StepState:
    """What a run carries from one step to the next (the model never changes).

    step / day: the step just made (0: the initial state) and its day.
    poses: FDI -> (4, 4) local -> arch frame, mm. touching: pairs in contact at `poses`.
    rest_depths: pair -> mm the exact meshes interpenetrate in the initial state (a scan may leave
        some; the run's interpenetration is measured against it).
    detector: the run's detector. queries: the run's exact queries and their memos (`ExactQueries`).
    bite: pairs of facing teeth in contact in the initial state (the bite as the model stands): they
        may slide by `occlusal_slide_mm`; contacts the run makes get the touch tolerance.
    centers: FDI -> (3,) crown centres at `poses` (`Dentition.crown_centers`; found when None).
    mandible_deg: with a closure, the hinge angle the lower teeth's poses stand at.
    """

    step: int
    day: float
    poses: Mapping[int, np.ndarray]
    touching: tuple[tuple[int, int], ...]
    rest_depths: Mapping[tuple[int, int], float]
    detector: Detector  # the run's (`orthosim.collision.detectors`): its capabilities steer the step
    queries: ExactQueries
    bite: frozenset[tuple[int, int]] = frozenset()
    centers: Mapping[int, np.ndarray] | None = None
    mandible_deg: float = 0.0  # the mandible's hinge angle from rest (degrees, positive open; `closure`)

    def slide_allowance(self, model: "MovementModel", pair: tuple[int, int]) -> float:
        """mm a facing pair may sink below the rest state while its cusps slide along each other."""
        s = model.settings
        return s.occlusal_slide_mm if pair in self.bite else min(s.occlusal_slide_mm, s.touch_tolerance_mm)


@dataclass(frozen=True, eq=False)
class Forces:
    """The forces phase: the loads on each tooth at the step's start and the force balance."""

    loads: dict[int, list[AppliedLoad]]
    balance: ForceBalance


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


def _touch_request(model: MovementModel) -> CollisionRequest:
    return CollisionRequest(all_leaf_pairs=True, touch_tolerance_mm=model.settings.touch_tolerance_mm)


def initial_state(model: MovementModel, detector: str | Detector, queries: ExactQueries | None = None) -> tuple[StepState, StepRecord]:
    """The state before any movement (rest poses) and its record (step 0); detector: a Detector or its name."""
    detector = detector_named(detector)
    queries = queries or ExactQueries(model.collision)
    P = {n: np.asarray(T, float).copy() for n, T in model.dentition.rest_poses().items()}
    found = contacts(model.collision, P, _touch_request(model), queries, model.pairs, detector)
    bite = frozenset(p for p in found.touching if p in model.facing)
    state = StepState(0, 0.0, P, found.touching, found.penetration, detector, queries, bite,
                      model.dentition.crown_centers(P))
    return state, _record(model, state, frozenset(), found, (), None)


def forces(model: MovementModel, state: StepState, centers: Mapping[int, np.ndarray]) -> Forces:
    """Phase 1: the case's loads at the step's start poses, and the forces touching teeth pass on."""
    s = model.settings
    P = state.poses
    loads: dict[int, list[AppliedLoad]] = {}
    for load in model.case.loads:
        for n in load.teeth:
            if n in model.mechanics:
                loads.setdefault(n, []).append(applied_load(model, P, load, n, centers))
    applied = {n: sum((a.force_cN for a in v), np.zeros(3)) for n, v in loads.items()}
    normals = [(a, b, _normal(model, (a, b), centers)) for a, b in state.touching]
    balance = propagate(applied, normals, s.force_share,
                        lambda n, f: n in model.mechanics and s.rate.moves(f, model.mechanics[n].resisting_area_mm2),
                        _onward(model, P, state.touching, centers))
    return Forces(loads, balance)


def motions(model: MovementModel, state: StepState, f: Forces, centers: Mapping[int, np.ndarray]) -> dict[int, Motion]:
    """Phase 2: each tooth's motion over the step under its free force; blocked teeth follow a
    neighbour that gives way."""
    s = model.settings
    dt = float(model.case.step_days)
    poses, balance = state.poses, f.balance
    wire = model.case.wire.type
    out: dict[int, Motion] = {}
    for n in model.present:
        free = balance.free.get(n)
        own = f.loads.get(n, ())
        couple = sum((a.couple_cNmm for a in own), np.zeros(3))
        if (free is None or not free.any()) and not couple.any():
            continue
        if free is None:
            free = np.zeros(3)
        if own and any(a.force_cN.any() for a in own):
            w = np.array([length(a.force_cN) for a in own])
            point = sum(wi * a.point_mm for wi, a in zip(w, own)) / max(w.sum(), 1e-12)
        else:
            point = centers[n]
        translation_only = wire == "rectangular" and (not own or any(a.bodily for a in own))
        m = tooth_motion(model.mechanics[n], poses[n], free, point, couple, wire, translation_only, s.rate)
        if not m.is_still:
            out[n] = m
    if wire != "rectangular":
        return out
    # a tooth blocked by a neighbour that moves away follows it, as far as its own push would take it
    settled: dict[tuple[int, int], tuple] = {}  # (i, j) -> the motions (of j, of i) it last left unchanged
    for _ in range(len(model.present)):
        changed = False
        for i, blockers in balance.blocked_by.items():
            for j in blockers:
                if j not in out:
                    continue
                seen = settled.get((i, j))
                if seen is not None and seen[0] is out[j] and seen[1] is out.get(i):
                    continue  # the same motions (frozen) as when this pair last changed nothing
                n_ij = _normal(model, (i, j), centers)
                p = 0.5 * (centers[i] + centers[j])
                away = float(out[j].displacement(p, dt)[0] @ n_ij) / dt
                mi = out.get(i, Motion.still(centers[i]))
                cur = float(mi.displacement(p, dt)[0] @ n_ij) / dt
                push = float(balance.total[i] @ n_ij)
                want = float(s.rate.rate(length(balance.total[i]), model.mechanics[i].resisting_area_mm2)) * push / max(
                    length(balance.total[i]), 1e-12)
                target = min(away, want)
                if target > cur + 1e-12:
                    out[i] = Motion(mi.pivot, mi.velocity + (target - cur) * n_ij, mi.omega)
                    changed = True
                else:
                    settled[(i, j)] = (out[j], out.get(i))
        if not changed:
            break
    return out


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
    hits: list[Hit] = []
    tested_pairs: set = set()

    def approaching(pair, current) -> bool:
        if not state.detector.exact_touch:
            return _approaching(model, pair, current, dt, centers)
        end = {n: (P1[n] if n in current else P[n]) for n in pair}
        return _sinking(model, state, pair, end)

    def tested(current: dict[int, Motion], skip: set) -> list[tuple[int, int]]:
        out = []
        for pair in model.pairs:
            a, b = pair
            if pair in skip or (a not in current and b not in current) or (model.closure is not None and pair in model.facing):
                continue
            if pair in touching_set and not approaching(pair, current):
                continue
            out.append(pair)
        return out

    _cut_back(model, state, moves, P1, tested, centers, hits, tested_pairs)
    if state.detector.sweeps:
        _hold_slides_within_allowance(model, state, P1)
    return Detection(P1, tuple(hits), frozenset(tested_pairs))


def _cut_back(model: MovementModel, state: StepState, moves: dict[int, Motion], P1: dict, tested: Callable,
              centers: Mapping[int, np.ndarray], hits: list, tested_pairs: set) -> None:
    """The one cut-back loop of every detector: the pairs the motions may bring into contact are
    asked, and each tooth at fault in a new contact stops at the time the detector found it: a
    sweeping detector's time of first contact (the tooth cut back to it, in rounds: cutting one
    tooth may put it in another's way), or the step's end for a detector that tests end poses (one
    round: the tooth stops where it was found overlapping, cutting nothing). `P1` (FDI -> end pose)
    is cut in place, new contacts appended to `hits`, the pairs asked added to `tested_pairs`."""
    s, P, queries, detector = model.settings, state.poses, state.queries, state.detector
    dt = float(model.case.step_days)
    touching_set = set(state.touching)
    tcut = {n: 1.0 for n in moves}
    done: set = set()
    request = CollisionRequest(all_leaf_pairs=False, refine_time_of_contact=detector.sweeps,
                               contact_tolerance_mm=s.contact_tolerance_mm, drawn_leaves=False)
    for _ in range(s.rounds if detector.sweeps else 1):
        current = {n: m for n, m in moves.items() if tcut[n] > 0}
        pairs = tested(_scaled(current, tcut), done)
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


def _hold_slides_within_allowance(model: MovementModel, state: StepState, P1: dict) -> None:
    """The sliding allowance was checked at the intended end of each move; a move cut short by
    another contact may stop mid-way over a cusp, deeper than its end would be: such a tooth keeps
    its start pose (in `P1`), so the bound holds on the poses a step leaves. With a closure, the
    arches' contacts are the closure's."""
    P, queries = state.poses, state.queries
    for pair in set(state.touching) if model.closure is None else ():
        if pair in model.facing and any(P1[n] is not P[n] for n in pair) and \
                queries.penetration(pair, P1) - state.rest_depths.get(pair, 0.0) > state.slide_allowance(model, pair):
            for n in pair:
                P1[n] = P[n]


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


def contacts_at(model: MovementModel, state: StepState, poses: Mapping[int, np.ndarray]) -> Contacts:
    """Phase 4: the contacts at the step's end poses with the run's detector (touching pairs, drawn
    leaves, interpenetration)."""
    return contacts(model.collision, poses, _touch_request(model), state.queries, model.pairs, state.detector)


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


def _normal(model: MovementModel, pair: tuple[int, int], centers: Mapping[int, np.ndarray]) -> np.ndarray:
    """Unit vector from pair[0] toward pair[1]: horizontal between crown centres for neighbours,
    vertical for facing (occlusal) pairs."""
    a, b = pair
    if pair in model.facing or (b, a) in model.facing:
        return np.array([0.0, np.sign(centers[b][1] - centers[a][1]) or 1.0, 0.0])
    return _horizontal(centers[b] - centers[a])


def _onward(model: MovementModel, poses, touching, centers) -> dict[tuple[int, int], np.ndarray]:
    """(pusher, pushed) -> direction of the force the pushed tooth receives: along the arch, toward
    its own next tooth away from the pusher (the paper's director vector); occlusal pairs: none
    (the contact normal, vertical, is used)."""
    out = {}
    found: dict[tuple[int, str], np.ndarray] = {}  # (tooth, way) -> its arch direction (a tooth in two contacts)
    for a, b in touching:
        if (a, b) in model.facing or (b, a) in model.facing or F.arch_of(a) != F.arch_of(b):
            continue
        ia, ib = model.arch_place[a], model.arch_place[b]
        for i, j, step_ in ((a, b, (ib > ia) - (ib < ia)), (b, a, (ia > ib) - (ia < ib))):
            way = "mesial" if step_ == _arch_step(j, "mesial") else "distal"
            d = found.get((j, way))
            if d is None:
                d = found[(j, way)] = arch_direction(model, poses, j, way, centers)
            out[(i, j)] = d
    return out


def _approaching(model, pair, moves, dt, centers) -> bool:
    """Discrete detectors: whether the pair's crown centres come closer along the contact normal."""
    a, b = pair
    p = 0.5 * (centers[a] + centers[b])
    n = _normal(model, pair, centers)
    da = moves[a].displacement(p, dt)[0] if a in moves else np.zeros(3)
    db = moves[b].displacement(p, dt)[0] if b in moves else np.zeros(3)
    return float((da - db) @ n) > 1e-9


def _at_fault(model, pair, moves, dt, centers) -> tuple[int, ...]:
    """The teeth of a colliding pair whose own motion runs into the other (both when neither
    clearly does, e.g. a contact made by turning): those are the ones a contact stops."""
    a, b = pair
    p = 0.5 * (centers[a] + centers[b])
    n = _normal(model, pair, centers)
    ga = float(moves[a].displacement(p, dt)[0] @ n) if a in moves else 0.0
    gb = -float(moves[b].displacement(p, dt)[0] @ n) if b in moves else 0.0
    out = tuple(t for t, g in ((a, ga), (b, gb)) if g > 1e-9)
    return out or pair


def _deepening(depths: Mapping, initial: Mapping) -> float:
    """mm: the largest interpenetration the run has added to any pair (a model may start with some)."""
    return max((d - initial.get(p, 0.0) for p, d in depths.items()), default=0.0)


def _deepest_first(depths: Mapping) -> tuple[tuple[tuple[int, int], float], ...]:
    return tuple(sorted(((tuple(map(int, p)), float(d)) for p, d in depths.items()), key=lambda item: -item[1]))


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
    hit = impact(bodies[0], bodies[1], 0.5 * (c[pair[0]] + c[pair[1]]), _normal(model, pair, c), restitution)
    return hit.summary()


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


def _scaled(moves: dict[int, Motion], tcut: dict[int, float]) -> dict[int, Motion]:
    """Motions shortened to the fraction of the step each tooth still makes (for the approach test)."""
    return {n: Motion(m.pivot, m.velocity * tcut[n], m.omega * tcut[n]) for n, m in moves.items()}


def _frac(tcut: dict[int, float], pair) -> float:
    return min((tcut.get(n, 1.0) for n in pair), default=1.0)

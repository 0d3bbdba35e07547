"""The tooth movement simulator: loads move teeth step by step until collisions stop them.

    model = MovementModel.build(case)                 # once: dentition, collision model, mechanics
    for record in simulate(model, detector="continuous"):
        ...                                           # one StepRecord per step (step 0 = initial)

Each step (the paper's frame) of `step_days`:
1. Forces: the case's loads (directions along the arch: toward the next present tooth, the paper's
   director vector) plus forces passed on by touching teeth (`propagation`): a tooth pushing into
   a touching tooth is blocked in that direction and passes a share of its push on, down the arch.
   A blocked tooth whose neighbour gives way follows it (teeth in contact move together).
2. Motion: each tooth's motion under its free force (`biomechanics`, wire models and rate law);
   its intended pose at the end of the step. Between the step's ends a tooth moves as
   `collision.motion.interpolate_pose` says, the motion the continuous detector sweeps.
3. Collisions: pairs of teeth that may meet (arch neighbours skipping extracted teeth; facing teeth
   of the other arch, for a tooth moving in any direction) are tested with the chosen detector.
   A pair already in contact at the step's start (touching, or interpenetrating as a scan left it:
   the rest state) is tested only when the move takes the two into each other: for arch
   neighbours, when the exact meshes come closer or sink deeper; for facing teeth (the occlusal
   rule: cusps in contact may slide along each other), only when the exact meshes end the step
   interpenetrating deeper than at rest (step 0) by more than `occlusal_slide_mm`.
   Continuous: every mover is cut back to its
   earliest time of first contact (refined on the exact meshes to `contact_tolerance_mm`), so the
   teeth stop just touching; cutting one tooth may put it in another's way, so detection repeats
   on the cut motions (a few rounds). Discrete detectors (bounding circles, discrete sphere trees,
   exact meshes) test the end poses: a tooth found overlapping stops there, so it may have sunk
   into its neighbour by up to one step's travel, which is the paper's point about them.
   Each collision's rigid-body impact response is computed and reported (`impact`).
4. Contacts at the new poses give the touching set of the next step; the exact meshes give the
   largest interpenetration; the paper's tooth-to-tooth distances are measured.

Model (built once) and state (poses, touching pairs) are kept apart: a step never rebuilds geometry.
Units: mm, degrees in reports, cN, cN*mm, days.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterator, Mapping

import numpy as np

from .. import fdi as F
from ..case import Case, Load
from ..collision import CollisionModel, CollisionRequest, ExactQueries, candidate_pairs, contacts, detect_step, interpolate_pose
from ..dentition import Dentition
from ..detectors import DETECTORS
from ..errors import CaseError
from ..metrics import PairDistance, tooth_to_tooth_distances
from .biomechanics import Motion, RateLaw, ToothMechanics, build_mechanics, tooth_motion
from .impact import Body, impact
from .propagation import ForceBalance, propagate

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
        at rest (step 0) by more than this (mm). Arch neighbours get `contact_tolerance_mm`.
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
    def from_case(cls, case: Case) -> "MovementSettings":
        sim = getattr(case, "simulation", None)
        if sim is None:
            return cls()
        return cls(force_share=sim.force_share, restitution=sim.restitution,
                   resistance_rule=sim.resistance_rule, resistance_fraction=sim.resistance_fraction,
                   occlusal_slide_mm=getattr(sim, "occlusal_slide_mm", cls.occlusal_slide_mm))


@dataclass(frozen=True, eq=False)
class CollisionEvent:
    """Two teeth met in a step: at `time` (fraction of the step; 1.0 for discrete detectors, which
    only see the end), with the impact response of the paper."""

    pair: tuple[int, int]
    time: float
    impact: dict


@dataclass(frozen=True, eq=False)
class StepRecord:
    """The state after one step (step 0: the initial state, before any movement).

    poses: FDI -> (4, 4) local -> arch frame, mm (extracted teeth keep their rest pose, not drawn).
    moving: teeth that moved in the step. touching: pairs in contact at the step's end.
    contact_centers (n, 3) mm / contact_radii (n,) mm: overlapping leaf spheres of touching pairs.
    collisions: events of the step. forces: the step's force balance (cN).
    max_penetration_mm: deepest interpenetration the run has added to any candidate pair, on the
        exact meshes (mm; depth now less depth in the initial model, which may have some).
    distances: the paper's tooth-to-tooth distances (mm) per adjacent pair.
    raw_penetration_mm: deepest interpenetration of any candidate pair as it stands (mm).
    penetrating: ((a, b), mm) for every candidate pair interpenetrating as it stands, deepest first.
    """

    step: int
    time_days: float
    poses: dict[int, np.ndarray]
    moving: frozenset[int]
    touching: tuple[tuple[int, int], ...]
    contact_centers: np.ndarray
    contact_radii: np.ndarray
    collisions: tuple[CollisionEvent, ...]
    forces: ForceBalance | None
    max_penetration_mm: float
    distances: tuple[PairDistance, ...]
    raw_penetration_mm: float = 0.0
    penetrating: tuple[tuple[tuple[int, int], float], ...] = ()

    @property
    def total_distance_mm(self) -> float:
        return float(sum(d.distance_mm for d in self.distances))


@dataclass(eq=False)
class MovementModel:
    """What never changes during a run: the case, the dentition, its collision model, each tooth's mechanics."""

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

    @classmethod
    def build(cls, case: Case, dentition: Dentition | None = None, collision: CollisionModel | None = None,
              settings: MovementSettings | None = None, tree_builder: Callable | None = None) -> "MovementModel":
        settings = settings or MovementSettings.from_case(case)
        dentition = dentition or case.build_dentition()
        if collision is None:  # the project's cached sphere trees unless a builder is given
            collision = CollisionModel.from_dentition(dentition, tree_builder=tree_builder)
        extracted = frozenset(case.extractions)
        present = tuple(n for n in dentition.fdis if n not in extracted)
        pairs = candidate_pairs(dentition.fdis, extracted)
        neighbours = set(dentition.adjacent_pairs(set(extracted)))
        facing = frozenset(p for p in pairs if tuple(p) not in neighbours)
        mech = {n: build_mechanics(dentition.teeth[n], settings.resistance_rule, settings.resistance_fraction) for n in present}
        orders = {arch: [t for t in F.arch_order(arch, set(dentition.teeth)) if t not in extracted] for arch in F.Arch}
        return cls(case, dentition, collision, mech, settings, extracted, present, tuple(map(tuple, pairs)), facing,
                   arch_orders=orders)


# ---------------------------------------------------------------------------------------------
# loads: directions and points at the current poses


def _arch_step(fdi: int, direction: str) -> int:
    """+1 / -1: which way along `arch_order` (right to left) is `direction` for this tooth."""
    mesial = 1 if F.quadrant(fdi) in (1, 4) else -1
    return mesial if direction == "mesial" else -mesial


def _horizontal(v: np.ndarray) -> np.ndarray:
    h = np.array([v[0], 0.0, v[2]])
    n = np.linalg.norm(h)
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
    (`_crown_centers`) when the caller has them."""
    order = _present_in_arch(model, fdi)
    i = order.index(fdi)
    j = i + _arch_step(fdi, direction)
    tooth = model.dentition.teeth[fdi]
    R = poses[fdi][:3, :3]
    if 0 <= j < len(order):
        if centers is not None:
            return _horizontal(centers[order[j]] - centers[fdi])
        other = model.dentition.teeth[order[j]]
        c_other = other.to_world(other.crown_center, poses[order[j]])
        return _horizontal(c_other - tooth.to_world(tooth.crown_center, poses[fdi]))
    sign = 1.0 if direction == "mesial" else -1.0
    return _horizontal(sign * (R @ tooth.mesial))


def load_vectors(model: MovementModel, poses: Mapping[int, np.ndarray], load: Load, fdi: int,
                 centers: Mapping[int, np.ndarray] | None = None):
    """(force (3,) cN, point (3,) mm, couple (3,) cN*mm) of one load on one tooth, arch frame, at `poses`
    (centers: the crown centres at `poses`, when the caller has them)."""
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
        u = np.asarray(d, float) / np.linalg.norm(d)
    pt = load.point
    local = {"bracket": mech.bracket, "crown_center": mech.crown_center,
             "center_of_resistance": mech.center_of_resistance}.get(pt) if isinstance(pt, str) else np.asarray(pt, float)
    axis = {"mesiodistal": tooth.mesial, "labiolingual": tooth.labial, "long_axis": tooth.long_axis}[load.moment_axis]
    return load.force_cN * u, R @ local + p, load.moment_cNmm * (R @ axis)


# ---------------------------------------------------------------------------------------------
# one step


def _crown_centers(model: MovementModel, poses: Mapping[int, np.ndarray]) -> dict[int, np.ndarray]:
    return {n: model.dentition.teeth[n].to_world(model.dentition.teeth[n].crown_center, poses[n]) for n in model.present}


def _normal(model: MovementModel, pair: tuple[int, int], centers: Mapping[int, np.ndarray]) -> np.ndarray:
    """Unit vector from pair[0] toward pair[1]: horizontal between crown centres for neighbours,
    vertical for facing (occlusal) pairs."""
    a, b = pair
    if pair in model.facing or (b, a) in model.facing:
        return np.array([0.0, np.sign(centers[b][1] - centers[a][1]) or 1.0, 0.0])
    return _horizontal(centers[b] - centers[a])


def _onward(model: MovementModel, poses, touching, centers=None) -> dict[tuple[int, int], np.ndarray]:
    """(pusher, pushed) -> direction of the force the pushed tooth receives: along the arch, toward
    its own next tooth away from the pusher (the paper's director vector); occlusal pairs: none
    (the contact normal, vertical, is used)."""
    out = {}
    for a, b in touching:
        if (a, b) in model.facing or (b, a) in model.facing or F.arch_of(a) != F.arch_of(b):
            continue
        order = F.arch_order(F.arch_of(a), set(model.dentition.teeth))
        ia, ib = order.index(a), order.index(b)
        for i, j, step in ((a, b, np.sign(ib - ia)), (b, a, np.sign(ia - ib))):
            way = "mesial" if step == _arch_step(j, "mesial") else "distal"
            out[(i, j)] = arch_direction(model, poses, j, way, centers)
    return out


def _motions(model: MovementModel, poses, balance: ForceBalance, loads_on: dict, dt: float, centers) -> dict[int, Motion]:
    """Each tooth's motion over the step under its free force; blocked teeth follow a neighbour that gives way."""
    s = model.settings
    wire = model.case.wire.type
    motions: dict[int, Motion] = {}
    for n in model.present:
        f = balance.free.get(n, np.zeros(3))
        own = loads_on.get(n, [])
        couple = sum((c for _, _, c, _ in own), np.zeros(3))
        if not np.any(f) and not np.any(couple):
            continue
        if own and any(np.any(fv) for fv, _, _, _ in own):
            w = np.array([np.linalg.norm(fv) for fv, _, _, _ in own])
            point = sum(wi * pt for wi, (_, pt, _, _) in zip(w, own)) / max(w.sum(), 1e-12)
        else:
            point = centers[n]
        translation_only = wire == "rectangular" and (not own or any(bodily for *_, bodily in own))
        m = tooth_motion(model.mechanics[n], poses[n], f, point, couple, wire, translation_only, s.rate)
        if not m.is_still:
            motions[n] = m
    if wire != "rectangular":
        return motions
    # a tooth blocked by a neighbour that moves away follows it, as far as its own push would take it
    for _ in range(len(model.present)):
        changed = False
        for i, blockers in balance.blocked_by.items():
            for j in blockers:
                if j not in motions:
                    continue
                n_ij = _normal(model, (i, j), centers)
                p = 0.5 * (centers[i] + centers[j])
                away = float(motions[j].displacement(p, dt)[0] @ n_ij) / dt
                mi = motions.get(i, Motion.still(centers[i]))
                cur = float(mi.displacement(p, dt)[0] @ n_ij) / dt
                push = float(balance.total[i] @ n_ij)
                want = float(s.rate.rate(np.linalg.norm(balance.total[i]), model.mechanics[i].root_area_mm2)) * push / max(
                    np.linalg.norm(balance.total[i]), 1e-12)
                target = min(away, want)
                if target > cur + 1e-12:
                    motions[i] = Motion(mi.pivot, mi.velocity + (target - cur) * n_ij, mi.omega)
                    changed = True
        if not changed:
            break
    return motions


def _approaching(model, pair, motions, dt, centers) -> bool:
    a, b = pair
    p = 0.5 * (centers[a] + centers[b])
    n = _normal(model, pair, centers)
    da = motions[a].displacement(p, dt)[0] if a in motions else np.zeros(3)
    db = motions[b].displacement(p, dt)[0] if b in motions else np.zeros(3)
    return float((da - db) @ n) > 1e-9


def _at_fault(model, pair, motions, dt, centers) -> tuple[int, ...]:
    """The teeth of a colliding pair whose own motion runs into the other (both when neither
    clearly does, e.g. a contact made by turning): those are the ones a contact stops."""
    a, b = pair
    p = 0.5 * (centers[a] + centers[b])
    n = _normal(model, pair, centers)
    ga = float(motions[a].displacement(p, dt)[0] @ n) if a in motions else 0.0
    gb = -float(motions[b].displacement(p, dt)[0] @ n) if b in motions else 0.0
    out = tuple(t for t, g in ((a, ga), (b, gb)) if g > 1e-9)
    return out or pair


def _deepening(depths: dict, initial: dict) -> float:
    """mm: the largest interpenetration the run has added to any pair (a model may start with some)."""
    return max((d - initial.get(p, 0.0) for p, d in depths.items()), default=0.0)


def _deepest_first(depths: dict) -> tuple[tuple[tuple[int, int], float], ...]:
    return tuple(sorted(((tuple(map(int, p)), float(d)) for p, d in depths.items()), key=lambda item: -item[1]))


def _impact(model: MovementModel, pair, motions, P_contact, dt, centers, restitution) -> dict:
    bodies = []
    for n in pair:
        mech = model.mechanics[n]
        T = P_contact[n]
        com = T[:3, :3] @ mech.center_of_mass + T[:3, 3]
        inertia = T[:3, :3] @ mech.inertia_g_mm2 @ T[:3, :3].T
        m = motions.get(n)
        v = m.displacement(com, dt)[0] / dt if m is not None else np.zeros(3)
        w = m.omega if m is not None else np.zeros(3)
        bodies.append(Body(mech.mass_g, com, inertia, v, w))
    c = _crown_centers_of(model, P_contact, pair)
    hit = impact(bodies[0], bodies[1], 0.5 * (c[0] + c[1]), _normal(model, pair, dict(zip(pair, c))), restitution)
    return hit.summary()


def _crown_centers_of(model, P, pair):
    return [model.dentition.teeth[n].to_world(model.dentition.teeth[n].crown_center, P[n]) for n in pair]


def simulate(model: MovementModel, detector: str | None = None, steps: int | None = None,
             queries: ExactQueries | None = None) -> Iterator[StepRecord]:
    """Run the case of `model` with `detector` ('circles', 'discrete', 'continuous', 'exact'; the
    case's by default) for `steps` steps of the case's step_days (the case's count by default).
    Yields the initial state (step 0), then one StepRecord per step. queries: the run's exact
    queries on `model.collision` when the caller has prepared them (a fresh one otherwise)."""
    detector = detector or model.case.detector
    if detector not in DETECTORS:
        raise CaseError(model.case.path, "treatment.detector", f"unknown detector {detector!r}",
                        f"use one of: {', '.join(DETECTORS)}")
    s = model.settings
    dt = float(model.case.step_days)
    n_steps = model.case.steps if steps is None else int(steps)
    P = {n: np.asarray(T, float).copy() for n, T in model.dentition.rest_poses().items()}
    queries = queries or ExactQueries(model.collision)
    touch_request = CollisionRequest(all_leaf_pairs=True, touch_tolerance_mm=s.touch_tolerance_mm)
    found = contacts(model.collision, P, touch_request, queries, model.pairs, detector)
    touching, leaves = list(found.touching), (found.centers, found.radii)
    dist = tuple(tooth_to_tooth_distances(model.dentition, P, set(model.extracted)))
    initial_depths = found.penetration
    yield StepRecord(0, 0.0, {n: T.copy() for n, T in P.items()}, frozenset(), tuple(touching), leaves[0], leaves[1],
                     (), None, 0.0, dist, max(initial_depths.values(), default=0.0), _deepest_first(initial_depths))
    for k in range(1, n_steps + 1):
        centers = _crown_centers(model, P)
        # 1. forces
        loads_on: dict[int, list] = {}
        for load in model.case.loads:
            bodily = load.movement in ("translation", "extrusion", "intrusion") or (
                load.movement == "auto" and load.moment_cNmm == 0.0)
            for n in load.teeth:
                if n in model.mechanics:
                    loads_on.setdefault(n, []).append((*load_vectors(model, P, load, n, centers), bodily))
        applied = {n: sum((f for f, *_ in v), np.zeros(3)) for n, v in loads_on.items()}
        normals = [(a, b, _normal(model, (a, b), centers)) for a, b in touching]
        balance = propagate(applied, normals, s.force_share,
                            lambda n, f: n in model.mechanics and s.rate.moves(f, model.mechanics[n].root_area_mm2),
                            _onward(model, P, touching, centers))
        # 2. motions and intended end poses
        motions = _motions(model, P, balance, loads_on, dt, centers)
        P1 = dict(P)
        for n, m in motions.items():
            P1[n] = m.apply(P[n], dt)
        # 3. collisions
        touching_set = set(touching)
        events: list[CollisionEvent] = []
        tested_pairs: set = set()

        def approaching(pair, current) -> bool:
            # continuous: touching teeth that slide along each other can still sink in, so the
            # exact meshes decide (closer, or sinking deeper, at the end of the motion; teeth of
            # the two arches may slide: only sinking deeper than occlusal_slide_mm counts);
            # discrete detectors only look at the end poses, and the crown centres decide
            if detector != "continuous":
                return _approaching(model, pair, current, dt, centers)
            end = {n: (P1[n] if n in current else P[n]) for n in pair}
            d0, d1 = queries.distance(pair, P), queries.distance(pair, end)
            facing = pair in model.facing
            if d1 > 0.0:
                return not facing and d1 < d0 - 1e-6
            if facing:  # sliding cusps: bounded against the rest state, so steps cannot add up
                return queries.penetration(pair, end) - initial_depths.get(pair, 0.0) > s.occlusal_slide_mm
            start = queries.penetration(pair, P) if d0 <= 0.0 else 0.0
            deeper = queries.penetration(pair, end) - start
            return deeper > (1e-6 if d0 > 0.0 else s.contact_tolerance_mm)

        def tested(current: dict[int, Motion], skip: set) -> list[tuple[int, int]]:
            out = []
            for pair in model.pairs:
                a, b = pair
                if pair in skip or (a not in current and b not in current):
                    continue
                if pair in touching_set and not approaching(pair, current):
                    continue
                out.append(pair)
            return out

        if detector == "continuous":
            tcut = {n: 1.0 for n in motions}
            done: set = set()
            request = CollisionRequest(all_leaf_pairs=False, refine_time_of_contact=True,
                                       contact_tolerance_mm=s.contact_tolerance_mm)
            for _ in range(s.rounds):
                current = {n: m for n, m in motions.items() if tcut[n] > 0}
                pairs = tested(_scaled(current, tcut), done)
                tested_pairs.update(pairs)
                if not pairs:
                    break
                res = detect_step(model.collision, P, P1, pairs, "continuous", request, queries=queries)
                hits = [(tuple(map(int, pr)), float(t)) for pr, t in zip(res.pairs, res.time_of_first_contact) if not np.isnan(t)]
                if not hits:
                    break
                for pair, t in hits:
                    done.add(pair)
                    if pair in touching_set:
                        continue  # a contact held from the last step stops the tooth; it is no new collision
                    P_at = dict(P1)
                    for n in pair:
                        if n in tcut:
                            P_at[n] = interpolate_pose(P[n], P1[n], t)
                    events.append(CollisionEvent(pair, t * _frac(tcut, pair), _impact(model, pair, motions, P_at, dt, centers, s.restitution)))
                cut: dict[int, float] = {}
                scaled = _scaled(motions, tcut)
                for pair, t in hits:
                    for n in _at_fault(model, pair, scaled, dt, centers):
                        if n in tcut:
                            cut[n] = min(cut.get(n, 1.0), t)
                for n, t in cut.items():
                    P1[n] = interpolate_pose(P[n], P1[n], t)
                    tcut[n] *= t
            # The sliding allowance was checked at the intended end of each move; a move cut short
            # by another contact may stop mid-way over a cusp, deeper than its end would be: such a
            # tooth keeps its start pose, so the bound holds on the poses a step leaves.
            for pair in touching_set:
                if pair in model.facing and any(P1[n] is not P[n] for n in pair) and \
                        queries.penetration(pair, P1) - initial_depths.get(pair, 0.0) > s.occlusal_slide_mm:
                    for n in pair:
                        P1[n] = P[n]
        else:
            pairs = tested(motions, set())
            tested_pairs.update(pairs)
            if pairs:
                res = detect_step(model.collision, P, P1, pairs, detector)
                for pair in res.touching_pairs():
                    if pair not in touching_set:
                        events.append(CollisionEvent(pair, 1.0, _impact(model, pair, motions, P1, dt, centers, s.restitution)))
        moved = frozenset(n for n in motions if not np.allclose(P1[n], P[n], atol=1e-12))
        P = P1
        # 4. contacts, interpenetration, distances
        before = touching_set
        found = contacts(model.collision, P, touch_request, queries, model.pairs, detector)
        touching, leaves = list(found.touching), (found.centers, found.radii)
        # a moving tooth that made a new contact without a reported hit (it stopped within the
        # touching tolerance) has collided too; teeth sliding over the other arch's have not
        seen = {e.pair for e in events}
        for pair in touching:
            if pair not in before and pair not in seen and pair in tested_pairs:
                events.append(CollisionEvent(pair, 1.0, _impact(model, pair, motions, P, dt, centers, s.restitution)))
        dist = tuple(tooth_to_tooth_distances(model.dentition, P, set(model.extracted)))
        yield StepRecord(k, k * dt, {n: T.copy() for n, T in P.items()}, moved, tuple(touching), leaves[0], leaves[1],
                         tuple(events), balance, max(0.0, _deepening(found.penetration, initial_depths)), dist,
                         max(found.penetration.values(), default=0.0), _deepest_first(found.penetration))


def simulate_case(case: Case, detector: str | None = None, steps: int | None = None,
                  dentition: Dentition | None = None) -> Iterator[StepRecord]:
    """`simulate(MovementModel.build(case, dentition), detector, steps)`: a whole run from the case
    (and its dentition, when the caller has built it already: building one takes seconds).

    Everything it needs pickles, so it can run in a child process beside the renderer
    (`orthosim.background.in_child_process(simulate_case, case, detector)`); the child builds the
    same model from the same case and yields the same records.
    """
    return simulate(MovementModel.build(case, dentition=dentition), detector, steps)


def _scaled(motions: dict[int, Motion], tcut: dict[int, float]) -> dict[int, Motion]:
    """Motions shortened to the fraction of the step each tooth still makes (for the approach test)."""
    return {n: Motion(m.pivot, m.velocity * tcut[n], m.omega * tcut[n]) for n, m in motions.items()}


def _frac(tcut: dict[int, float], pair) -> float:
    return min((tcut.get(n, 1.0) for n in pair), default=1.0)

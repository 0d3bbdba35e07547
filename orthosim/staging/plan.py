"""The staging planner: from start to target in aligner stages, within the limits, free of contact.

Each tooth follows one path from its start pose to its target pose, the motion the continuous
detector checks (`geometry.motion`: origin on a straight line, rotation at constant angular
velocity); the plan is how far along that path (progress 0..1) each tooth is at each stage. A
stage's motion between two progress values is that same path's piece, so its movement components
are the whole movement's times the progress made, and the limits cap each tooth's progress per
stage at `rate` = min over components of limit / |total|.

The lower bound is the largest per-tooth count ceil(1 / rate). The planner first offers every
tooth the clinicians' default, all teeth moving together at 1 / lower bound per stage (a tooth
delayed earlier catches up at up to its own rate), and checks that stage's motion for contact
(`staging.contacts`). Each contact is resolved by holding one of its two teeth at its pose for
that stage (delaying it; its movement is then split over later stages): the one whose holding
frees the pair, and of two such the one moving toward the other (so molars distalise before the
premolars that follow them, and a tooth leaves a place before another moves into it). The stage is
checked again until it is free. Teeth that no order can bring to the target without contact are
reported; teeth that do not fit at the target get interproximal reduction first (`staging.ipr`),
cut from their meshes before stage 1 (`staging.reduction`), so every stage is checked reduced.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from orthosim.model import fdi as F
from orthosim.collision.broadphase import arch_neighbour_pairs
from orthosim.collision.model import CollisionModel
from orthosim.geometry.motion import interpolate_pose
from orthosim.model.dentition import Dentition
from orthosim.staging.contacts import StageChecker, reduced_model
from orthosim.staging.ipr import InterproximalReduction, StagingError, reduction_for
from orthosim.staging.limits import StageLimits
from orthosim.staging.reduction import reduced_meshes
from orthosim.exchange.target import movement_components

_EPS = 1e-9


@dataclass(frozen=True, eq=False)
class StagingPlan:
    """A staged set-up. Stage 0 is the start; stage k's poses are where aligner k takes the teeth."""

    teeth: tuple[int, ...]  # FDI of every staged tooth (moving or not), dentition order
    start: dict[int, np.ndarray]  # FDI -> (4, 4) local -> arch frame, mm
    target: dict[int, np.ndarray]  # FDI -> (4, 4)
    progress: np.ndarray  # (stages + 1, teeth) fraction of each tooth's path reached at each stage
    totals: np.ndarray  # (teeth, 6) whole movement per tooth, COMPONENTS order (mm, mm, mm, deg, deg, deg)
    limits: StageLimits
    lower_bound: int  # the largest per-tooth stage count from the limits alone
    ipr: tuple[InterproximalReduction, ...] = ()
    held: tuple[tuple[int, int], ...] = ()  # (stage, FDI): a tooth held back at a stage to avoid a contact
    planning_s: float = 0.0
    fcl_queries: int = 0
    order_constraints: tuple[str, ...] = field(default=())  # "41 waits for 42": sequencing found necessary

    @property
    def n_stages(self) -> int:
        return len(self.progress) - 1

    @property
    def ipr_total_mm(self) -> float:
        return float(sum(r.amount_mm for r in self.ipr))

    def poses(self, stage: int) -> dict[int, np.ndarray]:
        """FDI -> (4, 4) pose of every staged tooth at `stage` (0 = start)."""
        return {n: path_pose(self.start[n], self.target[n], float(self.progress[stage, i])) for i, n in enumerate(self.teeth)}

    def stage_components(self) -> np.ndarray:
        """(stages, teeth, 6) each tooth's movement in each stage (mm, mm, mm, deg, deg, deg)."""
        dp = np.diff(self.progress, axis=0)
        return dp[:, :, None] * self.totals[None, :, :]


def path_pose(start: np.ndarray, target: np.ndarray, s: float) -> np.ndarray:
    """(4, 4) pose at progress s (0..1) along the tooth's path; exactly the target at s = 1."""
    if s <= 0.0:
        return np.array(start, float)
    if s >= 1.0:
        return np.array(target, float)
    return interpolate_pose(start, target, s)


def per_stage_rate(totals: np.ndarray, limits: StageLimits) -> np.ndarray:
    """(teeth,) the largest progress per stage each tooth's limits allow (inf for a tooth that stays)."""
    with np.errstate(divide="ignore"):
        ratio = np.abs(totals) / limits.array()[None, :]
    worst = ratio.max(axis=1)
    return np.where(worst > 1e-12, 1.0 / np.maximum(worst, 1e-300), np.inf)


def stage_counts(totals: np.ndarray, limits: StageLimits) -> np.ndarray:
    """(teeth,) int: stages each tooth needs from the limits alone (0 for a tooth that stays)."""
    with np.errstate(divide="ignore"):
        ratio = np.abs(totals) / limits.array()[None, :]
    return np.ceil(ratio.max(axis=1) - 1e-9).astype(int).clip(min=0)


def plan_staging(dentition: Dentition, start: dict[int, np.ndarray], target: dict[int, np.ndarray],
                 limits: StageLimits = StageLimits(), model: CollisionModel | None = None,
                 absent: frozenset[int] = frozenset(), max_stages: int | None = None, source=None) -> StagingPlan:
    """Plan the stages from `start` to `target` (FDI -> (4, 4) poses; teeth in `absent`, e.g.
    extracted, take no part). Raises StagingError (naming `source`, the case file, if given) when
    no contact-free staging is found."""
    started = time.perf_counter()
    teeth = tuple(n for n in dentition.fdis if n not in absent)
    if model is None:
        model = CollisionModel.from_dentition(Dentition({n: dentition.teeth[n] for n in teeth}))
    starts = {n: np.asarray(start[n], float) for n in teeth}
    targets = {n: np.asarray(target.get(n, start[n]), float) for n in teeth}
    totals = np.stack([movement_components(dentition.teeth[n], starts[n], starts[n], targets[n]) for n in teeth])
    rate = per_stage_rate(totals, limits)
    lower = int(stage_counts(totals, limits).max(initial=0))

    checker = StageChecker(model)
    at_start = checker.contacts(starts, starts)
    if at_start:
        c = at_start[0]
        raise StagingError(source, f"start poses of teeth {c.a} and {c.b}",
                           f"intersect before any movement ({len(at_start)} intersecting pair(s))",
                           "stage from a contact-free start (separate the teeth or fix the model)")
    ipr = _reductions(dentition, model, checker, targets, teeth, source)
    if ipr:  # done before stage 1: every stage's motion is checked on the reduced teeth
        checker = StageChecker(reduced_model(model, reduced_meshes({b.key: b.mesh for b in model.bodies}, ipr, targets)))
    moving = np.array([np.any(np.abs(targets[n] - starts[n]) > 0) for n in teeth])
    order = {n: i for i, n in enumerate(teeth)}
    after: dict[int, set[int]] = {}  # tooth index -> teeth that must finish before it moves
    for _ in range(2 * len(teeth)):
        try:
            rows, held = _greedy(checker, dentition, teeth, order, starts, targets, rate, lower, moving, after,
                                 max_stages or (10 * lower + 50), source)
        except _Stuck as stuck:
            stage, contacts = stuck.args
        else:
            return StagingPlan(teeth, starts, targets, np.array(rows), totals, limits, lower, tuple(ipr), tuple(held),
                               time.perf_counter() - started, checker.fcl_queries,
                               tuple(f"{teeth[i]} waits for {', '.join(str(teeth[j]) for j in sorted(js))}"
                                     for i, js in sorted(after.items())))
        added = False
        for c in contacts:  # the tooth that moves toward the other waits until the other has arrived
            ia, ib = order[c.a], order[c.b]
            wait, lead = (ia, ib) if _path_approach(dentition, teeth, starts, targets, ia, ib) >= \
                _path_approach(dentition, teeth, starts, targets, ib, ia) else (ib, ia)
            if lead in after.get(wait, set()) or wait in _waits_for(after, lead):
                continue
            after.setdefault(wait, set()).add(lead)
            added = True
        if not added:
            pairs = ", ".join(f"{c.a}-{c.b}" for c in contacts)
            raise StagingError(source, f"teeth {pairs}",
                               f"cannot move on from stage {stage} without contact along their paths, in any order tried",
                               "change the target so the teeth can pass (e.g. more space, or a different path)")
    raise StagingError(source, "staging", "no contact-free order found", "change the target so the teeth can pass")


class _Stuck(Exception):
    """The greedy pass cannot move on: (stage, contacts of its proposal)."""


def _waits_for(after: dict[int, set[int]], i: int) -> set[int]:
    """Every tooth that tooth i waits for, directly or through others."""
    seen, todo = set(), [i]
    while todo:
        for j in after.get(todo.pop(), ()):
            if j not in seen:
                seen.add(j)
                todo.append(j)
    return seen


def _path_approach(dentition, teeth, starts, targets, i: int, j: int) -> float:
    """mm: how far tooth i's crown centre moves toward tooth j's over its whole path."""
    ti, tj = dentition.teeth[teeth[i]], dentition.teeth[teeth[j]]
    ci0 = ti.to_world(ti.crown_center, starts[teeth[i]])
    ci1 = ti.to_world(ti.crown_center, targets[teeth[i]])
    cj = tj.to_world(tj.crown_center, starts[teeth[j]])
    return float((ci1 - ci0) @ ((cj - ci0) / np.linalg.norm(cj - ci0)))


def _greedy(checker, dentition, teeth, order, starts, targets, rate, lower, moving, after, cap, source):
    """One pass of the stage-by-stage planner under the `after` constraints: (rows, held) when it
    reaches the target; _Stuck(stage, contacts) when no tooth can move on without contact."""
    s = np.where(moving, 0.0, 1.0)
    rows = [s.copy()]
    held: list[tuple[int, int]] = []
    step = 1.0 / lower if lower else 1.0
    while np.any(s < 1.0):
        k = len(rows) - 1
        if k >= cap:
            raise StagingError(source, "staging", f"not finished after {cap} stages", "relax the limits or check the target")
        goal = min(1.0, (k + 1) * step)
        proposal = np.minimum(1.0, s + np.minimum(rate, np.maximum(step, goal - s)))
        proposal[proposal > 1.0 - _EPS] = 1.0  # float dust of k steps of 1 / k
        for i, leads in after.items():
            if any(s[j] < 1.0 for j in leads):
                proposal[i] = s[i]
        proposal, stage_held, contacts = _resolve(checker, dentition, teeth, order, starts, targets, s, proposal)
        held += [(k + 1, n) for n in stage_held]
        if np.array_equal(proposal, s):
            raise _Stuck(k, contacts)
        s = proposal
        rows.append(s.copy())
    return rows, held


def _reductions(dentition, model, checker, targets, teeth, source) -> list[InterproximalReduction]:
    """IPR for each pair of arch neighbours intersecting at the target; StagingError for any other
    intersecting pair (teeth that are not neighbours cannot be stripped apart)."""
    neighbours = {tuple(sorted(p)) for p in arch_neighbour_pairs(teeth)}
    out = []
    for c in checker.contacts(targets, targets):
        if (c.a, c.b) not in neighbours:
            where = "of opposing arches" if F.arch_of(c.a) is not F.arch_of(c.b) else "that are not neighbours"
            raise StagingError(source, f"target of teeth {c.a} and {c.b}", f"the teeth intersect at the target ({where})",
                               "change the target so these teeth do not meet there")
        out.append(reduction_for(dentition, c.a, c.b, targets[c.a], targets[c.b], source))
    return out


def _resolve(checker: StageChecker, dentition, teeth, order, starts, targets, s, proposal):
    """The proposal with teeth held back until the stage's motion is free of contact:
    (progress, held FDIs, the contacts of the first proposal)."""
    proposal = proposal.copy()
    held: list[int] = []

    def poses(p):
        return {n: path_pose(starts[n], targets[n], float(p[i])) for i, n in enumerate(teeth)}

    P0 = poses(s)
    first: list = []
    for _ in range(len(teeth) + 1):
        contacts = checker.contacts(P0, poses(proposal))
        if not contacts:
            return proposal, held, first
        first = first or contacts
        for c in contacts:
            ia, ib = order[c.a], order[c.b]
            options = [i for i in (ia, ib) if proposal[i] > s[i]]
            if len(options) < 2:
                pick = options  # one moving tooth meets one at rest (or already held): hold the moving one
            else:
                pick = _choose_hold(checker, dentition, teeth, starts, targets, s, proposal, ia, ib, P0)
            for i in pick:
                proposal[i] = s[i]
                held.append(teeth[i])
    # every round held a tooth per contact; should contacts remain, nothing moves this stage
    return s.copy(), held + [n for i, n in enumerate(teeth) if proposal[i] > s[i]], first


def _choose_hold(checker, dentition, teeth, starts, targets, s, proposal, ia, ib, P0) -> list[int]:
    """Which of two moving teeth in contact to hold: the one whose holding frees the pair; of two
    such, the one whose crown moves toward the other; when neither frees it, both."""
    a, b = teeth[ia], teeth[ib]
    frees = []
    for hold, other in ((ia, ib), (ib, ia)):
        end = {a: P0[a], b: P0[b]}
        end[teeth[other]] = path_pose(starts[teeth[other]], targets[teeth[other]], float(proposal[other]))
        if not checker.contacts({a: P0[a], b: P0[b]}, end, pairs=[(a, b)]):
            frees.append(hold)
    if len(frees) == 1:
        return frees
    if not frees:
        return [ia, ib]

    def approach(i, j):
        ti, tj = dentition.teeth[teeth[i]], dentition.teeth[teeth[j]]
        ci0 = ti.to_world(ti.crown_center, P0[teeth[i]])
        ci1 = ti.to_world(ti.crown_center, path_pose(starts[teeth[i]], targets[teeth[i]], float(proposal[i])))
        cj = tj.to_world(tj.crown_center, P0[teeth[j]])
        u = (cj - ci0) / np.linalg.norm(cj - ci0)
        return float((ci1 - ci0) @ u)

    return [ia] if approach(ia, ib) >= approach(ib, ia) else [ib]



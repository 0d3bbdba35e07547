"""certificate.json: the per-stage record that a staging keeps within its limits and free of contact.

For every transition (stage k-1 -> k) it lists
  - every staged tooth's increment per component (mm, mm, mm, deg, deg, deg; measured from the two
    poses with `target.movement_components`, in the tooth's start frame) against its limit;
  - every pair of teeth that comes within `REACH_MM` of each other during the motion, with the
    least distance between their meshes over the whole motion (`sweep.min_clearance`: FCL's exact
    mesh distance, branch and bound on the motion law's speed bound, to `TOLERANCE_MM`) and whether
    the two move relative to each other at all;
  - the interproximal reduction applied before it (all of it before stage 1: `staging.ipr`).
From stage 1 on every clearance is measured between the reduced teeth (`staging.reduction`: the
planned enamel cut off each contact side by a plane), the same teeth the stage models hold.
The start (stage 0) is certified too: every pair within REACH_MM there, unreduced.

`certify_stages` computes it from the poses alone, so `orthosim stage verify` recomputes every
figure from the written files with the same code and compares it with what the file claims,
within the `TOLERANCES` the file states.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthosim import __version__
from orthosim.staging.ipr import InterproximalReduction
from orthosim.staging.limits import StageLimits
from orthosim.staging.reduction import reduced_meshes
from orthosim.staging.sweep import ToothBodies, min_clearance
from orthosim.exchange.target import COMPONENTS, UNITS, movement_components

REACH_MM = 1.0  # pairs that come within this of each other are listed with their clearance
TOLERANCE_MM = 1e-3  # the true least clearance is within this below the one reported
LIMIT_SLACK = 1e-7  # mm or degrees: floating-point rounding allowed above a limit
# how far a recomputed figure may be from the one the file states (certificate.json's `tolerances`):
# clearances to the branch and bound's tolerance, the rest to the digits they are written with
TOLERANCES = {"clearance_mm": TOLERANCE_MM, "increment": 1e-6, "ratio": 1e-6, "ipr_mm": 1e-4, "time": 1e-5}


@dataclass(frozen=True)
class PairClearance:
    """Teeth a < b (FDI): least distance over a stage's motion (mm) and where it was found."""

    a: int
    b: int
    min_mm: float  # smallest exact distance found (0.0: the meshes intersect)
    lower_bound_mm: float  # proven lower bound: min_mm - lower_bound_mm <= TOLERANCE_MM
    time: float  # fraction 0..1 of the stage
    relative_motion: bool  # False: the two keep their relative pose (constant distance)
    ipr_mm: float = 0.0  # reduction planned at this contact, both teeth together (0.0: none, or unreduced)


@dataclass(frozen=True, eq=False)
class Transition:
    """Stage `stage - 1` -> `stage`."""

    stage: int
    teeth: tuple[int, ...]
    increments: np.ndarray  # (teeth, 6) COMPONENTS order: mm, mm, mm, deg, deg, deg
    clearances: tuple[PairClearance, ...]
    ipr: tuple[InterproximalReduction, ...]

    def ratios(self, limits: StageLimits) -> np.ndarray:
        """(teeth, 6) |increment| / limit."""
        return np.abs(self.increments) / limits.array()[None, :]


@dataclass(frozen=True, eq=False)
class Certificate:
    limits: StageLimits
    start: tuple[PairClearance, ...]  # stage 0, unreduced
    transitions: tuple[Transition, ...]

    def within_limits(self) -> bool:
        lim = self.limits.array()
        return all(bool(np.all(np.abs(t.increments) <= lim + LIMIT_SLACK)) for t in self.transitions)

    def contact_free(self) -> bool:
        return all(c.min_mm > 0.0 for _, c in self.all_clearances())

    def all_clearances(self) -> list[tuple[int, PairClearance]]:
        return [(0, c) for c in self.start] + [(t.stage, c) for t in self.transitions for c in t.clearances]


def clearances(bodies: ToothBodies, P0: dict, P1: dict, ipr_mm: dict | None = None) -> tuple[PairClearance, ...]:
    """Every pair within REACH_MM during the motion P0 -> P1 (FDI -> (4, 4)), with its clearance;
    ipr_mm: (a, b) -> the reduction planned at that contact (mm), when the bodies are reduced."""
    out = []
    for a, b in bodies.near_pairs(P0, P1, REACH_MM):
        motion = bodies.motion(a, b, P0, P1)
        c = min_clearance(motion, TOLERANCE_MM, reach_mm=REACH_MM)
        if c.lower_bound_mm <= REACH_MM:
            ipr = (ipr_mm or {}).get((a, b), 0.0)
            out.append(PairClearance(a, b, c.min_mm, c.lower_bound_mm, c.time, motion.mu > 0.0, ipr))
    return tuple(out)


def staged_bodies(dentition, teeth, ipr, target: dict) -> tuple[ToothBodies, ToothBodies]:
    """(the whole teeth, the teeth reduced by the IPR contacts) as exact bodies (the same object when
    there is no IPR): stage 0's teeth and every later stage's."""
    meshes = {n: dentition.teeth[n].mesh for n in teeth}
    whole = ToothBodies(meshes)
    return whole, (ToothBodies(reduced_meshes(meshes, ipr, target)) if ipr else whole)


def certify_stages(dentition, teeth, start: dict, stage_poses, limits: StageLimits, ipr, target: dict,
                   bodies: tuple[ToothBodies, ToothBodies] | None = None) -> Certificate:
    """The certificate of a staging given by its poses: `teeth` (FDI) of `dentition`, `start` (FDI ->
    (4, 4): the frames increments are measured in), stage_poses[k] (FDI -> (4, 4)) for k = 0..N,
    the `InterproximalReduction`s done before stage 1 and the `target` poses their cuts are set at;
    bodies: `staged_bodies` of the same, when the caller has them."""
    whole, reduced = bodies or staged_bodies(dentition, teeth, ipr, target)
    amounts = {(min(r.a, r.b), max(r.a, r.b)): float(r.amount_mm) for r in ipr}
    poses = list(stage_poses)
    first = clearances(whole, poses[0], poses[0])
    transitions = []
    for k in range(1, len(poses)):
        inc = np.stack([movement_components(dentition.teeth[n], start[n], poses[k - 1][n], poses[k][n]) for n in teeth])
        transitions.append(Transition(k, tuple(teeth), inc, clearances(reduced, poses[k - 1], poses[k], amounts),
                                      tuple(ipr) if k == 1 else ()))
    return Certificate(limits, first, tuple(transitions))


def certify(plan, dentition) -> Certificate:
    """The certificate of a `StagingPlan` of `dentition`'s teeth."""
    return certify_stages(dentition, plan.teeth, plan.start, [plan.poses(k) for k in range(plan.n_stages + 1)],
                          plan.limits, plan.ipr, plan.target)


def _pair_record(c: PairClearance) -> dict:
    return {"fdi_a": c.a, "fdi_b": c.b, "min_clearance_mm": c.min_mm,
            "lower_bound_mm": c.lower_bound_mm, "at_time": round(c.time, 5),
            "relative_motion": c.relative_motion, "ipr_mm": round(c.ipr_mm, 4)}


def summary(cert: Certificate) -> dict:
    """The headline numbers: whether it holds, the largest use of a limit, the least clearance."""
    lim = cert.limits.array()
    worst = (0.0, None, None, None)
    for t in cert.transitions:
        r = t.ratios(cert.limits)
        if r.size and r.max() > worst[0]:
            i, j = np.unravel_index(int(np.argmax(r)), r.shape)
            worst = (float(r[i, j]), t.stage, t.teeth[i], COMPONENTS[j])
    pairs = cert.all_clearances()
    moving = [sc for sc in pairs if sc[1].relative_motion]
    closest = min(moving, key=lambda sc: sc[1].min_mm) if moving else None
    still = [sc for sc in pairs if not sc[1].relative_motion]
    closest_still = min(still, key=lambda sc: sc[1].min_mm) if still else None
    return {
        "transitions": len(cert.transitions),
        "within_limits": cert.within_limits(),
        "contact_free": cert.contact_free(),
        "largest_limit_use": {"ratio": round(worst[0], 6), "stage": worst[1], "fdi": worst[2], "component": worst[3],
                              "limit": None if worst[3] is None else f"{lim[COMPONENTS.index(worst[3])]:g} {UNITS[worst[3]]}"},
        # between teeth moving relative to each other (what the staging decides), and between teeth
        # keeping their relative pose (neighbours that touch in the model itself, at the start)
        "least_clearance": None if closest is None else {"stage": closest[0], **_pair_record(closest[1])},
        "least_clearance_at_rest": None if closest_still is None else {"stage": closest_still[0], **_pair_record(closest_still[1])},
        "pairs_within_reach": len(pairs),
        "ipr_total_mm": round(sum(r.amount_mm for t in cert.transitions for r in t.ipr), 4),
    }


def certificate_record(cert: Certificate, case_file=None, case_sha256: str | None = None) -> dict:
    """The certificate.json content (see the module docstring)."""
    names = [f"{c}_{UNITS[c]}" for c in COMPONENTS]
    lim = cert.limits.array()
    transitions = []
    for t in cert.transitions:
        ratio = t.ratios(cert.limits)
        teeth = [{"fdi": n, **{k: round(float(v), 6) for k, v in zip(names, t.increments[i])},
                  "largest_ratio": round(float(ratio[i].max()), 6),
                  "within": bool(np.all(np.abs(t.increments[i]) <= lim + LIMIT_SLACK))}
                 for i, n in enumerate(t.teeth)]
        transitions.append({"stage": t.stage, "from_stage": t.stage - 1,
                            "within_limits": all(x["within"] for x in teeth),
                            "contact_free": all(c.min_mm > 0.0 for c in t.clearances),
                            "teeth": teeth, "clearances": [_pair_record(c) for c in t.clearances],
                            "ipr": [{"fdi_a": r.a, "fdi_b": r.b, "ipr_mm": round(r.amount_mm, 4)} for r in t.ipr]})
    return {
        "orthosim_version": __version__,
        "case_file": None if case_file is None else str(case_file),
        "case_sha256": case_sha256,
        "limits": {n: float(v) for n, v in zip(names, lim)},
        "method": {"clearance_reach_mm": REACH_MM, "clearance_tolerance_mm": TOLERANCE_MM,
                   "limit_slack": LIMIT_SLACK, "ipr": "a plane cut of half the reduction on each tooth's contact side, from stage 1 on (orthosim.staging.reduction)",
                   "motion": "origin on a straight line, rotation at constant angular velocity (orthosim.geometry.motion)",
                   "clearance": "FCL exact mesh distance, branch and bound on the relative speed bound"},
        "tolerances": dict(TOLERANCES),
        "summary": summary(cert),
        "start": {"clearances": [_pair_record(c) for c in cert.start]},
        "transitions": transitions,
    }

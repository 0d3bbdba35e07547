"""`orthosim stage verify DIR`: re-check a written staging from its files alone.

What is read: DIR/stages.json (`stagesfile.read_stages`, every field checked), the case file it
names (unchanged since staging: its SHA-256 must match) and the tooth models that case builds.
Nothing of the planner's memory is used: not its progress values, its contact checker or its
collision model. What is checked, in stage order (the first failure is the one named):

  1. the folder belongs to the case: the same staged teeth, stage 0 at the case's start poses;
  2. stage 0: no two teeth intersect (FCL on the whole meshes);
  3. each transition k-1 -> k: every tooth's increment per component (`target.movement_components`,
     in its start frame) within the file's limits (or `--limits`), allowing `LIMIT_SLACK`;
  4. each transition: no two teeth intersect anywhere along the motion, by dense sampling with
     FCL (`sweep.first_contact_on_grid`) at a spacing where no vertex moves more than `STEP_MM`
     relative to the other tooth between two samples; an intersection deeper than STEP_MM / 2
     cannot fall between samples. STEP_MM = 0.005 mm is 2 % of the default 0.25 mm mesiodistal
     limit and 3 % of the 0.15 mm extrusion limit: a stage within the limits moves a vertex by
     up to about 1 mm (2 degrees at a 13 mm root tip plus 0.25 mm), so a moving pair is
     sampled at a few hundred times, skipping only times that an FCL distance already proves free.
     A pair with interproximal reduction is tested reduced as the planner modelled it
     (`staging.ipr`: moved apart along the recorded direction by half the reduction each);
  5. the last stage is the case's target (every pose within `TARGET_ATOL_MM`);
  6. each recorded interproximal reduction is earned: the two teeth are arch neighbours, the
     direction is the one between their crown centres at the target, and the amount is no more
     than their exact overlap along it at the target (`ipr.penetration_along`, + its resolution):
     an inflated reduction would move the pair apart in step 4 and hide a real contact.
A damaged or inconsistent folder raises StagingFolderError (exit 2); violations are returned.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from orthosim.staging.certificate import LIMIT_SLACK
from orthosim.staging.ipr import CLEARANCE_MM
from orthosim.staging.limits import StageLimits
from orthosim.staging.stagesfile import StagingFolderError, WrittenStaging, read_stages
from orthosim.staging.sweep import ToothBodies, first_contact_on_grid
from orthosim.exchange.target import COMPONENTS, UNITS, movement_components

STEP_MM = 0.005  # the most any vertex moves relative to another tooth between two samples
TARGET_ATOL_MM = 1e-6  # a written pose within this of the case's own (matrix entries, mm)


@dataclass(frozen=True)
class Violation:
    stage: int  # the stage reached by the failing transition (0: the start itself)
    kind: str  # "limit", "contact" or "target"
    text: str  # one line, naming the teeth and the numbers


@dataclass
class Verdict:
    folder: Path
    stages: int
    teeth: int
    limits: StageLimits
    step_mm: float
    violations: list[Violation] = field(default_factory=list)
    pairs_checked: int = 0  # pair-transitions sampled
    fcl_queries: int = 0
    seconds: float = 0.0

    @property
    def holds(self) -> bool:
        return not self.violations

    def line(self) -> str:
        if self.holds:
            return (f"{self.folder}: all {self.stages} stages of {self.teeth} teeth hold: within the limits "
                    f"({self.limits.text()}) and free of contact (sampled to {self.step_mm:g} mm, "
                    f"{self.pairs_checked} pair-stages, {self.fcl_queries} FCL queries, {self.seconds:.1f} s)")
        v = self.violations[0]
        more = f" ({len(self.violations) - 1} more)" if len(self.violations) > 1 else ""
        return f"{self.folder}: stage {v.stage}: {v.kind}: {v.text}{more}"


def load_for_verify(folder: str | Path, case_path: str | Path | None = None):
    """(written staging, dentition, start poses, target poses), every file checked and the case
    matched to the staging; StagingFolderError (or the case's own CaseError) otherwise."""
    from orthosim.exchange.case import load_case
    from orthosim.storage.checksums import file_sha256

    written = read_stages(folder)
    case_file = Path(case_path) if case_path is not None else written.case_file
    if case_file is None or not case_file.is_file():
        raise StagingFolderError(written.path, "case_file", f"names no case file here ({case_file})",
                                 "give the case with --case PATH")
    if written.case_sha256 is not None and file_sha256(case_file) != written.case_sha256:
        raise StagingFolderError(case_file, None, "is not the case file this staging was written from: it has changed since, or is another (SHA-256 differs)",
                                 "give the case it was staged from with --case, or stage this one again")
    case = load_case(case_file)
    if case.staging is None or case.staging.target is None:
        raise StagingFolderError(case_file, "target", "missing: this case has nothing staged", "give the staged case with --case")
    dent = case.build_dentition()
    start, target = case.staging.poses(dent)
    staged = tuple(n for n in dent.fdis if n not in set(case.extractions))
    if set(staged) != set(written.teeth):
        raise StagingFolderError(written.path, "teeth", f"do not match the case's teeth ({len(written.teeth)} vs {len(staged)})",
                                 "give the case it was staged from with --case")
    for n in written.teeth:
        if np.abs(written.poses[0][n] - start[n]).max() > TARGET_ATOL_MM:
            raise StagingFolderError(written.path, f"poses[0].poses.{n}", "is not the case's start pose of this tooth",
                                     "give the case it was staged from with --case, or stage it again")
    return written, dent, start, target


def verify_staging(written: WrittenStaging, dentition, start: dict, target: dict, limits: StageLimits | None = None,
                   step_mm: float = STEP_MM, folder: Path | None = None) -> Verdict:
    """Check a read staging against the case's teeth, start and target (see the module docstring)."""
    began = time.perf_counter()
    limits = limits or written.limits
    verdict = Verdict(Path(folder or written.path.parent), written.n_stages, len(written.teeth), limits, step_mm)
    meshes = {n: dentition.teeth[n].mesh for n in written.teeth}
    shifts = {}
    for r in written.ipr:
        h = 0.5 * (r.amount_mm + CLEARANCE_MM)
        shifts[(r.a, r.b)] = (-h * r.direction, h * r.direction)
    bodies = ToothBodies(meshes, shifts)
    P = written.poses
    _contacts(verdict, bodies, 0, P[0], P[0], step_mm, shifted=False)
    for k in range(1, written.n_stages + 1):
        _limits(verdict, dentition, start, written.teeth, k, P[k - 1], P[k], limits)
        _contacts(verdict, bodies, k, P[k - 1], P[k], step_mm)
    _ipr(verdict, written, dentition, target, bodies)
    last = written.n_stages
    for n in written.teeth:
        off = float(np.abs(P[last][n] - target[n]).max())
        if off > TARGET_ATOL_MM:
            verdict.violations.append(Violation(last, "target", f"tooth {n} ends off its target (pose entries differ by up to {off:.4g})"))
    verdict.violations.sort(key=lambda v: v.stage)  # stable: in a stage, limits, contacts, target, IPR
    verdict.seconds = time.perf_counter() - began
    return verdict


def _limits(verdict: Verdict, dentition, start, teeth, k: int, P0: dict, P1: dict, limits: StageLimits) -> None:
    lim = limits.array()
    for n in teeth:
        c = movement_components(dentition.teeth[n], start[n], P0[n], P1[n])
        over = np.flatnonzero(np.abs(c) > lim + LIMIT_SLACK)
        for j in over:
            name, unit = COMPONENTS[j], UNITS[COMPONENTS[j]]
            verdict.violations.append(Violation(k, "limit", f"tooth {n} moves {c[j]:+.4f} {unit} {name}, "
                                                f"beyond the limit of {lim[j]:g} {unit} per stage"))


def _contacts(verdict: Verdict, bodies: ToothBodies, k: int, P0: dict, P1: dict, step_mm: float, shifted: bool = True) -> None:
    for a, b in bodies.near_pairs(P0, P1, 0.0):
        motion = bodies.motion(a, b, P0, P1, shifted)
        t = first_contact_on_grid(motion, step_mm)
        verdict.pairs_checked += 1
        verdict.fcl_queries += motion.queries
        if t is not None:
            when = "at the start" if k == 0 else f"at {100 * t:.1f} % of the motion from stage {k - 1}"
            verdict.violations.append(Violation(k, "contact", f"teeth {a} and {b} intersect {when}"))


def _ipr(verdict: Verdict, written: WrittenStaging, dentition, target: dict, bodies: ToothBodies) -> None:
    from orthosim.collision.broadphase import arch_neighbour_pairs
    from orthosim.staging.ipr import RESOLUTION_MM, penetration_along

    neighbours = {tuple(sorted(p)) for p in arch_neighbour_pairs(written.teeth)}
    for r in written.ipr:
        a, b = r.a, r.b
        name = f"IPR of {a}/{b} ({r.amount_mm:.3f} mm)"
        if (min(a, b), max(a, b)) not in neighbours:
            verdict.violations.append(Violation(1, "ipr", f"{name}: the two teeth are not arch neighbours"))
            continue
        ca = dentition.teeth[a].to_world(dentition.teeth[a].crown_center, target[a])
        cb = dentition.teeth[b].to_world(dentition.teeth[b].crown_center, target[b])
        u = (cb - ca) / np.linalg.norm(cb - ca)
        if np.abs(u - r.direction).max() > 1e-6:
            verdict.violations.append(Violation(1, "ipr", f"{name}: its direction is not from {a}'s crown centre to {b}'s at the target"))
            continue
        overlap = penetration_along(bodies.queries, bodies.index[a], target[a], bodies.index[b], target[b], u)
        if r.amount_mm > overlap + RESOLUTION_MM:
            verdict.violations.append(Violation(1, "ipr", f"{name}: more than the teeth overlap at the target ({overlap:.3f} mm)"))

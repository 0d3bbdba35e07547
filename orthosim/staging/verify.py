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
     From stage 1 on the teeth are the reduced ones where IPR is planned (`staging.reduction`: the
     recorded reduction cut off each contact side), the teeth the certificate and the models hold;
  5. the last stage is the case's target (every pose within `TARGET_ATOL_MM`);
  6. each recorded interproximal reduction is the one the case needs: the two teeth are arch
     neighbours, the direction is the one between their crown centres at the target, and the
     amount is the planner's own (`ipr.reduction_for` at the target), within the certificate's
     IPR tolerance: an inflated reduction would cut a real contact away;
  7. certificate.json: every figure it claims (per transition and pair the least clearance, its
     lower bound and time; per tooth the increments and the largest use of a limit; the IPR per
     contact; the summary; the case's SHA-256) equals its recomputation from the stages within the
     tolerances it states (`staging.certcheck`); a missing or wrongly typed field is refused (exit 2);
  8. the stage models, when models/ is there: each file holds the teeth of its stage as stages.json
     poses them, reduced from stage 1 on (`staging.modelcheck`).
A damaged or inconsistent folder raises StagingFolderError (exit 2); violations are returned.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from orthosim.staging.certificate import LIMIT_SLACK, TOLERANCES, certificate_record, certify_stages, staged_bodies
from orthosim.staging.limits import StageLimits
from orthosim.staging.stagesfile import StagingFolderError, WrittenStaging, read_stages
from orthosim.staging.sweep import ToothBodies, first_contact_on_grid
from orthosim.exchange.target import COMPONENTS, UNITS, movement_components

STEP_MM = 0.005  # the most any vertex moves relative to another tooth between two samples
TARGET_ATOL_MM = 1e-6  # a written pose within this of the case's own (matrix entries, mm)


@dataclass(frozen=True)
class Violation:
    stage: int  # the stage reached by the failing transition (0: the start itself)
    kind: str  # "limit", "contact", "target", "ipr", "certificate" or "models"
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
    certified_figures: int = 0  # figures of certificate.json held to their recomputation
    model_files: int = 0  # stage models checked against stages.json
    seconds: float = 0.0

    @property
    def holds(self) -> bool:
        return not self.violations

    def line(self) -> str:
        if self.holds:
            return (f"{self.folder}: all {self.stages} stages of {self.teeth} teeth hold: within the limits "
                    f"({self.limits.text()}) and free of contact (sampled to {self.step_mm:g} mm, "
                    f"{self.pairs_checked} pair-stages, {self.fcl_queries} FCL queries), certificate.json's "
                    f"{self.certified_figures} figures recomputed"
                    + (f", {self.model_files} stage models match stages.json" if self.model_files else "")
                    + f" ({self.seconds:.1f} s)")
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
                   step_mm: float = STEP_MM, folder: Path | None = None, certificate: bool = True) -> Verdict:
    """Check a read staging against the case's teeth, start and target (see the module docstring);
    certificate: also hold certificate.json's figures to their recomputation (and the stage models
    to stages.json, where written)."""
    began = time.perf_counter()
    limits = limits or written.limits
    folder = Path(folder or written.path.parent)
    verdict = Verdict(folder, written.n_stages, len(written.teeth), limits, step_mm)
    bodies = staged_bodies(dentition, written.teeth, written.ipr, target)
    P = written.poses
    _contacts(verdict, bodies[0], 0, P[0], P[0], step_mm)
    for k in range(1, written.n_stages + 1):
        _limits(verdict, dentition, start, written.teeth, k, P[k - 1], P[k], limits)
        _contacts(verdict, bodies[1], k, P[k - 1], P[k], step_mm)
    _ipr(verdict, written, dentition, target)
    last = written.n_stages
    for n in written.teeth:
        off = float(np.abs(P[last][n] - target[n]).max())
        if off > TARGET_ATOL_MM:
            verdict.violations.append(Violation(last, "target", f"tooth {n} ends off its target (pose entries differ by up to {off:.4g})"))
    if certificate:
        _certificate(verdict, folder, written, dentition, start, target, bodies)
        _models(verdict, folder, written, dentition, target)
    verdict.violations.sort(key=lambda v: v.stage)  # stable: in a stage, limits, contacts, target, IPR, certificate, models
    verdict.seconds = time.perf_counter() - began
    return verdict


def _certificate(verdict: Verdict, folder: Path, written: WrittenStaging, dentition, start, target, bodies) -> None:
    from orthosim.staging.certcheck import compare, read_certificate

    path, claimed = read_certificate(folder)
    cert = certify_stages(dentition, written.teeth, start, written.poses, written.limits, written.ipr, target, bodies)
    recomputed = certificate_record(cert, written.case_file, written.case_sha256)
    disagreements, verdict.certified_figures = compare(path, claimed, recomputed)
    verdict.violations += [Violation(d.stage, "certificate", d.text()) for d in disagreements]


def _models(verdict: Verdict, folder: Path, written: WrittenStaging, dentition, target) -> None:
    from orthosim.staging.modelcheck import check_stage_models

    problems, verdict.model_files = check_stage_models(folder / "models", written, dentition, target)
    verdict.violations += [Violation(stage, "models", text) for stage, text in problems]


def _limits(verdict: Verdict, dentition, start, teeth, k: int, P0: dict, P1: dict, limits: StageLimits) -> None:
    lim = limits.array()
    for n in teeth:
        c = movement_components(dentition.teeth[n], start[n], P0[n], P1[n])
        over = np.flatnonzero(np.abs(c) > lim + LIMIT_SLACK)
        for j in over:
            name, unit = COMPONENTS[j], UNITS[COMPONENTS[j]]
            verdict.violations.append(Violation(k, "limit", f"tooth {n} moves {c[j]:+.4f} {unit} {name}, "
                                                f"beyond the limit of {lim[j]:g} {unit} per stage"))


def _contacts(verdict: Verdict, bodies: ToothBodies, k: int, P0: dict, P1: dict, step_mm: float) -> None:
    for a, b in bodies.near_pairs(P0, P1, 0.0):
        motion = bodies.motion(a, b, P0, P1)
        t = first_contact_on_grid(motion, step_mm)
        verdict.pairs_checked += 1
        verdict.fcl_queries += motion.queries
        if t is not None:
            when = "at the start" if k == 0 else f"at {100 * t:.1f} % of the motion from stage {k - 1}"
            verdict.violations.append(Violation(k, "contact", f"teeth {a} and {b} intersect {when}"))


def _ipr(verdict: Verdict, written: WrittenStaging, dentition, target: dict) -> None:
    from orthosim.collision.broadphase import arch_neighbour_pairs
    from orthosim.staging.ipr import reduction_for

    neighbours = {tuple(sorted(p)) for p in arch_neighbour_pairs(written.teeth)}
    for r in written.ipr:
        a, b = r.a, r.b
        name = f"IPR of {a}/{b} ({r.amount_mm:.4f} mm)"
        if (min(a, b), max(a, b)) not in neighbours:
            verdict.violations.append(Violation(1, "ipr", f"{name}: the two teeth are not arch neighbours"))
            continue
        needed = reduction_for(dentition, a, b, target[a], target[b])
        if np.abs(needed.direction - r.direction).max() > 1e-6:
            verdict.violations.append(Violation(1, "ipr", f"{name}: its direction is not from {a}'s crown centre to {b}'s at the target"))
        elif abs(needed.amount_mm - r.amount_mm) > TOLERANCES["ipr_mm"]:
            verdict.violations.append(Violation(1, "ipr", f"{name}: stages.json records {r.amount_mm:.4f} mm, "
                                                f"the case needs {needed.amount_mm:.4f} mm at the target (tolerance {TOLERANCES['ipr_mm']:g})"))

"""A case's set-up split into aligner stages, in memory: what `orthosim.stage` gives.

    staging = orthosim.stage(orthosim.load_case("cases/staging_lower_incisor_crowding.toml"))
    staging.plan.n_stages            # StagingPlan: per-stage poses, IPR, the lower bound
    staging.verify().holds           # the plan checked as `orthosim stage verify` checks written files
    staging.write("out/staging")     # stages.json, staging.csv, ipr.csv, movement.csv, certificate.json, models/

The planner, certificate and verifier are `orthosim.staging`'s; the drawn parts (animation, charts,
page) are `orthosim_render`'s, as for `orthosim stage`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from orthosim.exchange.case import Case
from orthosim.staging.caseplan import StagingRun, plan_case
from orthosim.staging.limits import StageLimits
from orthosim.staging.plan import StagingPlan
from orthosim.staging.verify import Verdict


@dataclass(frozen=True, eq=False)
class Staging:
    """A planned staging: the case, its teeth (`dentition`) and the `plan` (stage 0 = start; stage k:
    where aligner k takes the teeth; poses {FDI: (4, 4) tooth frame -> arch frame, mm})."""

    run: StagingRun

    @property
    def case(self) -> Case:
        return self.run.case

    @property
    def plan(self) -> StagingPlan:
        return self.run.plan

    def stage_poses(self) -> list[dict]:
        """Per stage 0..n_stages: {FDI: (4, 4) pose, mm} of every staged tooth."""
        return [self.plan.poses(k) for k in range(self.plan.n_stages + 1)]

    def verify(self, limits: StageLimits | None = None) -> Verdict:
        """The plan checked in memory as `orthosim stage verify` checks a written one: every stage
        within the per-stage limits (mm, degrees; default: the plan's), no contact along any
        stage's motion (dense exact sampling), the last stage on the target. `.holds`: all pass;
        `.violations`: what does not; `.line()`: one line saying so."""
        from orthosim.staging.stagesfile import WrittenStaging
        from orthosim.staging.verify import verify_staging

        plan, case = self.plan, self.case
        written = WrittenStaging(case.path, case.path, None, plan.limits, plan.teeth, tuple(self.stage_poses()),
                                 plan.progress, plan.ipr)
        start, target = case.staging.poses(self.run.dentition)
        # the plan itself: no file of it exists yet, so no certificate or stage model to hold to it
        return verify_staging(written, self.run.dentition, start, target, limits, folder=Path(f"{case.name} (in memory)"),
                              certificate=False)

    def write(self, folder: str | Path, models: str | None = "stl") -> Path:
        """Write what the core makes into `folder` (a private folder swapped in whole at the end):
        stages.json, staging.csv, ipr.csv, movement.csv, certificate.json and, unless `models` is
        None, every stage's arches as models/stage_NN_upper.FMT and _lower (FMT "stl", "ply" or
        "glb"; mm, case frame). Returns the folder."""
        from orthosim.runtime.outputfolder import output_folder
        from orthosim.staging.certificate import certificate_record, certify
        from orthosim.staging.chart import write_outputs
        from orthosim.staging.models import export_stage_models
        from orthosim.storage.atomic import write_json
        from orthosim.storage.checksums import file_sha256

        folder = Path(folder)
        with output_folder(folder) as private:
            write_outputs(self.plan, private, self.case.path)
            record = certificate_record(certify(self.plan, self.run.dentition), Path(self.case.path).resolve(),
                                        file_sha256(self.case.path))
            write_json(private / "certificate.json", record)
            if models:
                from orthosim.staging.reduction import reduced_meshes

                plan, teeth = self.plan, self.run.dentition.teeth
                reduced = reduced_meshes({n: teeth[n].mesh for n in plan.teeth}, plan.ipr, plan.target)
                export_stage_models(self.run.dentition, self.stage_poses(), private / "models", models,
                                    teeth=plan.teeth, reduced=reduced)
        return folder


def stage(case: Case | str | Path, limits: StageLimits | None = None) -> Staging:
    """Plan the aligner staging of a case's set-up (its [target] section): stages within the
    per-stage `limits` (mm, degrees; default `StageLimits()`), free of contact along every stage's
    motion. `case`: a `Case` or a case file's path; `OrthosimError` when it has no [target]."""
    return Staging(plan_case(case.path if isinstance(case, Case) else Path(case), limits or StageLimits()))

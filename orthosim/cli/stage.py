"""`orthosim stage`: aligner staging of a case's set-up (`stage CASE --out DIR`, the `plan` command)
and the re-check of a written staging from its files (`stage verify DIR`)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from orthosim.cli.options import gl_option, parse_size, select_gl


class _DefaultCommandGroup(click.Group):
    """A group whose first argument, when it names none of its commands, goes to `default`:
    `orthosim stage CASE --out DIR` plans, `orthosim stage verify DIR` checks."""

    default = "plan"

    def parse_args(self, ctx, args):
        if args and args[0] not in self.commands and args[0] not in ctx.help_option_names:
            args = [self.default, *args]
        return super().parse_args(ctx, args)


@click.group(cls=_DefaultCommandGroup)
def stage() -> None:
    """Aligner staging: plan a case's set-up, or re-check a written staging.

    `orthosim stage CASE --out DIR` plans (the `plan` command); `orthosim stage verify DIR` checks."""


@stage.command("plan")
@click.argument("case", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True, help="Output folder.")
@click.option("--limits", default=None,
              help="Per-stage limits (mm, degrees); any subset of mesial=0.25,buccal=0.25,extrusion=0.15,tip=2,torque=1,rotation=2.")
@click.option("--no-render", is_flag=True, help="No animation and no 3D pictures (the charts and the page are still written).")
@click.option("--size", default="640x480", show_default=True, callback=parse_size, help="Image size WIDTHxHEIGHT.")
@click.option("--view", "views", multiple=True, help="Camera preset (repeatable). Default: frontal and mandibular_occlusal.")
@click.option("--frames-per-stage", default=6, show_default=True, type=click.IntRange(1, 120), help="Animation frames per stage.")
@click.option("--gif", is_flag=True, help="Also write animation.gif.")
@click.option("--export", "export", type=click.Choice(["stl", "ply", "glb"]), default=None,
              help="Also write every stage's arches for the lab: models/stage_NN_upper.FMT and _lower (mm, case frame).")
@gl_option
def stage_plan(case: Path, out_dir: Path, limits: str | None, no_render: bool, size, views, frames_per_stage: int,
               gif: bool, export: str | None, gl: str | None) -> None:
    """Split a case's set-up ([target]) into aligner stages: within per-stage limits, free of contact.

    Writes stages.json, staging.csv, ipr.csv, movement.csv, certificate.json, charts/, index.html
    (and the animation, and with --export the stage models) into a private folder that replaces
    --out whole at the end."""
    from orthosim.runtime.outputfolder import output_folder
    from orthosim.staging.chart import summary_line
    from orthosim.staging.limits import StageLimits

    parsed = StageLimits.parse(limits)
    if not no_render:
        select_gl(gl)
        from orthosim_render.cameras import check_view

        views = [check_view(v) for v in views or ("frontal", "mandibular_occlusal")]
    with output_folder(out_dir) as private:
        run, cert = _stage_into(case, private, parsed, None if no_render else views, size, frames_per_stage, gif, export)
    click.echo(f"{summary_line(run.plan, run.case.name)}; certificate: "
               f"{'within limits' if cert['within_limits'] else 'LIMITS EXCEEDED'}, "
               f"{'contact-free' if cert['contact_free'] else 'CONTACT'} -> {out_dir}/index.html")


def _stage_into(case: Path, out: Path, limits, views, size, frames_per_stage: int, gif: bool, export: str | None):
    """Plan and write one staging into the (private) folder `out`; returns (run, certificate summary)."""
    from orthosim.runtime.runfolder import write_run_record
    from orthosim.storage.checksums import file_sha256
    from orthosim.staging.certificate import certificate_record, certify
    from orthosim.staging.chart import write_outputs
    from orthosim.staging.caseplan import plan_case
    from orthosim.storage.atomic import write_json
    from orthosim_render.staging_page import write_staging_page

    run = plan_case(case, limits)
    extra = {"kind": "staging", "stages": run.plan.n_stages, "lower_bound": run.plan.lower_bound,
             "ipr_total_mm": run.plan.ipr_total_mm, "planning_s": run.plan.planning_s}
    if views is not None:
        from orthosim_render.staging import render_staging

        extra["animation"] = render_staging(run, out, views=views, size=size, frames_per_stage=frames_per_stage, gif=gif)
        from orthosim_render.viewer_page import write_staging_viewer

        extra["scene"] = {k: p.name for k, p in write_staging_viewer(run, out).items()}
    write_outputs(run.plan, out, case)
    record = certificate_record(certify(run.plan, run.dentition), Path(case).resolve(), file_sha256(case))
    write_json(out / "certificate.json", record)
    if export:
        from orthosim.staging.models import export_stage_models
        from orthosim.staging.reduction import reduced_meshes

        plan = run.plan
        reduced = reduced_meshes({n: run.dentition.teeth[n].mesh for n in plan.teeth}, plan.ipr, plan.target)
        export_stage_models(run.dentition, [plan.poses(k) for k in range(plan.n_stages + 1)], out / "models", export,
                            teeth=plan.teeth, reduced=reduced)
    write_staging_page(run, record, out, pictures=views is not None, viewer=views is not None)
    write_run_record(out, case, "continuous", extra)  # last: marks the folder finished
    return run, record["summary"]


@stage.command("verify")
@click.argument("folder", type=click.Path(path_type=Path))
@click.option("--case", "case", type=click.Path(path_type=Path), default=None,
              help="The case it was staged from (default: the one stages.json names).")
@click.option("--limits", default=None, help="Check against these limits instead of the ones the staging was planned with.")
@click.option("--all", "show_all", is_flag=True, help="Print every violation, one line each, not only the first.")
def stage_verify(folder: Path, case: Path | None, limits: str | None, show_all: bool) -> None:
    """Re-check a written staging from its files alone: limits per component, no contact along any
    stage's motion (dense exact sampling), the IPR the case needs, every figure certificate.json
    claims against its recomputation, and the stage models against stages.json. Exit 0 when all
    hold, 1 naming the first violation or disagreement, 2 for a damaged or incomplete folder."""
    from orthosim.staging.limits import StageLimits
    from orthosim.staging.verify import load_for_verify, verify_staging

    parsed = StageLimits.parse(limits) if limits else None
    written, dent, start, target = load_for_verify(folder, case)
    verdict = verify_staging(written, dent, start, target, parsed, folder=folder)
    click.echo(verdict.line())
    for v in verdict.violations[1:] if show_all else ():
        click.echo(f"{folder}: stage {v.stage}: {v.kind}: {v.text}")
    if not verdict.holds:
        sys.exit(1)

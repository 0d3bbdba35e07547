"""The `orthosim` command line: the composition root that wires the core and the renderer.

This is the one module of `orthosim` allowed to import `render`, and it does so lazily inside the
commands that draw, so `orthosim --help` and the simulation-only commands never load OpenGL.
Every error a user can cause is an `OrthosimError`; `main` prints it as one line on stderr and exits
with its code (2), never with a traceback.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import click

from orthosim import __version__
from orthosim.collision.detectors import DETECTORS, PAPER_DETECTORS
from orthosim.errors import OrthosimError
from orthosim.runtime.run import MIN_ANIMATION_S, RunOptions

DEMO_VIEWS = ("right_buccal", "maxillary_occlusal")
GL_CHOICES = ("auto", "egl", "osmesa")  # orthosim_render.glbackend.CHOICES (not imported here: --help stays light)


def _size(ctx, param, value: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in value.lower().split("x"))
        if not (16 <= w <= 8192 and 16 <= h <= 8192):
            raise ValueError
    except ValueError:
        raise click.BadParameter(f"{value!r} is not WIDTHxHEIGHT in pixels (16 to 8192), e.g. 640x480") from None
    return w, h


def _steps(ctx, param, value: str | None) -> tuple[int, ...] | None:
    if value is None:
        return None
    try:
        steps = tuple(int(v) for v in value.split(","))
        if not steps or min(steps) < 0:
            raise ValueError
    except ValueError:
        raise click.BadParameter(f"{value!r} is not a comma-separated list of step numbers, e.g. 0,60,120") from None
    return steps


def _views(ctx, param, value: tuple[str, ...]) -> tuple[str, ...]:
    """Camera presets checked while the options are read: a bad --view stops before any work."""
    from orthosim_render.cameras import check_view  # numpy only, no OpenGL

    return tuple(check_view(v) for v in value)


class _LazyGroup(click.Group):
    """A command group whose heavier subgroups are imported only when they run.

    Importing the sphere-tree and collision commands pulls trimesh, scipy and FCL (seconds on a
    loaded machine); `orthosim --help` and `orthosim check` should not pay for that.
    """

    lazy = {  # name -> (module, attribute, one-line help shown by --help)
        "spheretree": ("orthosim.spheretree.commands", "spheretree", "Build, export and evaluate sphere trees."),
        "collide": ("orthosim.collision.commands", "collide", "Collision accuracy studies, timings and single queries."),
        "batch": ("orthosim.batch.commands", "batch", "Many runs and parameter sweeps, on every core or a Dask cluster."),
        "evidence": ("orthosim_render.evidence_page", "evidence_command", "Run the clinical evidence table; write a page."),
        "cases": ("orthosim.exchange.shippedcases", "cases", "List the shipped case files, or copy one to start from."),
    }

    # commands that measurement (orthosim_bench, outside the product) adds to a lazy group
    extra = {"collide": (("orthosim_bench.collision", "bench_command"),)}

    def list_commands(self, ctx):
        return sorted([*super().list_commands(ctx), *self.lazy])

    def get_command(self, ctx, name):
        if name in self.lazy:
            module, attr, _ = self.lazy[name]
            import importlib

            group = getattr(importlib.import_module(module), attr)
            for extra_module, extra_attr in self.extra.get(name, ()):
                command = getattr(importlib.import_module(extra_module), extra_attr)
                group.add_command(command, command.name)
            return group
        return super().get_command(ctx, name)

    def format_commands(self, ctx, formatter):
        rows = []
        for name in self.list_commands(ctx):
            if name in self.lazy:
                rows.append((name, self.lazy[name][2]))
            else:
                cmd = super().get_command(ctx, name)
                if cmd is not None and not cmd.hidden:
                    rows.append((name, cmd.get_short_help_str(limit=formatter.width - 6 - len(name))))
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=_LazyGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="orthosim")
def main() -> None:
    """Headless orthodontic treatment simulator: tooth movement, collision detection, offscreen rendering."""


def gl_option(f):
    """`--gl auto|egl|osmesa`: the offscreen OpenGL backend of a command that draws (see select_gl)."""
    return click.option("--gl", type=click.Choice(GL_CHOICES), default=None,
                        help="Offscreen OpenGL: auto (an EGL GPU, else EGL on Mesa's software device, else OSMesa), "
                             "egl or osmesa. Default: $ORTHOSIM_GL, else auto.")(f)


def select_gl(gl: str | None) -> str:
    """Choose this process's offscreen OpenGL backend now, before any work (a one-line error, exit 2,
    when it cannot start); `gl` None keeps ORTHOSIM_GL or auto. Children inherit the choice."""
    import os

    from orthosim_render.glbackend import ENV, select

    if gl:
        os.environ[ENV] = gl
    return select().label


def render_options(f):
    """Options shared by the commands that draw frames."""
    f = gl_option(f)
    f = click.option("--no-render", is_flag=True, help="Run the simulation alone; write no images.")(f)
    f = click.option("--size", default="640x480", show_default=True, callback=_size, help="Image size WIDTHxHEIGHT.")(f)
    f = click.option("--view", "views", multiple=True, callback=_views,
                     help="Camera preset (repeatable): frontal, right_buccal, left_buccal, maxillary_occlusal, "
                          "mandibular_occlusal. Default: frontal.")(f)
    f = click.option("--gif", is_flag=True, help="Also write animation.gif (at the frame's size).")(f)
    f = click.option("--alpha", is_flag=True, help="PNG frames with a transparent background.")(f)
    f = click.option("--hide-roots", is_flag=True, help="Draw crowns only.")(f)
    f = click.option("--frames-per-step", default=None, type=click.IntRange(1, 120),
                     help="Animation frames per simulation step (positions interpolated between steps). "
                          "Default: enough for --seconds.")(f)
    f = click.option("--seconds", default=None, type=float,
                     help=f"Length of the animation in seconds (default: at least {MIN_ANIMATION_S:g}).")(f)
    f = click.option("--fps", default=30, show_default=True, type=int, help="Animation frames per second.")(f)
    f = click.option("--split-views", is_flag=True,
                     help="Also write each view's own PNG per frame (frames/<view>/NNNNN.png) besides the tiled frame.")(f)
    f = click.option("--export-scene", type=click.Choice(["glb", "ply"]), default=None,
                     help="Write the posed teeth at --export-steps for Blender, MeshLab or Open3D (scene/).")(f)
    f = click.option("--export-steps", default=None, callback=_steps,
                     help="Steps to export with --export-scene, comma-separated (default: first and last).")(f)
    f = click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors and warnings.")(f)
    f = click.option("-v", "--verbose", is_flag=True,
                     help="Print each phase with its time even when the output is not a terminal.")(f)
    f = click.option("--labels", is_flag=True, help="Write each crown's FDI number on the frames.")(f)
    f = click.option("--no-overlay", is_flag=True,
                     help="Bare frames: no case name, detector, day counter or colour legend drawn on them.")(f)
    f = click.option("--contact-faces", is_flag=True,
                     help="Also colour the tooth surface inside each contact sphere (as in the paper's Figure 7).")(f)
    f = click.option("--contact-faces-exact", is_flag=True,
                     help="Colour only the triangles within 0.05 mm of the tooth they touch (exact), not all inside the spheres.")(f)
    return f


@main.command()
@click.argument("case", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Output folder (default: out/<case name>).")
@click.option("--detector", type=click.Choice(DETECTORS), default=None,
              help="Collision detector (default: the case's).")
@render_options
def run(case: Path, out_dir: Path | None, detector: str | None, **render_opts) -> None:
    """Run one case: simulate, detect, write frames and metrics."""
    _run_case(case, out_dir or Path("out") / case.stem, run_options(detector, render_opts))


@main.command()
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("out/demo"), show_default=True,
              help="Output folder.")
@render_options
def demo(out_dir: Path, **render_opts) -> None:
    """Run the paper's case 1 (cases/case1_...) into out/demo/."""
    from orthosim.exchange.case import DEFAULT_CASE

    render_opts["views"] = render_opts.get("views") or DEMO_VIEWS
    _run_case(DEFAULT_CASE, out_dir, run_options(None, render_opts))


@main.command()
@click.argument("case", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Output folder (default: out/<case name>-occlusion).")
@click.option("--size", default="800x600", show_default=True, callback=_size, help="Image size WIDTHxHEIGHT.")
@click.option("--no-render", is_flag=True, help="Write occlusion.json only.")
@gl_option
def occlusion(case: Path, out_dir: Path | None, size, no_render: bool, gl: str | None) -> None:
    """Occlusal measures and contacts per pair of a case's model at rest; contact areas drawn (Figure 7)."""
    if not no_render:
        select_gl(gl)
    from orthosim.storage.atomic import write_json
    from orthosim.exchange.case import load_case
    from orthosim.analysis.occlusalcontacts import occlusal_contacts, occlusion_record

    dent = load_case(case).build_dentition()
    out_dir = out_dir or Path("out") / f"{case.stem}-occlusion"
    contacts = occlusal_contacts(dent)
    record = occlusion_record(dent, contacts)
    write_json(out_dir / "occlusion.json", record)
    if not no_render:
        from orthosim_render.occlusion_figure import write_occlusal_contacts

        write_occlusal_contacts(dent, contacts, out_dir, size)
    click.echo(f"{len(record['contacts'])} facing pairs in contact; overjet {record.get('overjet_mm', float('nan')):.2f} mm, "
               f"overbite {record.get('overbite_mm', float('nan')):.2f} mm -> {out_dir}")


@main.command()
@click.argument("cases", nargs=-1, required=True, type=click.Path(path_type=Path))
def check(cases: tuple[Path, ...]) -> None:
    """Validate case files without running them."""
    from orthosim.exchange.case import load_case

    for path in cases:
        case = load_case(path)
        click.echo(f"{path}: ok ({case.name}; {len(case.loads)} loads, {len(case.extractions)} extractions, {case.steps} steps)")


@main.command()
@click.option("--case", "case", type=click.Path(path_type=Path), default=None,
              help="Case to measure (default: cases/case1_first_premolar_extraction.toml, the paper's case 1).")
@click.option("--out", "out_file", type=click.Path(path_type=Path), required=True, help="Where to write the JSON record.")
@click.option("--size", default="640x480", show_default=True, callback=_size, help="Image size WIDTHxHEIGHT.")
@click.option("--frames", default=300, show_default=True, type=click.IntRange(1), help="Measured frames per figure (after warm-up).")
@click.option("--warmup", default=30, show_default=True, type=click.IntRange(0), help="Frames run before measuring.")
@click.option("--markers", default=2000, show_default=True, type=click.IntRange(0), help="Contact markers drawn per frame.")
@click.option("--memory-frames", default=2000, show_default=True, type=click.IntRange(0),
              help="Length of the run whose memory is recorded.")
@click.option("--no-png", is_flag=True, help="End to end without writing PNG frames (MP4 only).")
@click.option("--no-simulate", is_flag=True, help="Skip the movement simulation (end to end on synthetic motion).")
@click.option("--no-tree-build", is_flag=True, help="Skip timing the sphere-tree build from nothing.")
@click.option("--no-startup", is_flag=True, help="Skip timing `orthosim run` from launch to its first step.")
@click.option("--no-staging", is_flag=True, help="Skip timing the aligner staging planner (shipped staging cases, 28-tooth set-up).")
@click.option("--no-batch", is_flag=True, help="Skip `orthosim batch` animations per minute with 1 and 2 workers (minutes).")
@click.option("--no-report", is_flag=True, help="Skip timing `orthosim report` of the paper's three cases.")
@click.option("--no-scan", is_flag=True, help="Skip a 300k-triangle labelled arch scan made ready to simulate, cold and warm.")
@click.option("--no-memory", is_flag=True, help="Skip the peak memory of a 10,000-step run and a 2,000-frame render (minutes).")
@click.option("--report-runs", type=click.Path(path_type=Path), default=Path("out/bench/report-runs"), show_default=True,
              help="Where the report's runs are made once and kept for later benches.")
@click.option("--step-days", default=2.0, show_default=True, type=click.FloatRange(min=0.01),
              help="Simulation step for the bench, so the case's teeth keep moving through the measured frames.")
@click.option("--labels", is_flag=True, help="Also time the label pass of semantic goldens against a golden's render.")
@click.option("--closure", "closure_case", type=click.Path(path_type=Path), default=None,
              help="Also time this (real-jaw) case's step with and without the bite's closure.")
@click.option("--no-backends", is_flag=True,
              help="Skip render_backends: render frames/s through each offscreen backend found, one process each.")
@gl_option
def bench(case: Path | None, out_file: Path, size, frames: int, warmup: int, markers: int, memory_frames: int,
          no_png: bool, no_simulate: bool, step_days: float, no_tree_build: bool, no_startup: bool,
          no_staging: bool, no_batch: bool, no_report: bool, report_runs: Path, no_memory: bool, labels: bool,
          closure_case: Path | None, no_scan: bool, no_backends: bool, gl: str | None) -> None:
    """Measure throughput against the 40 fps target; write JSON.

    Simulation, each collision detector, rendering alone and end to end, in one run on one case.
    """
    select_gl(gl)
    from orthosim_bench.render import run_bench

    from orthosim.storage.atomic import write_json

    record = run_bench(case, frames=frames, warmup=warmup, size=size, n_markers=markers,
                       memory_frames=memory_frames, png=not no_png, simulate=not no_simulate,
                       step_days=step_days, tree_build=not no_tree_build, startup=not no_startup,
                       staging=not no_staging, batch=not no_batch, report=not no_report, report_runs=report_runs,
                       memory=not no_memory, run_case=run_case, labels=labels, scan=not no_scan)
    if closure_case is not None:
        from orthosim_bench.closure import closure_timings

        record["closure"] = closure_timings(closure_case)
        click.echo(f"closure: {record['closure']['closure_over_rest_of_step']:.2f} of the rest of the step (target <= 1)")
    if not no_backends:  # after run_bench closed its renderer: each backend draws in a process of its own
        from orthosim.exchange.case import DEFAULT_CASE
        from orthosim_bench.backends import render_backends

        record["render_backends"] = render_backends(case or DEFAULT_CASE, size, frames=max(30, frames // 2),
                                                    warmup=min(warmup, 20), n_markers=markers)
    write_json(out_file, record)
    rb = record.get("render_backends")
    if rb:
        click.echo("render fps per backend: " + ", ".join(f"{k} {v['fps']:.1f}" for k, v in rb["fps"].items())
                   + "".join(f"; {k} {v:.2f}" for k, v in rb.get("ratios", {}).items()))
    fps = record["fps"]
    shown = ", ".join(f"{k} {v:.1f}" if v is not None else f"{k} pending" for k, v in fps.items())
    click.echo(f"fps (median, target {record['target_fps']}): {shown} -> {out_file}")
    if record.get("startup"):
        st = record["startup"]
        click.echo(f"start-up: first step {st['startup_s']:.2f} s after launching `orthosim run` (target {st['target_s']:.0f} s; "
                   f"bare python {st['python_start_s']:.2f} s, load {st['load_avg_1min']:.1f})")
    trees = record.get("spheretree_build")
    if trees:
        click.echo(f"sphere trees of {trees['teeth']} teeth built in {trees['build_s']:.1f} s on {trees['workers']} cores "
                   f"(target {trees['target_s']:.0f} s; one process {trees['build_s_one_process']:.1f} s), "
                   f"loaded in {1000 * trees['load_s']:.0f} ms")
    if record.get("label_pass"):
        lp = record["label_pass"]
        click.echo(f"label pass: at most {100 * lp['worst_ratio']:.0f} % of a golden's render time "
                   f"(target {100 * lp['target_ratio']:.0f} %; draw alone {100 * lp['worst_ratio_draw_alone']:.0f} %)")
    staged = record.get("staging")
    if staged:
        big = staged["setup_28_teeth"]
        click.echo(f"staging: {big['teeth']} teeth, {big['stages']} stages planned in {big['staging_s']:.1f} s "
                   f"(target {big['target_s']:.0f} s); " + ", ".join(f"{k} {v['staging_s']:.1f} s" for k, v in staged["cases"].items()))
        v = staged["verify_28_teeth"]
        click.echo(f"stage verify: {v['stages']} stages of {v['teeth']} teeth checked in {v['verify_s']:.1f} s "
                   f"(target {v['target_s']:.0f} s; x{v['verify_to_planning']:.2f} its planning time)")
    if record.get("report"):
        r = record["report"]
        click.echo(f"report of {r['cases']} cases x 3 detectors from existing runs: {r['report_s']:.1f} s "
                   f"(target {r['target_s']:.0f} s), PDF {r['pdf_s']:.1f} s")
    b = record.get("batch")
    if b:
        click.echo(f"batch: {b['per_minute_1_worker']:.2f} animations/min with 1 worker, {b['per_minute_2_workers']:.2f} "
                   f"with 2 (x{b['ratio_2_to_1']:.2f}, target x{b['target_ratio_2_to_1']})")
    m = record.get("memory")
    if m:
        click.echo(f"peak private memory: {m['run_10k_steps_no_render_mb']:.0f} MB for {m['run_no_render']['steps']} steps without "
                   f"rendering, {m['render_2000_frames_mb']:.0f} MB for {m['render']['frames']} frames (target {m['target_mb']:.0f} MB)")



class _DefaultCommandGroup(click.Group):
    """A group whose first argument, when it names none of its commands, goes to `default`:
    `orthosim stage CASE --out DIR` plans, `orthosim stage verify DIR` checks."""

    default = "plan"

    def parse_args(self, ctx, args):
        if args and args[0] not in self.commands and args[0] not in ctx.help_option_names:
            args = [self.default, *args]
        return super().parse_args(ctx, args)


@main.group(cls=_DefaultCommandGroup)
def stage() -> None:
    """Aligner staging: plan a case's set-up, or re-check a written staging.

    `orthosim stage CASE --out DIR` plans (the `plan` command); `orthosim stage verify DIR` checks."""


@stage.command("plan")
@click.argument("case", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True, help="Output folder.")
@click.option("--limits", default=None,
              help="Per-stage limits (mm, degrees); any subset of mesial=0.25,buccal=0.25,extrusion=0.15,tip=2,torque=1,rotation=2.")
@click.option("--no-render", is_flag=True, help="No animation and no 3D pictures (the charts and the page are still written).")
@click.option("--size", default="640x480", show_default=True, callback=_size, help="Image size WIDTHxHEIGHT.")
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
    from orthosim.runtime.runfolder import file_sha256, write_run_record
    from orthosim.staging.certificate import certificate_record, certify
    from orthosim.staging.chart import write_outputs
    from orthosim.staging.commands import plan_case
    from orthosim.storage.atomic import write_json
    from orthosim_render.staging_page import write_staging_page

    run = plan_case(case, limits)
    extra = {"kind": "staging", "stages": run.plan.n_stages, "lower_bound": run.plan.lower_bound,
             "ipr_total_mm": run.plan.ipr_total_mm, "planning_s": run.plan.planning_s}
    if views is not None:
        from orthosim_render.staging import render_staging

        extra["animation"] = render_staging(run, out, views=views, size=size, frames_per_stage=frames_per_stage, gif=gif)
    write_outputs(run.plan, out, case)
    record = certificate_record(certify(run.plan, run.dentition), Path(case).resolve(), file_sha256(case))
    write_json(out / "certificate.json", record)
    if export:
        from orthosim.staging.models import export_stage_models

        plan = run.plan
        export_stage_models(run.dentition, [plan.poses(k) for k in range(plan.n_stages + 1)], out / "models", export)
    write_staging_page(run, record, out, pictures=views is not None)
    write_run_record(out, case, "continuous", extra)  # last: marks the folder finished
    return run, record["summary"]


@stage.command("verify")
@click.argument("folder", type=click.Path(path_type=Path))
@click.option("--case", "case", type=click.Path(path_type=Path), default=None,
              help="The case it was staged from (default: the one stages.json names).")
@click.option("--limits", default=None, help="Check against these limits instead of the ones the staging was planned with.")
@click.option("--all", "show_all", is_flag=True, help="Print every violation, one line each, not only the first.")
def stage_verify(folder: Path, case: Path | None, limits: str | None, show_all: bool) -> None:
    """Re-check a written staging from its files alone: limits per component, and no contact along
    any stage's motion (dense exact sampling). Exit 0 when every stage holds, 1 naming the first violation."""
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


@main.command()
@click.argument("golden", type=click.Path(path_type=Path))
@click.argument("candidate", type=click.Path(path_type=Path))
@click.option("--diff", "diff_path", type=click.Path(path_type=Path), default=None,
              help="Write the diff image here (default: CANDIDATE.diff.png, only when they differ).")
@click.option("--max-level", default=3, show_default=True, type=int,
              help="Tolerance mode: levels (0-255) a channel may be off before its pixel counts as different.")
@click.option("--max-fraction", default=0.001, show_default=True, type=float,
              help="Tolerance mode: fraction of pixels allowed to differ (0.001 = 0.1 %).")
@click.option("--update", is_flag=True, help="Make the candidate the golden: rewrite GOLDEN.png and GOLDEN.json.")
@click.option("--ignore", multiple=True, metavar="LABEL",
              help="Leave out the pixels of a kind (gingiva, contact, marker, background), a tooth (13) or a contact "
                   "(\"contact 13-14\"); repeatable; needs labels on both sides.")
@click.option("--max-shift-px", default=0.0, show_default=True, type=float,
              help="Tolerate a tooth or contact that only moved this many pixels (needs labels on both sides).")
def imgdiff(golden: Path, candidate: Path, diff_path: Path | None, max_level: int, max_fraction: float,
            update: bool, ignore: tuple[str, ...], max_shift_px: float) -> None:
    """Compare a render with its golden PNG; exit 0 match, 1 differ, 2 unusable input.

    Exact when the candidate was drawn by the GL renderer and Mesa version the golden's sidecar
    (GOLDEN.json) names, else within tolerance (SSIM reported). When both carry labels
    (GOLDEN.labels.npz/.json) a second line says what changed, tooth by tooth. See render/imgdiff.py.
    """
    from orthosim_render.imgdiff import Tolerance, imgdiff as compare
    from orthosim_render.regression import this_machine_gl

    outcome = compare(golden, candidate, diff_path=diff_path, tolerance=Tolerance(max_level, max_fraction),
                      update=update, this_machine=this_machine_gl, max_shift_px=max_shift_px,
                      ignore=tuple(int(item) if item.isdigit() else item for item in ignore))
    for line in outcome.lines:
        click.echo(line)
    if outcome.exit_code:
        sys.exit(outcome.exit_code)


@main.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path), metavar="CASE...|RUN_DIR...")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True, help="Report folder.")
@click.option("--detector", "detectors", multiple=True, type=click.Choice(DETECTORS),
              help="Detector to run each case with (repeatable; default: circles, discrete and continuous).")
@click.option("--from-runs", is_flag=True, help="The arguments are run folders `orthosim run` wrote: report them, run nothing.")
@click.option("--pdf", is_flag=True, help="Also print DIR/report.pdf with headless Chromium.")
@click.option("--render", "render_runs", is_flag=True,
              help="Draw the runs' frames too (frontal view, DIR/runs/...), so the report can show their frames/s.")
@click.option("--size", default="480x360", show_default=True, callback=_size, help="Size of each picture WIDTHxHEIGHT.")
@gl_option
def report(inputs: tuple[Path, ...], out_dir: Path, detectors: tuple[str, ...], from_runs: bool, pdf: bool,
           render_runs: bool, size, gl: str | None) -> None:
    """Contact-area report: index.html, report.json (and report.pdf) for cases or finished runs."""
    select_gl(gl)  # the report draws its pictures
    from orthosim_render.report.page import build_report

    if from_runs:
        if detectors:
            raise click.UsageError("--detector chooses how to run cases; with --from-runs the runs say their detector")
        run_dirs = list(inputs)
    else:
        from orthosim.exchange.case import load_case

        for path in inputs:
            load_case(path)  # every case file checked before any run starts
        run_dirs = []
        for path in inputs:
            for det in detectors or PAPER_DETECTORS:
                run_dir = out_dir / "runs" / path.stem / det
                opts = {"no_render": not render_runs, "size": size, "views": ("frontal",), "frames_per_step": 1, "gl": gl}
                run_case(path, run_dir, det, opts)
                run_dirs.append(run_dir)
    if pdf:
        from orthosim_render.report.browser import find_chromium

        find_chromium()  # fail before the work, not after it
    record = build_report(run_dirs, out_dir, pdf=pdf, size=size, progress=lambda text: click.echo(f"report: {text}"))
    outputs = ", ".join(["index.html", "report.json"] + (["report.pdf"] if pdf else []))
    click.echo(f"report of {len(record['cases'])} case(s) in {record['build_s']:.1f} s: {out_dir}/ ({outputs})")


def run_case(case_path: Path, out_dir: Path, detector: str | None, render_opts: dict) -> dict:
    """One run as `orthosim run` does it, also what each `orthosim batch` worker calls (a
    module-level function, so it pickles by name to worker processes and Dask workers).
    render_opts: the `run` command's options by name (any left out take their defaults), plus
    `simulate_in_process` and `single_core` (batch workers, `RunOptions`). Returns the run's metrics and run record, merged."""
    import json

    started = time.perf_counter()
    _run_case(case_path, out_dir, run_options(detector, render_opts))
    record = json.loads((Path(out_dir) / "run.json").read_text())
    # a batch worker outlives its runs: the run's own wall time, not the process's age
    return {**json.loads((Path(out_dir) / "metrics.json").read_text()), **record, "wall_s": time.perf_counter() - started}


def check_render_options(render_opts: dict) -> None:
    """Refuse an unknown --view, or an offscreen backend that cannot start, before any work."""
    if not render_opts.get("no_render"):
        from orthosim_render.cameras import check_view

        select_gl(render_opts.get("gl"))

        for view in render_opts.get("views") or ():
            check_view(view)


def run_options(detector: str | None, opts: dict) -> RunOptions:
    """The RunOptions of the `run` and `demo` command-line options (by name; absent ones keep their defaults)."""
    d = RunOptions()
    get = opts.get
    return RunOptions(detector=detector, render=not get("no_render", False), views=tuple(get("views") or ()) or d.views,
                      size=tuple(get("size", d.size)), gif=get("gif", d.gif), alpha=get("alpha", d.alpha),
                      hide_roots=get("hide_roots", d.hide_roots), contact_faces=get("contact_faces", d.contact_faces),
                      contact_faces_exact=get("contact_faces_exact", d.contact_faces_exact),
                      labels=get("labels", d.labels), overlay=not get("no_overlay", False),
                      frames_per_step=get("frames_per_step"), seconds=get("seconds"), fps=get("fps", d.fps),
                      split_views=get("split_views", d.split_views), export_scene=get("export_scene"),
                      export_steps=get("export_steps"), simulate_in_process=get("simulate_in_process", False),
                      single_core=get("single_core", False), gl=get("gl"),
                      verbosity=0 if get("quiet") else 2 if get("verbose") else 1)


def _run_case(case_path: Path, out_dir: Path, options: RunOptions) -> dict:
    """One run (`orthosim.runtime.run.run_case`) with this package's renderer; returns the run record (run.json)."""
    from orthosim.runtime.run import run_case

    def check_view(name: str) -> str:
        from orthosim_render.cameras import check_view

        return check_view(name)

    from orthosim.runtime.outputfolder import output_folder

    if options.render:
        select_gl(options.gl)  # before any work: a backend that cannot start is one line, not a half-written run
    # out_dir is checked and locked now, before any work; the run is written into a private
    # staging folder that replaces it whole at the end, so a failed or stopped run leaves it as it was
    lines: list[str] = []
    # a case file kept in its own run folder (each `orthosim batch` variant's case.toml) is an input: kept
    carry = (Path(case_path).name,) if Path(case_path).resolve().parent == Path(out_dir).resolve() else ()
    with output_folder(out_dir, carry) as staging:
        record = run_case(case_path, staging, options, draw=_render_steps, check_view=check_view,
                          shown_dir=out_dir, summary_to=lines.append)
    for line in lines:  # after the swap: the summary names files that are there
        click.echo(line)
    return record


def _render_steps(dent, records, out_dir: Path, options: RunOptions, *, extracted: frozenset[int], per_step: int,
                  total: int, progress: bool, case) -> dict:
    """Draw every simulated step (`per_step` frames each) into out_dir: frames, animation, split views,
    with the overlay (case, detector, day N of M, legend, FDI labels on request) unless --no-overlay."""
    from orthosim_render.animation import render_run
    from orthosim_render.overlay import FrameCaption, model_legend
    from orthosim_render.timeline import frames_from_steps

    caption = FrameCaption(case.name, options.detector, case.step_days, case.duration_days, labels=options.labels,
                           extra_legend=model_legend(dent, options.hide_roots)) if options.overlay else None
    frames = frames_from_steps(records, extracted, per_step)
    return render_run(dent, frames, out_dir, views=options.views, size=options.size, gif=options.gif, alpha=options.alpha,
                      hide_roots=options.hide_roots, color_contact_faces=options.contact_faces, fps=options.fps,
                      split_views=options.split_views, total=total, progress=progress,
                      exact_contact_faces=options.contact_faces_exact, caption=caption, single_core=options.single_core)


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Repairs and other warnings reach the user as `orthosim: warning: ...`, one line each."""
    text = " ".join(str(message).split())
    click.echo(f"orthosim: warning: {text}", err=True)


def entry() -> None:
    """Console-script entry: run the CLI, turning user errors into one line and an exit code."""
    import warnings

    from orthosim.runtime.lifeline import sigterm_as_interrupt, terminated

    warnings.showwarning = _one_line_warning
    sigterm_as_interrupt()
    try:
        try:
            main.main(standalone_mode=False)
        except Exception as err:  # whatever a SIGTERM interrupted ends as the stop it was
            if terminated() and not isinstance(err, OrthosimError):
                raise KeyboardInterrupt from None
            raise
    except OrthosimError as err:
        click.echo(f"orthosim: error: {err}", err=True)
        sys.exit(err.exit_code)
    except click.exceptions.Abort:
        click.echo("orthosim: terminated" if terminated() else "orthosim: aborted", err=True)
        sys.exit(143 if terminated() else 130)
    except click.ClickException as err:
        err.show()
        sys.exit(err.exit_code)
    except KeyboardInterrupt:
        click.echo("orthosim: terminated" if terminated() else "orthosim: interrupted", err=True)
        sys.exit(143 if terminated() else 130)
    except BrokenPipeError:
        sys.exit(1)
    except SystemExit:
        raise

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

from . import __version__
from .errors import OrthosimError

DEMO_VIEWS = ("right_buccal", "maxillary_occlusal")


def _size(ctx, param, value: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in value.lower().split("x"))
        if not (16 <= w <= 8192 and 16 <= h <= 8192):
            raise ValueError
    except ValueError:
        raise click.BadParameter(f"{value!r} is not WIDTHxHEIGHT in pixels (16 to 8192), e.g. 640x480") from None
    return w, h


class _LazyGroup(click.Group):
    """A command group whose heavier subgroups are imported only when they run.

    Importing the sphere-tree and collision commands pulls trimesh, scipy and FCL (seconds on a
    loaded machine); `orthosim --help` and `orthosim check` should not pay for that.
    """

    lazy = {  # name -> (module, attribute, one-line help shown by --help)
        "spheretree": ("orthosim.spheretree.commands", "spheretree", "Build, export and evaluate sphere trees."),
        "collide": ("orthosim.collision.commands", "collide", "Collision accuracy studies, timings and single queries."),
    }

    def list_commands(self, ctx):
        return sorted([*super().list_commands(ctx), *self.lazy])

    def get_command(self, ctx, name):
        if name in self.lazy:
            module, attr, _ = self.lazy[name]
            import importlib

            return getattr(importlib.import_module(module), attr)
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


def render_options(f):
    """Options shared by the commands that draw frames."""
    f = click.option("--no-render", is_flag=True, help="Run the simulation alone; write no images.")(f)
    f = click.option("--size", default="640x480", show_default=True, callback=_size, help="Image size WIDTHxHEIGHT.")(f)
    f = click.option("--view", "views", multiple=True,
                     help="Camera preset (repeatable): frontal, right_buccal, left_buccal, maxillary, mandibular. Default: frontal.")(f)
    f = click.option("--gif", is_flag=True, help="Also write animation.gif.")(f)
    f = click.option("--alpha", is_flag=True, help="PNG frames with a transparent background.")(f)
    f = click.option("--hide-roots", is_flag=True, help="Draw crowns only.")(f)
    f = click.option("--frames-per-step", default=6, show_default=True, type=click.IntRange(1, 120),
                     help="Animation frames per simulation step (positions interpolated between steps).")(f)
    f = click.option("--contact-faces", is_flag=True,
                     help="Also colour the tooth surface inside each contact sphere (as in the paper's Figure 7).")(f)
    return f


@main.command()
@click.argument("case", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Output folder (default: out/<case name>).")
@click.option("--detector", type=click.Choice(["circles", "discrete", "continuous", "exact"]), default=None,
              help="Collision detector (default: the case's).")
@render_options
def run(case: Path, out_dir: Path | None, detector: str | None, **render_opts) -> None:
    """Run one case: simulate, detect, write frames and metrics."""
    _run_case(case, out_dir or Path("out") / case.stem, detector, render_opts)


@main.command()
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("out/demo"), show_default=True,
              help="Output folder.")
@render_options
def demo(out_dir: Path, **render_opts) -> None:
    """Run the paper's case 1 (cases/case1_...) into out/demo/."""
    from .case import DEFAULT_CASE

    render_opts["views"] = render_opts.get("views") or DEMO_VIEWS
    _run_case(DEFAULT_CASE, out_dir, None, render_opts)


@main.command()
@click.argument("case", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Output folder (default: out/<case name>-occlusion).")
@click.option("--size", default="800x600", show_default=True, callback=_size, help="Image size WIDTHxHEIGHT.")
@click.option("--no-render", is_flag=True, help="Write occlusion.json only.")
def occlusion(case: Path, out_dir: Path | None, size, no_render: bool) -> None:
    """Occlusal measures and contacts per pair of a case's model at rest; contact areas drawn (Figure 7)."""
    from .atomic import write_json
    from .case import load_case
    from .occlusalcontacts import occlusal_contacts, occlusion_record

    dent = load_case(case).build_dentition()
    out_dir = out_dir or Path("out") / f"{case.stem}-occlusion"
    contacts = occlusal_contacts(dent)
    record = occlusion_record(dent, contacts)
    write_json(out_dir / "occlusion.json", record)
    if not no_render:
        from render.occlusion_figure import write_occlusal_contacts

        write_occlusal_contacts(dent, contacts, out_dir, size)
    click.echo(f"{len(record['contacts'])} facing pairs in contact; overjet {record.get('overjet_mm', float('nan')):.2f} mm, "
               f"overbite {record.get('overbite_mm', float('nan')):.2f} mm -> {out_dir}")


@main.command()
@click.argument("cases", nargs=-1, required=True, type=click.Path(path_type=Path))
def check(cases: tuple[Path, ...]) -> None:
    """Validate case files without running them."""
    from .case import load_case

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
@click.option("--step-days", default=2.0, show_default=True, type=click.FloatRange(min=0.01),
              help="Simulation step for the bench, so the case's teeth keep moving through the measured frames.")
def bench(case: Path | None, out_file: Path, size, frames: int, warmup: int, markers: int, memory_frames: int,
          no_png: bool, no_simulate: bool, step_days: float, no_tree_build: bool) -> None:
    """Measure throughput against the 40 fps target; write JSON.

    Simulation, each collision detector, rendering alone and end to end, in one run on one case.
    """
    from render.bench import run_bench

    from .atomic import write_json

    record = run_bench(case, frames=frames, warmup=warmup, size=size, n_markers=markers,
                       memory_frames=memory_frames, png=not no_png, simulate=not no_simulate,
                       step_days=step_days, tree_build=not no_tree_build)
    write_json(out_file, record)
    fps = record["fps"]
    shown = ", ".join(f"{k} {v:.1f}" if v is not None else f"{k} pending" for k, v in fps.items())
    click.echo(f"fps (median, target {record['target_fps']}): {shown} -> {out_file}")
    trees = record.get("spheretree_build")
    if trees:
        click.echo(f"sphere trees of {trees['teeth']} teeth built in {trees['build_s']:.1f} s on {trees['workers']} cores "
                   f"(target {trees['target_s']:.0f} s; one process {trees['build_s_one_process']:.1f} s), "
                   f"loaded in {1000 * trees['load_s']:.0f} ms")


def _run_case(case_path: Path, out_dir: Path, detector: str | None, render_opts: dict) -> None:
    """Simulate the case (orthosim.movement), draw its steps unless --no-render, write
    out_dir/metrics.json and out_dir/distances.csv.

    When drawing, the simulation runs in a child process (`orthosim.background`) that sends its
    records through a bounded queue: it computes the next steps while this process draws and
    encodes, on the other core, instead of taking turns with them for one GIL.
    """
    from contextlib import ExitStack

    from .case import load_case
    from .metrics import occlusion_summary
    from .movement.report import RunReport
    from .movement.simulation import MovementModel, simulate, simulate_case
    from .runfolder import write_run_record

    case = load_case(case_path)
    detector = detector or case.detector
    started = time.perf_counter()
    with ExitStack() as stack:
        child = None
        if not render_opts.get("no_render"):
            from .background import ChildProcessIterator

            # started first: it imports (seconds) while this process builds the model
            child = stack.enter_context(ChildProcessIterator(ignore_warnings=True,
                                                             preload=("orthosim.movement.simulation",)))
        model = MovementModel.build(case)
        dent, extracted = model.dentition, set(case.extractions)
        report = RunReport(model, detector)
        extra: dict = {"model": {"description": dent.description, **dent.info}, "simulated": True}
        if child is None:
            for _ in report.collect(simulate(model, detector)):
                pass
        else:
            # the child gets the dentition built here rather than building it again
            steps = child.submit(simulate_case, case, detector, dentition=dent)
            extra.update(_render_steps(dent, report.collect(steps), extracted, out_dir, render_opts))
    extra["occlusion"] = occlusion_summary(dent)  # the initial model's
    extra["occlusion_final"] = occlusion_summary(dent, {n: report.last.poses[n] for n in dent.fdis})
    extra["wall_s"] = time.perf_counter() - started
    metrics = report.write(out_dir, extra)
    write_run_record(out_dir, case_path, detector, {"wall_s": extra["wall_s"]})  # last: marks the run finished
    click.echo(f"{case.name} ({detector}): {metrics['steps']} steps, total distance "
               f"{metrics['total_distance_mm']['initial']:.2f} -> {metrics['total_distance_mm']['final']:.2f} mm, "
               f"{metrics['collisions']} collisions, max penetration {metrics['max_penetration_mm']:.3f} mm -> {out_dir}/metrics.json")


def _render_steps(dent, records, extracted, out_dir: Path, opts: dict) -> dict:
    """Render every simulated step (one frame per step and view) into out_dir/frames."""
    from render.animation import render_run
    from render.timeline import frames_from_steps

    frames = frames_from_steps(records, frozenset(extracted), opts.get("frames_per_step", 1))
    return render_run(dent, frames, out_dir, views=opts.get("views") or ("frontal",), size=opts["size"],
                      gif=opts.get("gif", False), alpha=opts.get("alpha", False),
                      hide_roots=opts.get("hide_roots", False),
                      color_contact_faces=opts.get("contact_faces", False))


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Repairs and other warnings reach the user as `orthosim: warning: ...`, one line each."""
    text = " ".join(str(message).split())
    click.echo(f"orthosim: warning: {text}", err=True)


def entry() -> None:
    """Console-script entry: run the CLI, turning user errors into one line and an exit code."""
    import warnings

    warnings.showwarning = _one_line_warning
    try:
        main.main(standalone_mode=False)
    except OrthosimError as err:
        click.echo(f"orthosim: error: {err}", err=True)
        sys.exit(err.exit_code)
    except click.exceptions.Abort:
        click.echo("orthosim: aborted", err=True)
        sys.exit(130)
    except click.ClickException as err:
        err.show()
        sys.exit(err.exit_code)
    except KeyboardInterrupt:
        click.echo("orthosim: interrupted", err=True)
        sys.exit(130)
    except BrokenPipeError:
        sys.exit(1)
    except SystemExit:
        raise

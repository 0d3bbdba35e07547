"""`orthosim bench`: the measurement package (`orthosim_bench`, outside the product) run on the
product, its record written as JSON and its summary printed."""

from __future__ import annotations

from pathlib import Path

import click

from orthosim.cli.options import gl_option, parse_size, select_gl


@click.command()
@click.option("--case", "case", type=click.Path(path_type=Path), default=None,
              help="Case to measure (default: cases/case1_first_premolar_extraction.toml, the paper's case 1).")
@click.option("--out", "out_file", type=click.Path(path_type=Path), required=True, help="Where to write the JSON record.")
@click.option("--size", default="640x480", show_default=True, callback=parse_size, help="Image size WIDTHxHEIGHT.")
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
@click.option("--no-mechanics", is_flag=True,
              help="Skip the ligament's time on a 40k-triangle tooth and the step with it against the rule's.")
@click.option("--no-backends", is_flag=True,
              help="Skip render_backends: render frames/s through each offscreen backend found, one process each.")
@gl_option
def bench(case: Path | None, out_file: Path, size, frames: int, warmup: int, markers: int, memory_frames: int,
          no_png: bool, no_simulate: bool, step_days: float, no_tree_build: bool, no_startup: bool,
          no_staging: bool, no_batch: bool, no_report: bool, report_runs: Path, no_memory: bool, labels: bool,
          closure_case: Path | None, no_scan: bool, no_mechanics: bool, no_backends: bool, gl: str | None) -> None:
    """Measure throughput against the 40 fps target; write JSON.

    Simulation, each collision detector, rendering alone and end to end, in one run on one case.
    Exits 1 when a sub-run failed or was refused (its figure null, a line on stderr naming it).
    """
    select_gl(gl)
    from orthosim_bench.render import run_bench
    from orthosim_bench.subruns import Failure, as_records, guarded
    from orthosim_bench.summary import summary_lines

    from orthosim.cli.run import run_for_batch
    from orthosim.storage.atomic import write_json

    record = run_bench(case, frames=frames, warmup=warmup, size=size, n_markers=markers,
                       memory_frames=memory_frames, png=not no_png, simulate=not no_simulate,
                       step_days=step_days, tree_build=not no_tree_build, startup=not no_startup,
                       staging=not no_staging, batch=not no_batch, report=not no_report, report_runs=report_runs,
                       memory=not no_memory, run_case=run_for_batch, labels=labels, scan=not no_scan)
    failures = [Failure(**f) for f in record["failures"]]
    if closure_case is not None:
        from orthosim_bench.closure import closure_timings

        record["closure"] = guarded("closure", failures, lambda: closure_timings(closure_case))
    from orthosim.exchange.case import DEFAULT_CASE

    if not no_mechanics:
        from orthosim_bench.mechanics import mechanics_timings

        record["mechanics"] = guarded("mechanics", failures, lambda: mechanics_timings(case or DEFAULT_CASE))
    if not no_backends:  # after run_bench closed its renderer: each backend draws in a process of its own
        from orthosim_bench.backends import render_backends

        record["render_backends"] = guarded("render_backends", failures, lambda: render_backends(
            case or DEFAULT_CASE, size, frames=max(30, frames // 2), warmup=min(warmup, 20), n_markers=markers))
    record["failures"] = as_records(failures)
    write_json(out_file, record)
    for line in summary_lines(record, out_file):
        click.echo(line)
    if record.get("mechanics"):
        from orthosim_bench.mechanics import summary_line

        click.echo(summary_line(record["mechanics"]))
    for failure in failures:  # every sub-run that failed or was refused, named, and the bench fails
        click.echo(failure.line(), err=True)
    if failures:
        raise SystemExit(1)

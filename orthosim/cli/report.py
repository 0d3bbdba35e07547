"""`orthosim report`: the contact-area report (HTML, JSON, PDF) of cases, run here, or of finished runs."""

from __future__ import annotations

from pathlib import Path

import click

from orthosim.cli.options import gl_option, parse_size, select_gl
from orthosim.cli.run import run_for_batch
from orthosim.collision.detectors import DETECTORS, PAPER_DETECTORS
from orthosim.runtime.options import RenderOptions, RunOptions


@click.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path), metavar="CASE...|RUN_DIR...")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True, help="Report folder.")
@click.option("--detector", "detectors", multiple=True, type=click.Choice(DETECTORS),
              help="Detector to run each case with (repeatable; default: circles, discrete and continuous).")
@click.option("--from-runs", is_flag=True, help="The arguments are run folders `orthosim run` wrote: report them, run nothing.")
@click.option("--pdf", is_flag=True, help="Also print DIR/report.pdf with headless Chromium.")
@click.option("--render", "render_runs", is_flag=True,
              help="Draw the runs' frames too (frontal view, DIR/runs/...), so the report can show their frames/s.")
@click.option("--size", default="480x360", show_default=True, callback=parse_size, help="Size of each picture WIDTHxHEIGHT.")
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
                render = RenderOptions(size=size, frames_per_step=1, gl=gl) if render_runs else None
                run_for_batch(path, run_dir, RunOptions(detector=det, render=render))
                run_dirs.append(run_dir)
    if pdf:
        from orthosim_render.report.browser import find_chromium

        find_chromium()  # fail before the work, not after it
    record = build_report(run_dirs, out_dir, pdf=pdf, size=size, progress=lambda text: click.echo(f"report: {text}"))
    outputs = ", ".join(["index.html", "report.json"] + (["report.pdf"] if pdf else []))
    click.echo(f"report of {len(record['cases'])} case(s) in {record['build_s']:.1f} s: {out_dir}/ ({outputs})")

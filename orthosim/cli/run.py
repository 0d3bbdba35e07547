"""`orthosim run` and `orthosim demo`: one case simulated, detected and drawn into a run folder.

`run_into_folder` is the run both commands make; `run_for_batch` is what each `orthosim batch`
worker, `orthosim report` and the bench call (a module-level function, so it pickles by name to
worker processes and Dask workers).
"""

from __future__ import annotations

import time
from pathlib import Path

import click

from orthosim.cli.options import render_options, run_options, select_gl
from orthosim.collision.detectors import DETECTORS
from orthosim.runtime.options import RunOptions

DEMO_VIEWS = ("right_buccal", "maxillary_occlusal")


@click.command()
@click.argument("case", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Output folder (default: out/<case name>).")
@click.option("--detector", type=click.Choice(DETECTORS), default=None,
              help="Collision detector (default: the case's).")
@render_options
def run(case: Path, out_dir: Path | None, detector: str | None, **flags) -> None:
    """Run one case: simulate, detect, write frames and metrics."""
    run_into_folder(case, out_dir or Path("out") / case.stem, run_options(detector, flags))


@click.command()
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("out/demo"), show_default=True,
              help="Output folder.")
@render_options
def demo(out_dir: Path, **flags) -> None:
    """Run the paper's case 1 (cases/case1_...) into out/demo/."""
    from orthosim.exchange.case import DEFAULT_CASE

    flags["views"] = flags["views"] or DEMO_VIEWS
    run_into_folder(DEFAULT_CASE, out_dir, run_options(None, flags))


def run_for_batch(case_path: Path, out_dir: Path, options: RunOptions) -> dict:
    """One run as `orthosim run` does it, also what each `orthosim batch` worker calls (a
    module-level function, so it pickles by name to worker processes and Dask workers).
    Returns the run's metrics and run record, merged, with the run's own wall time (wall_s, s)."""
    import json

    started = time.perf_counter()
    if options.simulate_in_process and (options.render is None or options.render.single_core):
        from orthosim.system.firstrun import keep_to_one_thread

        keep_to_one_thread()  # a worker on one core starts no thread, not even to say what it prepares
    run_into_folder(case_path, out_dir, options)
    record = json.loads((Path(out_dir) / "run.json").read_text())
    # a batch worker outlives its runs: the run's own wall time, not the process's age
    return {**json.loads((Path(out_dir) / "metrics.json").read_text()), **record, "wall_s": time.perf_counter() - started}


def run_into_folder(case_path: Path, out_dir: Path, options: RunOptions) -> dict:
    """One run (`orthosim.runtime.run.run_one`) with this package's renderer, written into a private
    folder that replaces out_dir whole at the end; returns the run record (run.json)."""
    from orthosim.runtime.run import run_one

    def check_view(name: str) -> str:
        from orthosim_render.cameras import check_view

        return check_view(name)

    from orthosim.runtime.outputfolder import output_folder

    if options.render is not None:
        select_gl(options.render.gl)  # before any work: a backend that cannot start is one line, not a half-written run
    # out_dir is checked and locked now, before any work; the run is written into a private
    # staging folder that replaces it whole at the end, so a failed or stopped run leaves it as it was
    lines: list[str] = []
    # a case file kept in its own run folder (each `orthosim batch` variant's case.toml) is an input: kept
    carry = (Path(case_path).name,) if Path(case_path).resolve().parent == Path(out_dir).resolve() else ()
    with output_folder(out_dir, carry) as staging:
        record = run_one(case_path, staging, options, draw=_render_steps, check_view=check_view,
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

    render = options.render
    caption = FrameCaption(case.name, options.detector, case.step_days, case.duration_days, labels=render.labels,
                           extra_legend=model_legend(dent, render.hide_roots)) if render.overlay else None
    scene = _scene_recorder(dent, extracted) if render.animation_scene else None
    frames = frames_from_steps(scene.watch(records) if scene else records, extracted, per_step)
    rendered = render_run(dent, frames, out_dir, render, total=total, progress=progress, caption=caption)
    if scene is not None:  # the steps as one animated glTF scene and its 3D page (orthosim_render.viewer_page)
        rendered["outputs"].update({k: p.name for k, p in scene.write(out_dir, title=case.name).items()})
    return rendered


def _scene_recorder(dent, extracted):
    from orthosim_render.viewer_page import SceneRecorder

    return SceneRecorder(dent, extracted)

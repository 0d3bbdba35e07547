"""`orthosim batch`: every case times every detector times every `--set` value, into one folder.

The command wires the batch (planning, the local pool, the Dask runner: all core) to the function
that runs one case, `orthosim.cli.run.run_for_batch`, the same run `orthosim run` makes.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click

from orthosim.cli.options import check_render_options, render_options, run_options
from orthosim.cli.run import run_for_batch
from orthosim.collision.detectors import DETECTORS
from orthosim.batch.execute import BatchOptions, counts, run_batch
from orthosim.batch.plan import parse_sweep, plan_batch


@click.command()
@click.argument("cases", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), required=True,
              help="Batch folder: a run folder per variant, batch.json and batch.csv.")
@click.option("--detector", "detectors", multiple=True, type=click.Choice(DETECTORS),
              help="Collision detector (repeatable: every run with each). Default: each case's own.")
@click.option("--set", "sweeps", multiple=True, metavar="KEY=V1,V2,...",
              help="Sweep a case-file value (repeatable; the Cartesian product runs), e.g. "
                   "treatment.step_days=1,2,5 or loads.0.force_cN=50,100,150.")
@click.option("--workers", type=click.IntRange(1, 256), default=None,
              help="Local worker processes, each rendering on one core. Default: one per core.")
@click.option("--run-timeout", type=click.FloatRange(min=0, min_open=True), default=None, metavar="SECONDS",
              help="Stop a run still going after this long and record it as failed.")
@click.option("--retries", type=click.IntRange(0, 10), default=1, show_default=True,
              help="Local workers: times a run is tried again after its worker process died.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Run on a Dask distributed scheduler (tcp://HOST:PORT) instead of local workers; needs orthosim[cluster].")
@click.option("--simulation", type=click.Choice(["in-worker", "child"]), default="in-worker", show_default=True,
              help="Simulate in each worker, on the one thread that draws and encodes (one core per worker), or "
                   "in a child process per run as `orthosim run` does.")
@click.option("--dry-run", is_flag=True, help="Validate and list the runs; run nothing.")
@render_options
def batch(cases, out_dir: Path, detectors, sweeps, workers, run_timeout, retries, scheduler, simulation, dry_run,
          **flags) -> None:
    """Run many cases and parameter sweeps; resumable; exit 1 when any run failed.

    Each run writes OUT/<run-id>/ as `orthosim run` does, plus case.toml (the exact case that ran).
    Running the same command again skips finished runs and redoes the rest.
    """
    run = run_options(None, flags)
    check_render_options(run)
    parsed = [parse_sweep(s) for s in sweeps]
    variants = plan_batch(cases, detectors, parsed)
    keys = [s.key for s in parsed]
    if dry_run:
        for v in variants:
            click.echo(f"{v.run_id}\t{v.source}\t{v.label}\t{v.steps} steps")
        click.echo(f"{len(variants)} runs, all valid")
        return
    if simulation == "in-worker":
        run = run.on_one_core()
    options = BatchOptions(workers=workers or os.cpu_count() or 1, run_timeout_s=run_timeout, retries=retries,
                           scheduler=scheduler, run=run)
    rows = run_batch(variants, out_dir, run_for_batch, options, keys)
    c = counts(rows)
    reused = f" ({c['reused']} from an earlier run)" if c["reused"] else ""
    click.echo(f"batch: {len(rows)} runs, {c['ok']} ok{reused}, {c['failed']} failed -> {out_dir}/batch.csv")
    for r in rows:
        if r.status == "failed":
            click.echo(f"  failed: {r.run_id}: {r.error}", err=True)
    if c["failed"] or c["pending"]:
        sys.exit(1)

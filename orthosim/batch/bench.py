"""`orthosim bench`'s batch figure: animations per minute with 1 and with 2 local workers, same runs.

The runs are variants of one case (the bench's), shortened so a run is a fraction of a minute,
each with its own load (`loads.0.force_cN`), rendered as `orthosim batch` renders them. The clock
covers what a user waits for: starting the worker processes, every run's model, simulation,
frames and video, the table. The model's sphere trees are made before either measurement, so
neither pays for building them. Target: 2 workers at least 1.8 times 1 worker on a 2-core
machine; read the figures with the load averages beside them.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from .execute import BatchOptions, prebuild_trees, run_batch
from .plan import parse_sweep, plan_batch
from .worker import RunCase

TARGET_RATIO = 1.8


def batch_throughput(run_case: RunCase, case: str | Path, *, runs: int = 4, duration_days: float = 20.0,
                     step_days: float = 2.0, size: tuple[int, int] = (320, 240), frames_per_step: int = 6) -> dict:
    """Animations per minute of the same `runs` runs with 1 and with 2 local workers (one bench run)."""
    from ..case import load_case

    sweeps = [parse_sweep(f"treatment.duration_days={duration_days:g}"), parse_sweep(f"treatment.step_days={step_days:g}")]
    if load_case(case).loads:
        sweeps.append(parse_sweep("loads.0.force_cN=" + ",".join(str(100 + 10 * i) for i in range(runs))))
    else:  # a case without loads: the runs differ in their (otherwise unused) restitution
        sweeps.append(parse_sweep("simulation.restitution=" + ",".join(f"{0.1 + 0.1 * i:g}" for i in range(runs))))
    variants = plan_batch([case], sweeps=sweeps)
    render_opts = {"size": tuple(size), "frames_per_step": frames_per_step, "views": ("frontal",), "simulate_in_process": True}
    record: dict = {"case": str(case), "runs": len(variants), "steps_per_run": variants[0].steps,
                    "frames_per_run": variants[0].steps * frames_per_step + 1, "size": list(size),
                    "target_ratio_2_to_1": TARGET_RATIO, "load_average_start": list(os.getloadavg())}
    with tempfile.TemporaryDirectory(prefix="orthosim-bench-batch-") as tmp:
        prebuild_trees([Path(case)])
        for workers, name in ((1, "1_worker"), (2, "2_workers")):
            started = time.perf_counter()
            rows = run_batch(variants, Path(tmp) / name, run_case,
                             BatchOptions(workers=workers, render_opts=render_opts, prebuild_trees=False, progress=False))
            wall = time.perf_counter() - started
            failed = [f"{r.run_id}: {r.error}" for r in rows if r.status != "ok"]
            if failed:
                record[f"errors_{name}"] = failed
            record[f"wall_s_{name}"] = wall
            record[f"per_minute_{name}"] = (len(rows) - len(failed)) / wall * 60.0
    record["ratio_2_to_1"] = record["per_minute_2_workers"] / record["per_minute_1_worker"] if record["per_minute_1_worker"] else None
    record["meets_target"] = record["ratio_2_to_1"] is not None and record["ratio_2_to_1"] >= TARGET_RATIO
    record["load_average_end"] = list(os.getloadavg())
    record["cores"] = os.cpu_count()
    return record

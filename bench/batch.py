"""`orthosim bench`'s batch figure: animations per minute with 1 and with 2 local workers, same runs.

The runs are variants of one case (the bench's), shortened so a run takes a second or two of CPU,
each with its own load (`loads.0.force_cN`), rendered as `orthosim batch` renders them. Each worker
count gets a cold pool of its own and the same runs; the clock covers what a user waits for:
starting the worker processes, every run's model, simulation, frames and video, the table. The
model's sphere trees are made before either measurement, so neither pays for building them.

Batch size (`RUNS`): users render hundreds of runs, and a batch that short that each worker's
start-up (interpreter, imports, the first run's loading of compiled kernels: about 2 s of CPU
here, once per worker) is a large share of it measures process start, not throughput. With 24
runs each of 2 workers does 12, and start-up is about a tenth of its CPU (a twentieth for 1 worker).

Beside the figures, what explains them: the workers' CPU seconds per run (from the operating
system's accounting of the finished worker processes, ffmpeg included) and the cores the batch
kept busy on average. A worker runs each run on one core (`RunOptions.on_one_core`, `worker.WORKER_ENV`:
simulation, drawing and encoding on one thread), so one worker keeps about one core busy and two
workers on two cores can gain up to 2x; `ratio_ceiling` is min(2, cores / cores_busy_1_worker),
meaningful on a quiet machine. On a loaded machine the ratio means little: the kernel shares the
cores between sessions (autogroup), so two workers get no more CPU than one; the CPU per run
(equal for 1 and 2 workers when nothing is lost to contention) and one worker's cores_busy still
mean something. Target: 2 workers at least 1.8 times 1 worker on a 2-core machine; read the
figures with the load averages beside them.
"""

from __future__ import annotations

import os
import resource
import statistics
import tempfile
import time
from pathlib import Path

from orthosim.batch.execute import BatchOptions, prebuild_trees, run_batch
from orthosim.batch.plan import parse_sweep, plan_batch
from orthosim.batch.worker import RunCase
from orthosim.runtime.options import RenderOptions, RunOptions
from orthosim_bench.subruns import last_line

TARGET_RATIO = 1.8
RUNS = 24


def _children_cpu_s() -> float:
    """CPU seconds of this process's finished and reaped child processes (and theirs)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _self_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def batch_throughput(run_case: RunCase, case: str | Path, *, runs: int = RUNS, duration_days: float = 20.0,
                     step_days: float = 2.0, size: tuple[int, int] = (320, 240), frames_per_step: int = 6,
                     worker_counts: tuple[int, ...] = (1, 2)) -> dict:
    """Animations per minute of the same `runs` runs with 1 and with 2 local workers (one bench run)."""
    from orthosim.exchange.case import load_case

    sweeps = [parse_sweep(f"treatment.duration_days={duration_days:g}"), parse_sweep(f"treatment.step_days={step_days:g}")]
    if load_case(case).loads:
        sweeps.append(parse_sweep("loads.0.force_cN=" + ",".join(str(100 + 5 * i) for i in range(runs))))
    else:  # a case without loads: the runs differ in their (otherwise unused) restitution
        sweeps.append(parse_sweep("simulation.restitution=" + ",".join(f"{0.01 * (i + 1):g}" for i in range(runs))))
    variants = plan_batch([case], sweeps=sweeps)
    options = RunOptions(render=RenderOptions(size=tuple(size), frames_per_step=frames_per_step)).on_one_core()
    cores = os.cpu_count() or 1
    record: dict = {"case": str(case), "runs": len(variants), "steps_per_run": variants[0].steps,
                    "frames_per_run": variants[0].steps * frames_per_step + 1, "size": list(size),
                    "batch_size_why": f"{len(variants)} runs: each of 2 workers runs {len(variants) // 2}, so a worker's "
                                      "start-up (about 2 s of CPU, once) is a small share, as in a real batch of hundreds",
                    "target_ratio_2_to_1": TARGET_RATIO, "cores": cores, "load_average_start": list(os.getloadavg()),
                    "failures": []}
    with tempfile.TemporaryDirectory(prefix="orthosim-bench-batch-") as tmp:
        prebuild_trees([Path(case)])
        for workers in worker_counts:
            name = "1_worker" if workers == 1 else f"{workers}_workers"
            load = os.getloadavg()[0]
            cpu0, own0 = _children_cpu_s(), _self_cpu_s()
            started = time.perf_counter()
            rows = run_batch(variants, Path(tmp) / name, run_case,
                             BatchOptions(workers=workers, run=options, prebuild_trees=False, progress=False))
            wall = time.perf_counter() - started
            cpu = _children_cpu_s() - cpu0  # the pool's workers are joined when run_batch returns
            failed = [f"{r.run_id}: {r.error}" for r in rows if r.status != "ok"]
            if failed:  # a batch with a failed run has no throughput: null, and the bench says why
                record[f"errors_{name}"] = failed
                record["failures"].append({"figure": f"per_minute_{name}",
                                           "why": f"{len(failed)} of {len(rows)} runs failed; first: {last_line(failed[0])}"})
            run_walls = [r.wall_s for r in rows if r.status == "ok" and r.wall_s is not None]
            run_cpu = [r.extra["cpu_s"] for r in rows if r.status == "ok" and "cpu_s" in r.extra]
            record[f"wall_s_{name}"] = wall
            record[f"per_minute_{name}"] = None if failed else len(rows) / wall * 60.0
            record[f"detail_{name}"] = {
                "load_average_1min_before": load,
                "workers_cpu_s_per_run": cpu / max(len(rows), 1),
                "run_cpu_s_median": statistics.median(run_cpu) if run_cpu else None,
                "run_cpu_s_first": run_cpu[0] if run_cpu else None,
                # the workers' CPU outside their runs: interpreter start, imports, pool traffic
                "workers_cpu_s_outside_runs": cpu - sum(run_cpu),
                "parent_cpu_s": _self_cpu_s() - own0,
                "cores_busy": cpu / wall,
                "run_wall_s_median": statistics.median(run_walls) if run_walls else None,
                "run_wall_s_max": max(run_walls) if run_walls else None,
                "worker_processes": len({r.extra.get("worker") for r in rows if r.extra.get("worker")}),
            }
    one, two = record.get("per_minute_1_worker"), record.get("per_minute_2_workers")
    record["ratio_2_to_1"] = two / one if one and two is not None else None
    # a ratio whose either side did not run is null, and so is its verdict: never met
    record["meets_target"] = None if record["ratio_2_to_1"] is None else record["ratio_2_to_1"] >= TARGET_RATIO
    busy_1 = (record.get("detail_1_worker") or {}).get("cores_busy")
    # two workers gain at most 2x, and no more than the cores one worker leaves idle allow
    record["ratio_ceiling"] = min(2.0, cores / busy_1) if busy_1 else None
    record["load_average_end"] = list(os.getloadavg())
    return record

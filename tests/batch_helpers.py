"""Run functions that `tests/batch/test_batch_runs.py` hands to batch workers in place of
`orthosim.cli.run.run_for_batch`: module-level, so that they pickle by name to worker processes and
Dask workers (bound with `functools.partial`). Each misbehaves for the runs named in `fail_runs`,
so one batch can hold good and bad runs."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from orthosim.runtime.options import RenderOptions, RunOptions

SMALL_CASE = """\
[case]
name = "small"

[model]
kind = "parametric"
resolution = "coarse"

[treatment]
extractions = [14, 24]
duration_days = 4
step_days = 2
detector = "discrete"

[[loads]]
teeth = [16, 26]
force_cN = 150
direction = "mesial"
"""

RUN = RunOptions(render=RenderOptions(size=(48, 32), frames_per_step=1)).on_one_core()


def _real(case_path, out_dir, options):
    from orthosim.cli.run import run_for_batch

    return run_for_batch(case_path, out_dir, options)


def _named(out_dir, fail_runs) -> bool:
    return Path(out_dir).name in fail_runs


def crash(case_path, out_dir, options, fail_runs=()):
    """A bug: raises half way through the named runs (after writing a frame-like file)."""
    if _named(out_dir, fail_runs):
        Path(out_dir, "frames").mkdir(parents=True, exist_ok=True)
        raise RuntimeError("simulated crash in the renderer")
    return _real(case_path, out_dir, options)


def hang(case_path, out_dir, options, fail_runs=()):
    """Never ends for the named runs (until the batch's --run-timeout stops it)."""
    if _named(out_dir, fail_runs):
        time.sleep(3600)
    return _real(case_path, out_dir, options)


def kill_worker_once(case_path, out_dir, options, fail_runs=(), marker=None):
    """The named run's first attempt kills its own worker process (SIGKILL) part-way through."""
    marker = Path(marker) / Path(out_dir).name
    if _named(out_dir, fail_runs) and not marker.exists():
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.write_text(str(os.getpid()))
        Path(out_dir, "partial.tmp").write_text("half")
        os.kill(os.getpid(), signal.SIGKILL)
    return _real(case_path, out_dir, options)


def kill_worker_always(case_path, out_dir, options, fail_runs=()):
    if _named(out_dir, fail_runs):
        os.kill(os.getpid(), signal.SIGKILL)
    return _real(case_path, out_dir, options)


def hang_or_instant(case_path, out_dir, options, fail_runs=()):
    """Never ends for the named runs (until the batch's --run-timeout stops it); the others end at once."""
    if _named(out_dir, fail_runs):
        time.sleep(3600)
    return instant(case_path, out_dir, options)


def instant(case_path, out_dir, options):
    """No simulation, no drawing: a run that ends at once with a plausible summary (for tests of
    the batch's own machinery: its table, its pool)."""
    return {"steps": 1, "collisions": 0, "max_penetration_mm": 0.0,
            "total_distance_mm": {"initial": 1.0, "final": 0.5}, "frames": 0, "wall_s": 0.0}


def with_threads(case_path, out_dir, options):
    """A real run that then lists its worker process's threads (threads.json): Python's, and the
    operating system's by name (llvmpipe's raster threads are named llvmpipe-N)."""
    import json
    import threading

    summary = _real(case_path, out_dir, options)
    native = sorted(Path(task, "comm").read_text().strip() for task in Path("/proc/self/task").iterdir())
    Path(out_dir, "threads.json").write_text(json.dumps({"python": [t.name for t in threading.enumerate()],
                                                          "native": native}))
    return summary

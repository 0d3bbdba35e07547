"""What a batch worker does around one run: the same on a local worker process and on a Dask worker.

The run itself is `run_case(case_file, out_dir, options: RunOptions) -> summary`, the run
`orthosim run` makes, handed in by the composition root (`orthosim.cli.run.run_for_batch`): this
module never draws. A local worker asks each run for one core (`RunOptions.on_one_core`), as
WORKER_ENV holds each library to one thread; `orthosim run` alone keeps its pipeline, which keeps
more than a core busy.
Around it: the run's printed lines and warnings are captured (the batch shows one progress bar,
not a bar per run; the text goes to `DIR/logs/<run-id>.log`), and any failure becomes an outcome
with its one-line error instead of an exception, so that one bad run never stops the batch.

Workers render single-threaded (`WORKER_ENV`): llvmpipe would otherwise start a thread per core
in every worker's GL context, and numba and BLAS their own pools, and N workers on N cores would
fight over them. The variables must be in the environment before those libraries load, so the
local pool sets them before it starts its processes and a Dask worker should be started with them
(README, "Batch on a cluster").
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from orthosim.errors import OrthosimError
from orthosim.runtime.options import RunOptions
from orthosim.batch.table import run_summary

WORKER_ENV = {
    "LP_NUM_THREADS": "1",  # Mesa llvmpipe rendering threads
    "NUMBA_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}

RunCase = Callable[[Path, Path, RunOptions], dict]


@dataclass(frozen=True)
class RunTask:
    """One run as a worker gets it (picklable): where its case file is, where it writes, and what
    is asked of it (its detector set)."""

    run_id: str
    case_file: str
    out_dir: str
    options: RunOptions


@dataclass(frozen=True)
class RunOutcome:
    run_id: str
    ok: bool
    error: str | None
    summary: dict
    log: str
    wall_s: float
    worker: str = ""  # host:pid that ran it
    cpu_s: float | None = None  # CPU seconds of the worker process and its children (ffmpeg) during the run; on a
    # Dask worker running several tasks at once, theirs too


def process_cpu_s() -> float:
    """CPU seconds used so far by this process (every thread) and its finished children."""
    import resource

    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@contextlib.contextmanager
def worker_environment():
    """WORKER_ENV set in this process's environment (inherited by processes started inside), then undone."""
    saved = {k: os.environ.get(k) for k in WORKER_ENV}
    os.environ.update(WORKER_ENV)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def init_local_worker() -> None:
    """A local worker process: Ctrl-C is the batch's to handle (it stops the pool), not each run's."""
    os.environ.update(WORKER_ENV)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def execute(run_case: RunCase, task: RunTask) -> RunOutcome:
    """Run one task and return its outcome; never raises for a failing run."""
    import socket
    import warnings

    log = io.StringIO()
    started, cpu_started = time.perf_counter(), process_cpu_s()
    error, summary = None, {}
    with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log), warnings.catch_warnings():
        warnings.simplefilter("default")
        warnings.showwarning = lambda message, category, filename, lineno, file=None, line=None: log.write(
            f"orthosim: warning: {' '.join(str(message).split())}\n")
        try:
            summary = run_summary(run_case(Path(task.case_file), Path(task.out_dir), task.options) or {})
        except OrthosimError as err:
            error = str(err)
        except Exception as err:  # a crash of this run, not of the batch: recorded with its traceback in the log
            error = f"{type(err).__name__}: {' '.join(str(err).split())}"
            log.write(traceback.format_exc())
    return RunOutcome(task.run_id, error is None, error, summary, log.getvalue(), time.perf_counter() - started,
                      f"{socket.gethostname()}:{os.getpid()}", process_cpu_s() - cpu_started)


def execute_shipped(run_case: RunCase, run_id: str, case_text: str, options: RunOptions) -> tuple[RunOutcome, dict[str, bytes]]:
    """A run on a machine that may not see the batch folder (a Dask worker): the case text comes
    with the task, the run writes into a private temporary folder, and its files go back with the
    outcome ({relative path: bytes}) for the client to write into DIR/<run-id>/."""
    os.environ.update(WORKER_ENV)  # for the GL context this run creates; threads already started stay
    with tempfile.TemporaryDirectory(prefix="orthosim-batch-") as tmp:
        run_dir = Path(tmp) / run_id
        run_dir.mkdir()
        (run_dir / "case.toml").write_text(case_text)
        outcome = execute(run_case, RunTask(run_id, str(run_dir / "case.toml"), str(run_dir), options))
        files = {}
        if outcome.ok:
            for path in sorted(run_dir.rglob("*")):
                if path.is_file():
                    files[str(path.relative_to(run_dir))] = path.read_bytes()
    return outcome, files

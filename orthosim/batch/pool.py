"""Local batch workers: N processes on this machine, each running one run at a time.

Why pebble's `ProcessPool` and not the standard library's: a run that passes `--run-timeout` has to
be stopped, which needs its process killed, and a worker that dies (killed, out of memory, a crash
in native code) must cost only its own run; `concurrent.futures.ProcessPoolExecutor` can do
neither (a dead worker breaks the whole pool). pebble kills the timed-out worker, reports a dead one
as `ProcessExpired` for that task alone, and starts a replacement. Workers are started with
"spawn" (fresh interpreters, safe with OpenGL) and live for the whole batch, so imports and
compiled kernels are paid once per worker, not once per run.
"""

from __future__ import annotations

import multiprocessing
import signal
from concurrent.futures import FIRST_COMPLETED, TimeoutError, wait
from typing import Iterator, Sequence

from orthosim.batch.worker import RunCase, RunOutcome, RunTask, execute, init_local_worker, worker_environment


def _death(err) -> str:
    code = getattr(err, "exitcode", None)
    if isinstance(code, int) and code < 0:
        try:
            return f"the worker process died (signal {signal.Signals(-code).name})"
        except ValueError:
            pass
    return f"the worker process died (exit code {code})"


def _clear_partial(task: RunTask) -> None:
    """Before a retry: remove what the dead attempt left in its run folder, keeping its case file."""
    import shutil
    from pathlib import Path

    case_file = Path(task.case_file)
    for path in Path(task.out_dir).iterdir():
        if path == case_file:
            continue
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)


def run_local(tasks: Sequence[RunTask], run_case: RunCase, workers: int, run_timeout_s: float | None = None,
              retries: int = 1) -> Iterator[tuple[RunOutcome, int]]:
    """Yield (outcome, attempts) for every task as it ends, in the order they end.

    A run that exceeds `run_timeout_s` is stopped (its worker killed) and fails; a run whose worker
    died is tried again up to `retries` times (a killed machine process is often not the run's
    fault), then fails. Closing the generator (Ctrl-C in the caller) stops every worker at once.
    """
    from pebble import ProcessExpired, ProcessPool

    with worker_environment():  # inherited by the workers, also by those started after a death
        pool = ProcessPool(max_workers=max(1, workers), initializer=init_local_worker,
                           context=multiprocessing.get_context("spawn"))
        try:
            running = {}
            for task in tasks:
                running[pool.schedule(execute, args=(run_case, task), timeout=run_timeout_s)] = (task, 1)
            while running:
                done, _ = wait(list(running), return_when=FIRST_COMPLETED)
                for fut in done:
                    task, attempt = running.pop(fut)
                    try:
                        yield fut.result(), attempt
                        continue
                    except TimeoutError:
                        error = f"stopped after {run_timeout_s:g} s (--run-timeout)"
                    except ProcessExpired as err:
                        if attempt <= retries:
                            _clear_partial(task)
                            running[pool.schedule(execute, args=(run_case, task), timeout=run_timeout_s)] = (task, attempt + 1)
                            continue
                        error = f"{_death(err)}, {attempt} times"
                    except Exception as err:  # e.g. the task could not be pickled
                        error = f"{type(err).__name__}: {' '.join(str(err).split())}"
                    yield RunOutcome(task.run_id, False, error, {}, "", 0.0), attempt
        finally:
            pool.stop()  # every run has ended, or Ctrl-C: the workers go now
            pool.join()

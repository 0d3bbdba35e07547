"""Running a planned batch into one folder: skip what is finished, prepare the rest, run, tabulate.

    rows = run_batch(variants, Path("out/sweep"), run_case, BatchOptions(workers=2))

`DIR/<run-id>/` is a run folder as `orthosim run` leaves it, plus `case.toml`, the exact case that
ran. A run counts as done when `orthosim.runtime.runfolder.read_finished_run` accepts its folder and its
run.json names this variant's case text and detector; the same command after an interruption
(Ctrl-C, a killed worker, a full disk) reuses those and runs the others again from a cleared
folder. One batch at a time writes into a folder (a lock). The sphere trees the runs need are
loaded or built here, once per distinct model, on every core, before any worker starts: workers
then only read the cache and never build the same tree twice at once.
"""

from __future__ import annotations

import fcntl
import shutil
import sys
import time
from collections import Counter
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterator, Sequence

from orthosim.runtime.options import RunOptions
from orthosim.runtime.outputfolder import clear_leftovers
from orthosim.storage.atomic import write_text
from orthosim.batch.plan import BatchError, Variant
from orthosim.batch.table import FAILED, OK, RunRow, finished_summary, write_table
from orthosim.batch.worker import RunCase, RunOutcome, RunTask

LOCK_FILE = ".batch.lock"
TABLE_EVERY_S = 2.0  # batch.json/csv rewritten at most this often while runs end (and always at the end)
TABLE_SHARE = 0.05  # ... and never more than this share of the parent's time


class _TableWriter:
    """Rewrites the table as runs end, throttled: each rewrite costs O(rows) (57 ms of CPU for 1000
    rows here), so rewriting after every run of a long batch would cost the parent O(rows^2) CPU,
    taken from the workers. The run folders, not the table, say which runs are finished (resume
    reads those), so a table a few seconds behind loses nothing."""

    def __init__(self, out_dir: Path, rows: dict, sweep_keys: Sequence[str], meta: dict):
        self.out_dir, self.rows, self.sweep_keys, self.meta = out_dir, rows, sweep_keys, meta
        self.last_end, self.cost = float("-inf"), 0.0

    def __call__(self, force: bool = False) -> None:
        now = time.perf_counter()
        if not force and now - self.last_end < max(TABLE_EVERY_S, self.cost / TABLE_SHARE):
            return
        write_table(self.out_dir, list(self.rows.values()), self.sweep_keys, self.meta)
        self.last_end = time.perf_counter()
        self.cost = self.last_end - now


@dataclass(frozen=True)
class BatchOptions:
    """How a batch runs: local workers or a Dask scheduler, time limit, retries, and what each run is asked."""

    workers: int = 1
    run_timeout_s: float | None = None  # a run still going after this is stopped and fails
    retries: int = 1  # local pool: runs tried again after their worker process died
    scheduler: str | None = None  # a Dask scheduler's address: run there instead of locally
    run: RunOptions = RunOptions()  # what each run is asked (its detector: the variant's)
    prebuild_trees: bool = True
    progress: bool = True


@contextmanager
def batch_lock(out_dir: Path) -> Iterator[None]:
    """Hold DIR/.batch.lock for the batch: a second batch into the same folder is refused at once."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        fh = open(out_dir / LOCK_FILE, "a")
    except OSError as err:
        raise BatchError(out_dir, None, f"cannot be written ({err.strerror})", "give a writable --out folder") from None
    try:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise BatchError(out_dir, None, "another orthosim batch is writing into this folder",
                             "wait for it to finish, or give another --out") from None
        yield
    finally:
        fh.close()  # releases the lock


def prepare_run_dir(run_dir: Path, variant: Variant) -> Path:
    """An empty run folder holding the variant's case.toml (what a partial earlier run left is cleared)."""
    if run_dir.exists():
        shutil.rmtree(run_dir)
    write_text(run_dir / "case.toml", variant.case_text)
    return run_dir / "case.toml"


def prebuild_trees(case_files: Sequence[Path]) -> None:
    """Load or build, once each, the sphere trees of these cases' models (one case per distinct model)."""
    from orthosim.exchange.case import load_case
    from orthosim.collision import CollisionModel

    for path in case_files:
        CollisionModel.from_dentition(load_case(path).build_dentition())


class _Progress:
    """One bar over the batch (runs done, failed, frames per second, time left) on a terminal; a
    line per finished run otherwise (logs of CI jobs and cluster submissions)."""

    def __init__(self, total: int, reused: int, enabled: bool):
        self.total, self.done, self.failed, self.frames = total, 0, 0, 0
        self.started = time.perf_counter()
        self.enabled = enabled
        self.bar = None
        if enabled and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="run", desc=f"batch ({reused} done earlier)" if reused else "batch",
                            dynamic_ncols=True)

    def update(self, row: RunRow) -> None:
        self.done += 1
        self.failed += row.status == FAILED
        self.frames += row.frames or 0
        fps = self.frames / max(time.perf_counter() - self.started, 1e-9)
        if self.bar is not None:
            self.bar.set_postfix_str(f"{self.failed} failed, {fps:.1f} frames/s", refresh=False)
            self.bar.update(1)
        elif self.enabled:
            what = "ok" if row.status == OK else f"FAILED: {row.error}"
            print(f"[{self.done}/{self.total}] {row.run_id}: {what}", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run_batch(variants: Sequence[Variant], out_dir: Path, run_case: RunCase, options: BatchOptions,
              sweep_keys: Sequence[str] = ()) -> list[RunRow]:
    """Run every variant not finished earlier into out_dir/<run-id>/; return the table's rows
    (also in out_dir/batch.json and batch.csv, rewritten as runs end, every few seconds, and at the end)."""
    out_dir = Path(out_dir)
    rows = {v.run_id: RunRow.of(v) for v in variants}
    with batch_lock(out_dir):
        todo = []
        for v in variants:
            summary = finished_summary(out_dir / v.run_id, v)
            if summary is None:
                todo.append(v)
            else:
                clear_leftovers(out_dir / v.run_id)  # a kill during its swap may have left the earlier copy
                row = rows[v.run_id]
                row.status, row.reused = OK, True
                row.record(summary)
        meta = {"workers": options.workers, "scheduler": options.scheduler}
        table = _TableWriter(out_dir, rows, sweep_keys, meta)
        table(force=True)
        if not todo:
            return list(rows.values())
        try:
            case_files = {v.run_id: prepare_run_dir(out_dir / v.run_id, v) for v in todo}
        except OSError as err:
            raise BatchError(out_dir, None, f"cannot be written ({err.strerror})", "free space or give another --out") from None
        if options.scheduler is not None:
            from orthosim.batch.cluster import connect, run_cluster

            client = connect(options.scheduler)
            outcomes = run_cluster(client, todo, out_dir, run_case, options.run, options.run_timeout_s)
        else:
            from orthosim.batch.pool import run_local

            if options.prebuild_trees:
                firsts = {}
                for v in todo:
                    firsts.setdefault(v.model_key, case_files[v.run_id])
                prebuild_trees(list(firsts.values()))
            client = None
            tasks = [RunTask(v.run_id, str(case_files[v.run_id]), str(out_dir / v.run_id),
                             replace(options.run, detector=v.detector)) for v in todo]
            outcomes = run_local(tasks, run_case, options.workers, options.run_timeout_s, options.retries)
        progress = _Progress(len(todo), len(variants) - len(todo), options.progress)
        try:
            for outcome, attempts in outcomes:
                row = rows[outcome.run_id]
                _record(row, outcome, attempts, out_dir)
                table()
                progress.update(row)
        finally:
            outcomes.close()  # on Ctrl-C: stops the workers before the table is written
            progress.close()
            table(force=True)
            if client is not None:
                client.close()
    return list(rows.values())


def _record(row: RunRow, outcome: RunOutcome, attempts: int, out_dir: Path) -> None:
    row.attempts = attempts
    if outcome.ok:
        row.status, row.error = OK, None
        row.record(outcome.summary)
        if row.wall_s is None:
            row.wall_s = outcome.wall_s
    else:
        row.status, row.error = FAILED, outcome.error
    row.extra = {"worker": outcome.worker} if outcome.worker else {}
    if outcome.cpu_s is not None:
        row.extra["cpu_s"] = round(outcome.cpu_s, 3)
    if outcome.log.strip():
        try:
            write_text(out_dir / "logs" / f"{row.run_id}.log", outcome.log)
        except OSError:
            pass  # the run's own outputs and the table matter more than its log


def counts(rows: Sequence[RunRow]) -> Counter:
    c = Counter(r.status for r in rows)
    c["reused"] = sum(r.reused for r in rows)
    return c

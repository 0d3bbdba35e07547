"""Batch runs on a Dask distributed cluster (`orthosim batch --scheduler ADDRESS`).

Dask does the distributing; this module only turns runs into tasks and their results back into
run folders. Each task carries its case text and runs into a private folder on its worker
(`worker.execute_shipped`), and returns the folder's files, which are written here into
`DIR/<run-id>/`, run.json last, exactly as a local worker would have left them: the workers need
not see the batch folder. They need the orthosim package, offscreen GL (EGL or OSMesa), and read
access to the meshes a mesh-based case names (the parametric model needs none). A worker that dies mid-run is Dask's to
handle: the scheduler gives its task to another worker, and after
`distributed.scheduler.allowed-failures` deaths (3 by default) reports `KilledWorker`, which fails
that run only. `--run-timeout` on a cluster: the run is recorded as failed once it has been
processing that long, its task cancelled, and its worker restarted to stop the work.
"""

from __future__ import annotations

import hashlib
import json
import time
import uuid
from pathlib import Path
from dataclasses import replace
from typing import Iterator, Sequence

from orthosim.runtime.options import RunOptions
from orthosim.storage.atomic import write_bytes
from orthosim.runtime.runfolder import RUN_FILE
from orthosim.batch.plan import BatchError, Variant
from orthosim.batch.worker import RunCase, RunOutcome, execute_shipped

_POLL_S = 0.5


def connect(address: str):
    """A Dask client of the scheduler at `address`; BatchError when Dask is missing or unreachable."""
    try:
        from distributed import Client
    except ImportError:
        raise BatchError("--scheduler", None, "needs Dask distributed, which is not installed",
                         "pip install 'orthosim[cluster]'") from None
    try:
        return Client(address, timeout="20s")
    except (OSError, TimeoutError, ValueError) as err:
        raise BatchError("--scheduler", address, f"cannot reach the scheduler ({' '.join(str(err).split())})",
                         "start one with `dask scheduler` and give its tcp://HOST:PORT") from None


def write_shipped_run(run_dir: Path, files: dict[str, bytes]) -> None:
    """Write a run's files into run_dir, each atomically, run.json last (it marks the run finished),
    its case path pointing at run_dir/case.toml (the same bytes the worker ran)."""
    record = files.get(RUN_FILE)
    rewritten = {}
    for name, data in files.items():
        if name == RUN_FILE:
            continue
        if name == "metrics.json":
            metrics = json.loads(data)
            if "case_file" in metrics:
                metrics["case_file"] = str(run_dir / "case.toml")
                data = (json.dumps(metrics, indent=2) + "\n").encode()
                rewritten[name] = hashlib.sha256(data).hexdigest()
        write_bytes(run_dir / name, data)
    if record is not None:
        run = json.loads(record)
        run["case_file"] = str(run_dir / "case.toml")
        if isinstance(run.get("output_sha256"), dict):  # the checksum of what this side wrote (runfolder.read_finished_run)
            run["output_sha256"].update((k, v) for k, v in rewritten.items() if k in run["output_sha256"])
        write_bytes(run_dir / RUN_FILE, (json.dumps(run, indent=2) + "\n").encode())


def run_cluster(client, variants: Sequence[Variant], out_dir: Path, run_case: RunCase, options: RunOptions,
                run_timeout_s: float | None = None) -> Iterator[tuple[RunOutcome, int]]:
    """Yield (outcome, attempts) per variant as its task ends; the run's files are in out_dir by then."""
    from distributed import as_completed

    batch_tag = uuid.uuid4().hex[:8]  # task keys unique to this invocation (a resumed batch submits anew)
    futures = {}
    for v in variants:
        fut = client.submit(execute_shipped, run_case, v.run_id, v.case_text, replace(options, detector=v.detector),
                            key=f"orthosim-run-{v.run_id}-{batch_tag}", pure=False)
        futures[fut.key] = (fut, v)
    pending = as_completed([f for f, _ in futures.values()])
    started: dict[str, float] = {}
    try:
        while futures:
            for fut in pending.next_batch(block=False) if pending.has_ready() else []:
                if fut.key not in futures:  # cancelled for its time limit, already reported
                    continue
                _, v = futures.pop(fut.key)
                try:
                    outcome, files = fut.result()
                except Exception as err:  # KilledWorker after repeated deaths, a lost scheduler...
                    yield RunOutcome(v.run_id, False, f"{type(err).__name__}: {' '.join(str(err).split())}", {}, "", 0.0), 1
                    continue
                if outcome.ok:
                    write_shipped_run(out_dir / v.run_id, files)
                yield outcome, 1
            if run_timeout_s is not None and futures:
                for key in _stop_overdue(client, futures, started, run_timeout_s):
                    _, v = futures.pop(key)
                    yield RunOutcome(v.run_id, False, f"stopped after {run_timeout_s:g} s (--run-timeout)", {}, "", 0.0), 1
            if futures:
                time.sleep(_POLL_S)
    finally:
        client.cancel([f for f, _ in futures.values()], force=True)


def _stop_overdue(client, futures: dict, started: dict[str, float], limit_s: float) -> list[str]:
    """Cancel tasks processing for longer than limit_s and restart their workers (a running task
    cannot be stopped any other way: it is a thread of the worker process)."""
    now = time.monotonic()
    where = {}
    for worker, keys in client.processing().items():
        for key in keys:
            where[key] = worker
            started.setdefault(key, now)
    overdue = [k for k in futures if k in where and now - started[k] > limit_s]
    if overdue:
        client.cancel([futures[k][0] for k in overdue], force=True)
        try:
            client.restart_workers(sorted({where[k] for k in overdue}))
        except Exception:  # e.g. a worker without a nanny: the run goes on there, its result is ignored
            pass
    return overdue

"""Batch rendering: many runs and parameter sweeps, on every core or on a Dask cluster (`orthosim batch`).

`plan` turns cases, detectors and `--set` sweeps into validated variants; `execute` runs them
into one folder (resumable, one lock, trees built once); `pool` is the local process pool,
`cluster` the Dask runner, `worker` what either does around one run, `table` the batch.json and
batch.csv rows. None of it draws: the function that runs one case (`orthosim.cli.run.run_for_batch`,
which renders) is handed in by the composition root; the animations-per-minute figure is
`orthosim_bench.batch`.
"""

from orthosim.batch.execute import BatchOptions, run_batch
from orthosim.batch.plan import BatchError, Sweep, Variant, parse_sweep, plan_batch
from orthosim.batch.table import RunRow

__all__ = ["BatchError", "BatchOptions", "RunRow", "Sweep", "Variant", "parse_sweep", "plan_batch", "run_batch"]

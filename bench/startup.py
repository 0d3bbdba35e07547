"""`orthosim bench`'s start-up figure: seconds from launching `orthosim run` to its first simulated step.

Measured from outside, as a user waits: the command is started as a new process (`--verbose`, which
prints "first step after ..." when the first step record reaches the drawing process), and the
clock runs from the launch to the moment that line arrives. The caches are warmed by one run
first (dentitions and sphere trees on disk, numba's compiled kernels), then `runs` runs are timed
and the median reported. Beside it, measured in the same way and the same minute so that the
machine's load can be read off: a bare interpreter start and the import of the simulation modules.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from orthosim_bench.subruns import SubRunFailed, exit_failure

TARGET_S = 0.8  # issue 42: launch to first step, warm, on two cores
_FIRST_STEP = "first step after"


def _timed_run(case: Path, out_dir: Path, size: str) -> tuple[float, float]:
    """(seconds to the first-step line, seconds to the end) of one `orthosim run`, from its launch."""
    cmd = [sys.executable, "-c", "from orthosim.cli import entry; entry()", "run", str(case), "--out", str(out_dir),
           "--verbose", "--size", size, "--frames-per-step", "1"]
    env = dict(os.environ)  # ORTHOSIM_GL / PYOPENGL_PLATFORM: the backend this bench chose
    started = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    first = None
    lines = []
    for line in proc.stderr:
        lines.append(line)
        if first is None and line.startswith(_FIRST_STEP):
            first = time.perf_counter() - started
    code = proc.wait()
    if code != 0:
        raise SubRunFailed("startup", exit_failure("startup", "orthosim run", code, "".join(lines)).why)
    if first is None:
        raise SubRunFailed("startup", f"orthosim run exited with 0 without printing '{_FIRST_STEP}' (--verbose)")
    return first, time.perf_counter() - started


def _timed_python(code: str) -> float:
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", code], stderr=subprocess.PIPE)
    if done.returncode != 0:
        raise SubRunFailed("startup", exit_failure("startup", f"python -c {code!r}", done.returncode, done.stderr).why)
    return time.perf_counter() - started


def startup_timings(case: str | Path, runs: int = 3, size: str = "160x120") -> dict:
    """{"startup_s": median seconds to the first step over `runs` warm runs, ...} (see the module doc)."""
    case = Path(case)
    with tempfile.TemporaryDirectory(prefix="orthosim-startup-") as tmp:
        _timed_run(case, Path(tmp) / "warm", size)  # fills every cache
        firsts, totals, interpreter, imports = [], [], [], []
        for i in range(runs):  # interleaved, so that each figure sees the same load
            interpreter.append(_timed_python("pass"))
            imports.append(_timed_python("import orthosim.movement.simulation"))
            first, total = _timed_run(case, Path(tmp) / f"run{i}", size)
            firsts.append(first)
            totals.append(total)
    return {
        "case": case.name,
        "startup_s": statistics.median(firsts),
        "startup_s_runs": firsts,
        "target_s": TARGET_S,
        "run_total_s": statistics.median(totals),
        "python_start_s": statistics.median(interpreter),
        "import_simulation_s": statistics.median(imports),
        "load_avg_1min": os.getloadavg()[0],
        "note": "from launching `orthosim run` to its first step record reaching the drawing process, warm caches",
    }

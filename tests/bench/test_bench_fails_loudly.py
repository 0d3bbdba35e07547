"""`orthosim bench` fails loudly: a sub-run that fails or is refused leaves its figure null, is
named in one line with why, and the bench exits 1; the long-run memory figure asks for a run the
case ranges allow."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from orthosim.exchange.case import DEFAULT_CASE, RANGES, load_case
from orthosim_bench.memory import _case_with_steps, memory_timings
from orthosim_bench.startup import startup_timings
from orthosim_bench.subruns import guarded

ROOT = Path(__file__).resolve().parents[2]


def test_the_long_memory_run_is_a_case_the_ranges_allow(tmp_path):
    long_case = load_case(_case_with_steps(DEFAULT_CASE, 10_000, tmp_path))  # refused here if out of range
    assert long_case.steps == 10_000
    assert long_case.duration_days <= RANGES["duration_days"][1]
    assert long_case.step_days < load_case(DEFAULT_CASE).step_days  # shorter steps, not impossible days


def test_a_refused_start_up_run_leaves_the_figure_null_and_says_why(tmp_path):
    failures = []
    figure = guarded("startup", failures, lambda: startup_timings(tmp_path / "no_such_case.toml", runs=1))
    assert figure is None
    (failure,) = failures
    assert failure.figure == "startup"
    assert "orthosim run exited with 2" in failure.why and "no_such_case.toml" in failure.why
    assert failure.line().startswith("bench: failed: startup: ")


@pytest.mark.slow  # a 4-step run in a child process
def test_a_refused_memory_run_leaves_its_figure_null_and_the_other_measured(tmp_path):
    record = memory_timings(DEFAULT_CASE, steps=4, frames=30, size=(8, 8), work_dir=tmp_path)  # 8x8: refused by --size
    assert record["run_10k_steps_no_render_mb"] > 0 and record["meets_target"]["run_10k_steps_no_render"] is not None
    assert record["render_2000_frames_mb"] is None and record["render_2000_frames_resident_mb"] is None
    assert record["meets_target"]["render_2000_frames"] is None  # never met without a run
    (failure,) = record["failures"]
    assert failure["figure"] == "render_2000_frames_mb"
    assert "exited with 2" in failure["why"] and "--size" in failure["why"]


@pytest.mark.slow  # a whole (small) bench run, minutes on a loaded two-core machine
def test_a_failing_sub_run_fails_the_bench(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")  # the report's runs are asked to go inside a file: each `orthosim run` refuses
    out = tmp_path / "bench.json"
    argv = [sys.executable, "-c", "from orthosim.cli import entry; entry()", "bench", "--out", out, "--size", "64x48",
            "--frames", "2", "--warmup", "1", "--markers", "10", "--memory-frames", "0", "--no-simulate",
            "--no-tree-build", "--no-startup", "--no-staging", "--no-batch", "--no-scan", "--no-memory",
            "--no-backends", "--report-runs", blocker / "runs"]
    env = {**os.environ, "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "osmesa")}
    done = subprocess.run([str(a) for a in argv], cwd=ROOT, env=env, capture_output=True, text=True, timeout=1800)
    assert done.returncode == 1, done.stderr[-2000:]
    assert "Traceback" not in done.stderr
    failed = [line for line in done.stderr.splitlines() if line.startswith("bench: failed: ")]
    assert len(failed) == 1 and failed[0].startswith("bench: failed: report: orthosim run ")
    assert "exited with 2" in failed[0] and "cannot be created" in failed[0]  # the run's own one line, shortened
    record = json.loads(out.read_text())  # the record is still written, the failed figure null
    assert record["report"] is None and record["report_s"] is None and record["meets_target"]["report"] is None
    assert [f["figure"] for f in record["failures"]] == ["report"]
    assert record["fps"]["render"] > 0  # the figures that ran are kept

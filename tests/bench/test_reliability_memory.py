"""Peak memory of long runs (`orthosim_bench.memory`): measured on a fresh child process tree, the
measuring process's own memory never counted, every process of the run's tree counted."""

from __future__ import annotations

import sys
import textwrap

import pytest

from orthosim.exchange.case import DEFAULT_CASE
from orthosim_bench.memory import TARGET_MB, measure_peak_memory, memory_timings

MB = 2 ** 20

# a child that holds 120 MB and starts a grandchild holding 120 MB at the same time, then both exit
_TWO_PROCESSES = textwrap.dedent("""
    import subprocess, sys, time
    held = b"\\x01" * (120 * 2 ** 20)
    grandchild = subprocess.Popen([sys.executable, "-c",
                                   "import time; held = b'\\\\x01' * (120 * 2 ** 20); time.sleep(2.0)"])
    time.sleep(2.0)
    grandchild.wait()
""")


def test_peak_memory_sums_the_whole_process_tree_and_not_the_measuring_process():
    ballast = b"\x01" * (400 * MB)  # held by this process while it measures: must not count
    peak = measure_peak_memory([sys.executable, "-c", _TWO_PROCESSES], interval_s=0.02)
    assert len(ballast) == 400 * MB
    assert peak.exit_code == 0 and peak.processes_seen >= 2
    assert 120 < peak.largest_process_peak_mb < 200  # one process's own high-water mark
    assert 240 <= peak.tree_rss_sampled_peak_mb < 360  # both at once, without the 400 MB here
    assert peak.peak_mb >= peak.largest_process_peak_mb
    assert 240 <= peak.peak_mb < 360  # two processes' own pages: the headline counts both
    assert 240 <= peak.tree_private_dirty_peak_mb < 360  # written by each: private to each


# a child that holds 150 MB, then forks: the forked copy shares those pages until it writes them
_FORKED = textwrap.dedent("""
    import os, time
    import numpy as np
    held = np.ones(150 * 2 ** 20, np.uint8)  # written once, in place
    pid = os.fork()
    time.sleep(2.5)
    if pid == 0:
        os._exit(0)
    os.waitpid(pid, 0)
""")


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.skipif(sys.platform != "linux", reason="/proc")
def test_pages_a_forked_child_shares_with_its_parent_count_once_in_the_headline_and_twice_in_summed_rss():
    peak = measure_peak_memory([sys.executable, "-c", _FORKED], interval_s=0.05, unique_interval_s=0.2)
    assert peak.exit_code == 0 and peak.processes_seen >= 2
    assert peak.tree_rss_sampled_peak_mb >= 300  # 150 MB in each process's RSS
    assert 150 <= peak.tree_pss_sampled_peak_mb < 250  # split between the two
    if peak.tree_unique_sampled_peak_mb is None:  # page frames hidden (not root): the headline is the PSS
        assert peak.peak_measure == "PSS"
    else:
        assert peak.peak_measure == "unique pages"
        assert 150 <= peak.tree_unique_sampled_peak_mb < 250
    assert peak.peak_mb < 250
    assert peak.tree_private_dirty_peak_mb < 250  # the held pages, once shared with the fork, are never counted twice


def test_a_run_past_its_time_limit_is_killed_and_says_so():
    peak = measure_peak_memory([sys.executable, "-c", "import time; time.sleep(60)"], timeout_s=1.0)
    assert peak.exit_code == -9 and peak.wall_s < 30


@pytest.mark.slow
def test_the_bench_record_measures_a_long_run_and_a_drawn_run_in_child_processes(tmp_path):
    record = memory_timings(DEFAULT_CASE, steps=4, frames=30, size=(160, 120), work_dir=tmp_path)
    assert record["run_no_render"]["exit_code"] == 0 and record["render"]["exit_code"] == 0
    assert record["run_no_render"]["steps"] == 4 and record["render"]["frames"] >= 30
    assert record["render"]["processes_seen"] >= 2  # the simulation child beside the drawing process
    for key in ("run_10k_steps_no_render_mb", "render_2000_frames_mb", "render_2000_frames_rss_mb",
                "render_2000_frames_pss_mb"):
        assert 50 < record[key] < 5000  # an interpreter with numpy, trimesh, FCL: tens of MB at least
    assert record["render_2000_frames_resident_mb"] < record["render_2000_frames_rss_mb"]  # the fork's shared pages once
    assert record["render_2000_frames_mb"] <= record["render_2000_frames_uss_mb"] <= record["render_2000_frames_rss_mb"]
    assert record["target_mb"] == TARGET_MB
    assert record["meets_target"]["run_10k_steps_no_render"] == (record["run_10k_steps_no_render_mb"] < TARGET_MB)
    assert list(tmp_path.iterdir()) == []  # the runs' folders are removed

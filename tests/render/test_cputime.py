"""CPU per frame by thread and child process (`orthosim_render.cputime`, the bench's end-to-end accounting)."""

import subprocess
import sys
import threading
import time

import pytest

from orthosim_render.cputime import cpu_ms_per_frame, cpu_snapshot

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")


def _spin(seconds: float, done: threading.Event, release: threading.Event):
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass
    done.set()
    release.wait(10)  # a thread's CPU is read while it lives, as the bench's threads do


def test_cpu_is_counted_per_named_thread_and_per_child_process():
    spin = ("import sys, time\nprint('ready', flush=True)\nsys.stdin.readline()\nt = time.process_time()\n"
            "while time.process_time() - t < 0.3: pass\nprint('spun', flush=True)\ntime.sleep(30)")
    child = subprocess.Popen([sys.executable, "-c", spin], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    done, release = threading.Event(), threading.Event()
    try:
        assert child.stdout.readline().strip() == "ready"  # the child's start-up, before the first snapshot
        before = cpu_snapshot()
        child.stdin.write("go\n")
        child.stdin.flush()
        worker = threading.Thread(target=_spin, args=(0.3, done, release), name="encoder-0")
        worker.start()
        done.wait(30)
        assert child.stdout.readline().strip() == "spun"
        after = cpu_snapshot()
    finally:
        release.set()
        child.kill()
        child.wait()
    per_frame = cpu_ms_per_frame(before, after, frames=10)
    assert per_frame["encoder"] == pytest.approx(30.0, abs=6.0)  # 300 ms over 10 frames, the thread's own name less its number
    assert per_frame["simulation child"] == pytest.approx(30.0, abs=6.0)  # a Python child process
    assert per_frame.get("main", 0.0) < 10.0  # the main thread slept
    assert per_frame["total"] == pytest.approx(sum(v for k, v in per_frame.items() if k != "total"))


def test_a_child_that_ends_between_the_snapshots_is_still_counted():
    """The simulation child sends its last step and exits while the drawing finishes: its CPU in
    the window counts once it has been waited for, under its own name."""
    spin = ("import sys, time\nprint('ready', flush=True)\nsys.stdin.readline()\nt = time.process_time()\n"
            "while time.process_time() - t < 0.4: pass\n")
    child = subprocess.Popen([sys.executable, "-c", spin], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                             text=True)
    assert child.stdout.readline().strip() == "ready"
    before = cpu_snapshot()
    child.stdin.write("go\n")
    child.stdin.flush()
    child.wait(30)  # ended and waited for: gone from /proc
    after = cpu_snapshot()
    per_frame = cpu_ms_per_frame(before, after, frames=10)
    assert per_frame["simulation child"] == pytest.approx(40.0, abs=8.0)  # 400 ms over 10 frames
    assert per_frame["total"] == pytest.approx(sum(v for k, v in per_frame.items() if k != "total"))


def test_no_snapshot_means_no_figures():
    assert cpu_ms_per_frame(None, cpu_snapshot(), 10) is None

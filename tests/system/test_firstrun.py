"""A long first step says what it prepares, in one line on stderr, once, also when stderr is not a
terminal; a warm one says nothing (`orthosim.system.firstrun`)."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import textwrap
import threading

from orthosim.system import firstrun


class _Watched(io.StringIO):
    """A stream that tells when something was written to it (so the test waits on the event, not a clock)."""

    def __init__(self):
        super().__init__()
        self.written = threading.Event()

    def write(self, text):
        self.written.set()
        return super().write(text)


def _fresh_process_state(monkeypatch):
    """What a fresh `orthosim` process starts with: nothing said yet, neither hushed nor kept to one
    thread (a batch test that ran `run_for_batch` on one core in this pytest worker leaves it so)."""
    monkeypatch.setattr(firstrun, "_said", set())
    monkeypatch.setattr(firstrun, "_hushed", [])
    monkeypatch.setattr(firstrun, "_one_thread", [])


def test_a_step_still_running_after_the_threshold_says_what_it_prepares_once(monkeypatch):
    stream = _Watched()
    monkeypatch.setattr(sys, "stderr", stream)
    _fresh_process_state(monkeypatch)
    for _ in range(2):
        with firstrun.preparing("the sphere trees of 3 tooth shapes", after_s=0.01):
            assert stream.written.wait(120)  # the line comes while the step still runs
    assert stream.getvalue() == ("orthosim: preparing the sphere trees of 3 tooth shapes "
                                 "(once: kept in the cache for later runs)\n")


def test_a_step_that_ends_before_the_threshold_says_nothing(monkeypatch):
    stream = _Watched()
    monkeypatch.setattr(sys, "stderr", stream)
    _fresh_process_state(monkeypatch)
    with firstrun.preparing("the teeth of this model", after_s=600):
        pass
    assert stream.getvalue() == ""


# a kernel defined in a module of its own (numba caches beside, or in NUMBA_CACHE_DIR), called once
_KERNEL = textwrap.dedent("""
    from numba import njit

    @njit(cache=True)
    def triangle_area(a, b, c):
        return 0.5 * abs((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
""")
_CALL = textwrap.dedent("""
    import numpy as np
    from orthosim.system import firstrun
    firstrun.NOTICE_AFTER_S = 0.0  # any compile says so, however short
    firstrun.announce_compiles()
    from kernel import triangle_area
    triangle_area(np.zeros(2), np.array([1.0, 0.0]), np.array([0.0, 1.0]))
""")


def test_a_kernel_compiled_for_this_machine_says_so_and_one_loaded_from_the_cache_does_not(tmp_path):
    (tmp_path / "kernel.py").write_text(_KERNEL)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache"), "PYTHONPATH": str(tmp_path)}

    def stderr_of_a_run() -> str:  # stderr is a pipe here, not a terminal
        done = subprocess.run([sys.executable, "-c", _CALL], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=600)
        assert done.returncode == 0, done.stderr
        return done.stderr

    first, second = stderr_of_a_run(), stderr_of_a_run()
    assert first.splitlines() == ["orthosim: preparing the compiled kernels for this machine "
                                  "(once: kept in the cache for later runs)"]
    assert second == ""

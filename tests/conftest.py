"""Suite-wide: tests marked `real_data` read the Open-Full-Jaw teeth found by `orthosim.exchange.shareddata`.

They are skipped, with the folder named, when the data is absent, and the run's summary says how
many of them ran and how many were skipped, so a clone without `../shared` cannot pass silently on
the parametric teeth alone.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

# The step guard and the goldens are bit-exact, so the suite computes with the same arithmetic on
# every x86-64 machine: numpy's AVX-512 loops (exp, log, ...) round differently from the libm path
# other CPUs take (numpy issue #23523), and OpenBLAS picks its kernels (and so its summation order)
# by CPU. Off AVX-512 and on OpenBLAS's Haswell kernels, an AVX-512 machine computes as an AVX2 one.
# Set before numpy loads (dev.sh test exports the same); child processes inherit them.
REFERENCE_ARITHMETIC = {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL "
                                                    "AVX512_ICL AVX512_SPR",
                        "OPENBLAS_CORETYPE": "Haswell"}
for _name, _value in REFERENCE_ARITHMETIC.items():
    os.environ.setdefault(_name, _value)

import pytest  # noqa: E402

from orthosim.exchange.shareddata import OPEN_FULL_JAW, shared_data_dir
from orthosim_render.offscreen_backend import ENV, probe_osmesa

# The goldens (tests/golden/) were drawn through OSMesa, and a golden is compared exactly only with
# frames drawn through its own backend: where OSMesa is present, the suite draws through it (unless
# ORTHOSIM_GL says otherwise), else through `auto`'s EGL, the goldens then compared within tolerance.
# tests/render/test_gl_backends.py draws through each backend in child processes.
if not os.environ.get(ENV) and not os.environ.get("PYOPENGL_PLATFORM") and probe_osmesa():
    os.environ[ENV] = "osmesa"

_REAL_DATA = shared_data_dir() / OPEN_FULL_JAW
# The fast tier (`-m "not slow"`) is what a developer runs between edits: a test that takes longer
# than this (set-up and call, on a quiet two-core machine) is marked `slow`; the summary names the
# fast tier's tests that went over it in this session
FAST_TEST_BUDGET_S = 2.0
_fast_seconds: dict[str, float] = {}
_outcomes: dict[str, str] = {}
_damaged_entries: dict[str, int] = {}  # kind of cache entry -> damaged copies a test loaded (tests/storage/test_damaged_entries.py)
_edited_certificates: dict[str, int] = {}  # kind of certified figure -> edited certificates verify was shown (tests/staging/)


# How this pytest process started to handle Ctrl-C and SIGTERM (a worker fresh from pytest-xdist:
# Python's defaults). A child process inherits an ignored signal across exec, so a test that left
# SIGINT ignored here made later tests' `orthosim run` children ignore Ctrl-C and SIGTERM alike.
_START_SIGNALS = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}


def _restore_signals(when: str, nodeid: str) -> None:
    for sig, handler in _START_SIGNALS.items():
        if signal.getsignal(sig) is not handler:
            warnings.warn(f"{nodeid}: {sig.name} found changed {when} the test; set back as this process started")
            signal.signal(sig, handler)


@pytest.fixture(autouse=True)
def _signals_as_the_process_started(request):
    """Each test starts, and leaves, with the signal dispositions this process started with; one
    whose set-up or call changed them is named in a warning."""
    _restore_signals("before", request.node.nodeid)
    yield
    _restore_signals("after", request.node.nodeid)


@pytest.fixture
def damage_tally(request) -> dict[str, int]:
    """Where a test counts the damaged files it tried; the run's summary prints the counts. They
    travel with the test's teardown report (its user properties), so pytest-xdist's controller,
    which prints the summary, receives them from its workers."""
    tally: dict[str, int] = {}
    yield tally
    request.node.user_properties.append(("damaged_entries", dict(tally)))


@pytest.fixture
def edit_tally(request) -> dict[str, int]:
    """Where a test counts the edited certificates it showed `stage verify`'s comparison, by kind of
    figure edited; the run's summary prints the counts (carried as `damage_tally`'s are)."""
    tally: dict[str, int] = {}
    yield tally
    request.node.user_properties.append(("edited_certificates", dict(tally)))


def pytest_sessionstart(session):
    """Once per pytest-xdist session, in the controller before it starts its workers: the numba
    kernels compiled in one process (`tests/numba_warmup.py`), so that the many processes the
    workers start load them instead of each compiling them at once (a run without workers
    compiles what it needs as it goes, and skips this)."""
    config = session.config
    if hasattr(config, "workerinput") or config.option.collectonly or not getattr(config.option, "numprocesses", None):
        return
    t = time.perf_counter()
    done = subprocess.run([sys.executable, str(Path(__file__).with_name("numba_warmup.py"))], capture_output=True, text=True)
    outcome = "compiled or loaded" if done.returncode == 0 else f"warm-up failed (exit {done.returncode}): {done.stderr.strip()[-300:]}"
    session.config._orthosim_warmup = f"numba kernels {outcome} in {time.perf_counter() - t:.1f} s before the tests"


def pytest_collection_modifyitems(items):
    """The modules marked heavy_setup, then those holding long tests (marked slow), then the rest,
    each module's tests kept together in their own order (a module's shared set-up is built once,
    not again each time its tests resume): on pytest-xdist's workers the long ones start at once and
    the short ones fill in around them, instead of one worker finishing a long test alone at the end."""
    has_slow = {item.module.__name__ for item in items if item.get_closest_marker("slow") is not None}
    # `dev.sh test` keeps each module on one worker (--dist loadscope): a module whose tests share
    # one costly set-up is the largest unit of work, so those go first of all
    grouped = {item.module.__name__ for item in items if item.get_closest_marker("heavy_setup") is not None}
    items.sort(key=lambda item: (item.module.__name__ not in grouped, item.module.__name__ not in has_slow))


def pytest_runtest_setup(item):
    if item.get_closest_marker("real_data") and not _REAL_DATA.is_dir():
        pytest.skip(f"real-tooth data not found at {_REAL_DATA} (set ORTHOSIM_SHARED_DATA or put shared/ beside the repository)")


def pytest_runtest_logreport(report):
    """Counted from the reports (in the one process, or in pytest-xdist's controller, which receives
    every worker's reports with their markers among the keywords)."""
    if report.when in ("setup", "call") and "slow" not in report.keywords:
        _fast_seconds[report.nodeid] = _fast_seconds.get(report.nodeid, 0.0) + report.duration
    if report.when == "teardown":
        for name, tally in report.user_properties:
            counts = {"damaged_entries": _damaged_entries, "edited_certificates": _edited_certificates}.get(name)
            for kind, n in tally.items() if counts is not None else ():
                counts[kind] = counts.get(kind, 0) + n
    if "real_data" in report.keywords and (report.when == "call" or report.skipped):
        if hasattr(report, "wasxfail"):  # a known failure that ran (pytest reports it as skipped)
            _outcomes[report.nodeid] = "xfailed" if report.skipped else "passed"
        else:
            _outcomes[report.nodeid] = "skipped" if report.skipped else ("failed" if report.failed else "passed")


def pytest_terminal_summary(terminalreporter):
    ran = sum(v != "skipped" for v in _outcomes.values())
    skipped = sum(v == "skipped" for v in _outcomes.values())
    terminalreporter.write_line(f"real-data tests ({_REAL_DATA}): {ran} ran, {skipped} skipped")
    warmup = getattr(terminalreporter.config, "_orthosim_warmup", None)
    if warmup:
        terminalreporter.write_line(warmup)
    over = sorted((s, n) for n, s in _fast_seconds.items() if s > FAST_TEST_BUDGET_S)
    if over:
        terminalreporter.write_line(f"fast-tier tests over the {FAST_TEST_BUDGET_S:.0f} s budget (mark them slow, or make "
                                    f"them faster): " + ", ".join(f"{n} {s:.1f} s" for s, n in reversed(over)))
    if _damaged_entries:
        tried = ", ".join(f"{kind} {n}" for kind, n in sorted(_damaged_entries.items()))
        terminalreporter.write_line(f"damaged cache entries tried: {sum(_damaged_entries.values())} ({tried})")
    if _edited_certificates:
        tried = ", ".join(f"{kind} {n}" for kind, n in sorted(_edited_certificates.items()))
        terminalreporter.write_line(f"edited certificates tried: "
                                    f"{sum(_edited_certificates.values())} ({tried})")

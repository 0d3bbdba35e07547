"""Suite-wide: tests marked `real_data` read the Open-Full-Jaw teeth found by `orthosim.exchange.shareddata`.

They are skipped, with the folder named, when the data is absent, and the run's summary says how
many of them ran and how many were skipped, so a clone without `../shared` cannot pass silently on
the parametric teeth alone.
"""

from __future__ import annotations

import os

import pytest

from orthosim.exchange.shareddata import OPEN_FULL_JAW, shared_data_dir
from orthosim_render.glbackend import ENV, probe_osmesa

# The goldens (tests/golden/) were drawn through OSMesa, and a golden is compared exactly only with
# frames drawn through its own backend: where OSMesa is present, the suite draws through it (unless
# ORTHOSIM_GL says otherwise), else through `auto`'s EGL, the goldens then compared within tolerance.
# tests/test_gl_backends.py draws through each backend in child processes.
if not os.environ.get(ENV) and not os.environ.get("PYOPENGL_PLATFORM") and probe_osmesa():
    os.environ[ENV] = "osmesa"

_REAL_DATA = shared_data_dir() / OPEN_FULL_JAW
_outcomes: dict[str, str] = {}


def pytest_runtest_setup(item):
    if item.get_closest_marker("real_data") and not _REAL_DATA.is_dir():
        pytest.skip(f"real-tooth data not found at {_REAL_DATA} (set ORTHOSIM_SHARED_DATA or put shared/ beside the repository)")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if item.get_closest_marker("real_data") and (report.when == "call" or report.skipped):
        if hasattr(report, "wasxfail"):  # a known failure that ran (pytest reports it as skipped)
            _outcomes[item.nodeid] = "xfailed" if report.skipped else "passed"
        else:
            _outcomes[item.nodeid] = "skipped" if report.skipped else ("failed" if report.failed else "passed")


def pytest_terminal_summary(terminalreporter):
    ran = sum(v != "skipped" for v in _outcomes.values())
    skipped = sum(v == "skipped" for v in _outcomes.values())
    terminalreporter.write_line(f"real-data tests ({_REAL_DATA}): {ran} ran, {skipped} skipped")

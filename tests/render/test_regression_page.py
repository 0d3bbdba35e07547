"""The CI page: `pytest --orthosim-results DIR` on a user's project with two failing image checks.

The session runs in a child process on a small project in tmp_path, as a CI job would: its goldens
are drawn first, then three of its four checks see a changed dentition (tooth 13 drifts 0.4 mm
distally, in one check tolerated by `max_shift_px`; tooth 41 is gone). DIR/summary.json must list exactly those two with what changed, and
DIR/index.html must load in headless Chromium with no request, console error or broken image,
showing both explanations.
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest

from render_helpers import pytest_in

ROOT = Path(__file__).resolve().parents[2]

USER_TESTS = """
import os
from orthosim import load_case
from orthosim_render.frame_state import FrameState
from orthosim_render.frame import render_state
from orthosim_render.regression import DEFAULT_SIZE, RenderedFrame, gl_identity

DENT = load_case({case!r}).build_dentition()
CHANGE = os.path.exists("change")


def frame(state, view):
    image, labels = render_state(DENT, state, view, DEFAULT_SIZE, labels=True)
    return RenderedFrame(image, gl_identity(), labels)


def test_canine_position(orthosim_image_regression):
    poses = {{k: v.copy() for k, v in DENT.rest_poses().items()}}
    if CHANGE:  # 0.4 mm distal drift of 13
        poses[13][:3, 3] -= 0.4 * poses[13][:3, :3] @ DENT.teeth[13].mesial
    orthosim_image_regression.check(frame(FrameState(poses=poses), "right_buccal"))


def test_lower_incisors(orthosim_image_regression):
    extracted = frozenset({{41}}) if CHANGE else frozenset()
    orthosim_image_regression.check(frame(FrameState(poses=DENT.rest_poses(), extracted=extracted), "frontal"))


def test_canine_within_tolerance(orthosim_image_regression):
    poses = {{k: v.copy() for k, v in DENT.rest_poses().items()}}
    if CHANGE:  # the same drift, tolerated by label: it passes
        poses[13][:3, 3] -= 0.4 * poses[13][:3, :3] @ DENT.teeth[13].mesial
    orthosim_image_regression.check(frame(FrameState(poses=poses), "right_buccal"), max_shift_px=3)


def test_upper_arch(orthosim_image_regression):
    orthosim_image_regression.check(frame(FrameState(poses=DENT.rest_poses()), "maxillary_occlusal"))
"""


@pytest.fixture(scope="module")
def session_with_two_failures(tmp_path_factory):
    project = tmp_path_factory.mktemp("project")
    (project / "test_arch.py").write_text(textwrap.dedent(USER_TESTS.format(case=str(ROOT / "cases" / "normal_occlusion.toml"))))
    first = pytest_in(project, "test_arch.py")  # writes the goldens (each "new" check fails once)
    assert "4 failed" in first.stdout, first.stdout + first.stderr
    (project / "change").write_text("")
    results = project / "results"
    run = pytest_in(project, "test_arch.py", "--orthosim-results", str(results))
    return project, results, run


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_the_session_writes_a_summary_of_exactly_the_two_failures(session_with_two_failures):
    project, results, run = session_with_two_failures
    assert "2 failed, 2 passed" in run.stdout, run.stdout + run.stderr
    summary = json.loads((results / "summary.json").read_text())
    assert summary["failed"] == 2 and summary["regenerated"] == 0
    checks = {c["test"].split("::")[1]: c for c in summary["checks"]}
    assert set(checks) == {"test_canine_position", "test_lower_incisors"}
    canine = checks["test_canine_position"]["explanation"]
    (move,) = canine["changes"]
    assert move["subject"] == "tooth 13" and move["kind"] == "moved" and move["direction"].startswith("distally")
    assert checks["test_lower_incisors"]["explanation"]["text"] == "tooth 41 disappeared; 27 other teeth unchanged"
    assert checks["test_canine_position"]["figures"]["differing_pixels"] > 0
    # the assertion message says the same
    assert "what changed: tooth 41 disappeared; 27 other teeth unchanged" in run.stdout


def test_the_page_is_self_contained_and_loads_clean_in_headless_chromium(session_with_two_failures, tmp_path):
    from orthosim_render.report.browser import BrowserError, find_chromium, load_page

    _, results, _ = session_with_two_failures
    page = (results / "index.html").read_text()
    assert "tooth 41 disappeared" in page and "tooth 13 moved" in page
    assert "src=\"http" not in page and page.count("data:image/png;base64,") == 8  # golden, candidate, diff, what changed x 2
    try:
        find_chromium()
    except BrowserError:
        pytest.skip("headless Chromium is not installed")
    loaded = load_page(results / "index.html", window=(1400, 1500))
    assert loaded.problems == [] and loaded.images == 8
    (tmp_path / "page.png").write_bytes(loaded.screenshot_png)
    assert loaded.screenshot_png.startswith(b"\x89PNG")


def test_a_session_without_failures_still_writes_both_files(tmp_path):
    (tmp_path / "test_nothing.py").write_text("def test_nothing(orthosim_image_regression):\n    pass\n")
    r = pytest_in(tmp_path, "test_nothing.py", "--orthosim-results", str(tmp_path / "out"))
    assert r.returncode == 0, r.stdout + r.stderr
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["checks"] == []
    assert "Every image check matched" in (tmp_path / "out" / "index.html").read_text()


def test_results_pointing_at_a_file_is_refused_in_one_line(tmp_path):
    (tmp_path / "taken").write_text("")
    (tmp_path / "test_nothing.py").write_text("def test_nothing():\n    pass\n")
    r = pytest_in(tmp_path, "test_nothing.py", "--orthosim-results", str(tmp_path / "taken"))
    assert r.returncode == 4 and "--orthosim-results" in r.stderr and "is a file" in r.stderr


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_a_session_on_several_pytest_xdist_workers_writes_one_page_of_every_workers_failures(session_with_two_failures):
    """CI jobs run their tests on every core: each worker hands its checks to the controller, which
    writes the one page (no worker's page overwrites another's, no part file is left behind)."""
    pytest.importorskip("xdist")
    project, _, _ = session_with_two_failures
    results = project / "results_xdist"
    run = pytest_in(project, "test_arch.py", "-n", "2", "--orthosim-results", str(results))
    assert "2 failed, 2 passed" in run.stdout, run.stdout + run.stderr
    summary = json.loads((results / "summary.json").read_text())
    assert summary["failed"] == 2
    assert sorted(c["test"].split("::")[1] for c in summary["checks"]) == ["test_canine_position", "test_lower_incisors"]
    assert sorted(p.name for p in results.iterdir()) == ["index.html", "summary.json"]
    assert (results / "index.html").read_text().count("data:image/png;base64,") == 8


def test_a_damaged_worker_part_is_refused_in_one_line(tmp_path):
    from orthosim_render.imageerrors import ImageInputError
    from orthosim_render.report.regression_page import read_worker_part

    part = tmp_path / "gw0.json"
    part.write_text('{"format": 1, "checks": [{"test": "t"}]')  # truncated
    with pytest.raises(ImageInputError, match="damaged"):
        read_worker_part(part)


def test_an_interrupted_sessions_leftover_worker_part_is_not_merged_into_the_next_page(tmp_path):
    out = tmp_path / "out"
    stale = out / ".orthosim-worker-parts" / "gw0.json"
    stale.parent.mkdir(parents=True)
    stale.write_text("{}")  # what a killed worker may leave behind
    (tmp_path / "test_nothing.py").write_text("def test_nothing(orthosim_image_regression):\n    pass\n")
    r = pytest_in(tmp_path, "test_nothing.py", "--orthosim-results", str(out))
    assert r.returncode == 0, r.stdout + r.stderr
    assert json.loads((out / "summary.json").read_text())["checks"] == []
    assert sorted(p.name for p in out.iterdir()) == ["index.html", "summary.json"]

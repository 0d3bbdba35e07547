"""viewer.html in a real browser: headless Chromium (WebGL2 through SwiftShader) opens the page of
case 3's run and of the crowding staging from a file:// URL, with no network and no console error,
and at a given step and named view its per-tooth id picture agrees with orthosim's offscreen label
pass of the same step and view at 320x240: the same teeth visible, each centroid within 3 px.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from cli_helpers import orthosim
from render_helpers import case3_run
from orthosim_render.frame_state import FrameState
from orthosim_render.report.browser import NAMES
from orthosim_render.viewer_check import disagreements, label_picture, open_viewer

ROOT = Path(__file__).resolve().parents[2]
CASE3 = ROOT / "cases" / "case3_incisor_space_closure.toml"
CROWDING = ROOT / "cases" / "staging_lower_incisor_crowding.toml"
SIZE = (320, 240)
MAX_PX = 3.0

pytestmark = pytest.mark.slow  # Chromium, end-to-end runs


@pytest.fixture(scope="module", autouse=True)
def chromium():
    if not any(shutil.which(n) for n in NAMES):
        pytest.fail("headless Chromium is not installed: run `bash tools/dev.sh install`")


@pytest.fixture(scope="module")
def case3(tmp_path_factory):
    """Case 3 run by `orthosim run` and its step records (the same simulation, in process)."""
    return case3_run(tmp_path_factory.mktemp("case3"))


@pytest.fixture(scope="module")
def crowding(tmp_path_factory):
    """The crowding case staged by `orthosim stage`, and its plan."""
    from orthosim.staging.caseplan import plan_case
    from orthosim_render.viewer_page import staging_keyframes

    out = tmp_path_factory.mktemp("crowding") / "out"
    r = orthosim("stage", CROWDING, "--out", out, "--frames-per-stage", "1", "--size", "160x120")
    assert r.returncode == 0, r.stderr
    run = plan_case(CROWDING)
    return out, run.dentition, staging_keyframes(run)


@pytest.mark.parametrize("which, view", [("first", "frontal"), ("last", "frontal"), ("last", "maxillary_occlusal"),
                                         ("last", "right_buccal")])
def test_case3s_page_draws_each_tooth_where_the_frames_draw_it(case3, which, view):
    out, dentition, records, extracted = case3
    record = records[0] if which == "first" else records[-1]
    load = open_viewer(out / "viewer.html", step=record.step, view=view, size=SIZE)
    assert load.errors == []
    reference = label_picture(dentition, FrameState.from_step(record, extracted), view, SIZE)
    assert load.picture.visible(20) == reference.visible(20) and len(reference.visible(20)) >= 10
    assert disagreements(load.picture, reference, max_px=MAX_PX) == []


@pytest.mark.parametrize("view", ["frontal", "mandibular_occlusal"])
def test_the_crowding_stagings_page_draws_its_middle_stage_where_the_frames_draw_it(crowding, view):
    out, dentition, keyframes = crowding
    middle = keyframes[len(keyframes) // 2]
    load = open_viewer(out / "viewer.html", step=middle.step, view=view, size=SIZE)
    assert load.errors == []
    reference = label_picture(dentition, FrameState(poses=middle.poses, extracted=middle.hidden), view, SIZE)
    assert load.picture.visible(20) == reference.visible(20) and len(reference.visible(20)) >= 10
    assert disagreements(load.picture, reference, max_px=MAX_PX) == []


def test_a_moved_tooth_is_caught(case3):
    """The comparison fails when the page shows another step: the claim can fail."""
    out, dentition, records, extracted = case3
    load = open_viewer(out / "viewer.html", step=0, view="frontal", size=SIZE)
    shifted = {n: p.copy() for n, p in records[0].poses.items()}
    shifted[11][:3, 3] += [1.5, 0.0, 0.0]  # 1.5 mm toward the patient's left: several pixels at 320x240
    reference = label_picture(dentition, FrameState(poses=shifted, extracted=extracted), "frontal", SIZE)
    assert any(p.startswith("tooth 11:") for p in disagreements(load.picture, reference, max_px=MAX_PX))


def test_the_pages_open_offline_and_the_staging_page_embeds_its_viewer(case3, crowding):
    from orthosim_render.report.browser import load_page
    from orthosim_render.viewer_check import WEBGL_FLAGS

    for page in (case3[0] / "viewer.html", crowding[0] / "viewer.html"):
        load = open_viewer(page, test=False)
        assert load.errors == [] and load.drawn_ms is not None
        assert "http:" not in page.read_text() and "https:" not in page.read_text()
    index = load_page(crowding[0] / "index.html", extra_flags=WEBGL_FLAGS, screenshot=False)
    assert index.problems == [] and index.network_requests == []
    assert '<iframe src="viewer.html"' in (crowding[0] / "index.html").read_text()


def test_pointing_at_a_tooth_names_it_and_the_view_buttons_frame_the_presets(case3):
    """Hover: the tooltip names the tooth under the pointer (its FDI number and name); a view button
    frames that preset (the maxillary occlusal view hides the opposing arch, as the frames do)."""
    from orthosim_render.report.browser import load_page
    from orthosim_render.viewer_check import WEBGL_FLAGS

    probe = """(() => {
      const t = JSON.parse(document.documentElement.dataset.viewerTest).teeth["11"].centroid;
      const canvas = document.getElementById("view"), r = canvas.getBoundingClientRect();
      canvas.dispatchEvent(new PointerEvent("pointermove", {clientX: r.left + t[0] + 0.5, clientY: r.top + t[1] + 0.5}));
      const tip = document.getElementById("tooltip");
      const named = tip.hidden ? "" : tip.textContent;
      document.querySelector('button[data-view="maxillary_occlusal"]').click();
      return JSON.stringify({named, size: [r.width, r.height], opposing: document.getElementById("toggle-opposing").checked});
    })()"""
    page = load_page(case3[0] / "viewer.html", fragment="test&w=640&h=480&view=frontal&step=0", window=(640, 480 + 87),
                     extra_flags=WEBGL_FLAGS, screenshot=False, evaluate=probe)
    assert page.problems == []
    import json

    result = json.loads(page.value)
    assert result["size"] == [640, 480]  # the id picture was drawn at the canvas's own size
    assert result["named"] == "11: upper right central incisor"
    assert result["opposing"] is False

"""`orthosim report` as a reader meets it: a page that loads offline in a real browser with every
picture, a PDF with a section per case, and figures that are the runs' own."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from orthosim.movement.report import read_steps
from cli_helpers import orthosim as run_cli

ROOT = Path(__file__).resolve().parents[2]

CASE_A = """
[case]
name = "small extraction case"
[model]
kind = "parametric"
resolution = "coarse"
[treatment]
extractions = [14, 24, 34, 44]
duration_days = 4
step_days = 2
[wire]
type = "rectangular"
[[loads]]
teeth = [16, 26, 36, 46]
force_cN = 150
direction = "mesial"
movement = "translation"
"""

CASE_B = """
[case]
name = "small diastema case"
[model]
kind = "parametric"
resolution = "coarse"
diastema_mm = 1.0
[treatment]
duration_days = 4
step_days = 2
[wire]
type = "rectangular"
[[loads]]
teeth = [11, 21, 31, 41]
force_cN = 100
direction = "mesial"
movement = "translation"
"""

DETECTORS = ("circles", "continuous")


def orthosim(*args, cwd=ROOT):
    return run_cli(*args, cwd=cwd, timeout=1200)  # a report runs several cases


def chromium_required():
    from orthosim_render.report.browser import NAMES

    if not any(shutil.which(n) for n in NAMES):
        pytest.fail("headless Chromium is not installed: run `bash tools/dev.sh install` (it installs Debian's chromium)")


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory):
    """Two small cases, two detectors each, run and reported by one `orthosim report ... --pdf`."""
    chromium_required()
    tmp = tmp_path_factory.mktemp("report")
    (tmp / "case_a.toml").write_text(CASE_A)
    (tmp / "case_b.toml").write_text(CASE_B)
    out = tmp / "report"
    args = ["report", str(tmp / "case_a.toml"), str(tmp / "case_b.toml"), "--out", str(out), "--pdf", "--render",
            "--size", "320x240"]
    for d in DETECTORS:
        args += ["--detector", d]
    r = orthosim(*args)
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="module")
def report(report_dir):
    return json.loads((report_dir / "report.json").read_text())


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_report_json_figures_equal_the_metrics_of_the_runs(report):
    assert [c["name"] for c in report["cases"]] == ["small extraction case", "small diastema case"]
    for case in report["cases"]:
        assert case["detectors"] == list(DETECTORS)
        for det, shown in case["runs"].items():
            metrics = json.loads((Path(shown["run_dir"]) / "metrics.json").read_text())
            run = json.loads((Path(shown["run_dir"]) / "run.json").read_text())
            steps = list(read_steps(shown["run_dir"]))
            assert metrics["detector"] == det
            for key in ("steps", "total_distance_mm", "max_penetration_mm", "initial_penetration_mm", "collisions",
                        "distances"):
                assert shown[key] == metrics[key], key
            for n, t in metrics["teeth"].items():
                assert shown["teeth"][n] == {k: t[k] for k in ("moved_mm", "rotated_deg", "extracted", "root")}
            assert [p["total_mm"] for p in shown["totals_over_days"]] == [s["total_distance_mm"] for s in steps]
            assert [p["day"] for p in shown["totals_over_days"]] == [s["time_days"] for s in steps]
            assert case["largest_interpenetration_mm"][det] == metrics["max_penetration_mm"]
            assert case["throughput"][det]["fps"] == run["render"]["fps"]  # the run drew its frames (--render)
            touching = {tuple(sorted(p)) for s in steps for p in s["touching"]}
            assert {tuple(r["pair"]) for r in case["contacts"][det]} == touching
        # every crown vertex of every present tooth is in the distance map, before and after
        counts = {p: m["both"]["vertices"] for p, m in case["distance_map"].items()}
        assert len(set(counts.values())) == 1 and counts["initial"] > 0


def test_the_page_loads_offline_in_chromium_with_every_picture_and_no_console_error(report_dir, report):
    from PIL import Image

    from orthosim_render.report.browser import load_page

    page = load_page(report_dir / "index.html")
    assert page.problems == []
    poses = 1 + len(DETECTORS)
    per_case = poses * 3 + 1 + poses * 2 + 2  # contact areas, colour bar, distance maps, two plots
    assert page.images == len(report["cases"]) * per_case
    shot = np.asarray(Image.open(io.BytesIO(page.screenshot_png)).convert("RGB")).astype(int)
    assert shot.shape[0] > 500 and shot.shape[1] > 800
    # the pictures show: the renderer's dark slate background and lit enamel, not a blank page
    slate = np.all(np.abs(shot - [26, 28, 36]) < 12, axis=2).mean()
    enamel = ((shot.min(axis=2) > 150) & (shot[:, :, 0] - shot[:, :, 2] > 15)).mean()
    assert slate > 0.10 and enamel > 0.01, (slate, enamel)


def test_the_page_check_catches_a_console_error_and_a_missing_picture(tmp_path):
    from orthosim_render.report.browser import load_page

    chromium_required()
    (tmp_path / "bad.html").write_text('<!DOCTYPE html><html><body><img src="img/missing.png" alt="x">'
                                       '<script>console.error("a broken page")</script></body></html>')
    page = load_page(tmp_path / "bad.html", screenshot=False)
    assert any("a broken page" in e for e in page.console_errors)
    assert page.broken_images == ["img/missing.png"]
    assert any("missing.png" in e for e in page.failed_requests)


def test_the_pdf_has_one_section_per_case(report_dir, report):
    from pypdf import PdfReader

    pdf = PdfReader(report_dir / "report.pdf")
    texts = [p.extract_text() for p in pdf.pages]
    starts = []
    for case in report["cases"]:
        # a case's section starts on a page of its own, headed by its name
        starts.append(next(i for i, t in enumerate(texts) if t.lstrip().startswith(case["name"])))
    assert starts == sorted(starts) and len(set(starts)) == len(report["cases"])
    assert len(pdf.pages) >= len(report["cases"]) + 1
    for case, start in zip(report["cases"], starts):
        assert "Occlusal contact areas" in texts[start] and "Throughput" in "".join(texts[start:])


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_report_refuses_an_unfinished_run_one_from_another_version_and_a_damaged_one(report_dir, report, tmp_path):
    run = Path(report["cases"][0]["runs"]["continuous"]["run_dir"])
    unfinished = tmp_path / "unfinished"
    shutil.copytree(run, unfinished)
    (unfinished / "run.json").unlink()
    r = orthosim("report", "--from-runs", str(unfinished), "--out", str(tmp_path / "r1"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "run.json" in r.stderr and "Traceback" not in r.stderr
    foreign = tmp_path / "foreign"
    shutil.copytree(run, foreign)
    record = json.loads((foreign / "run.json").read_text())
    (foreign / "run.json").write_text(json.dumps({**record, "orthosim_version": "0.0.1"}))
    r = orthosim("report", "--from-runs", str(foreign), "--out", str(tmp_path / "r2"))
    assert r.returncode == 2 and "orthosim_version" in r.stderr and r.stderr.count("\n") == 1
    damaged = tmp_path / "damaged"  # one pose in steps.jsonl changed by a bit: refused, never drawn silently
    shutil.copytree(run, damaged)
    steps = bytearray((damaged / "steps.jsonl").read_bytes())
    steps[len(steps) // 2] ^= 0x01
    (damaged / "steps.jsonl").write_bytes(bytes(steps))
    r = orthosim("report", "--from-runs", str(damaged), "--out", str(tmp_path / "r3"))
    assert r.returncode == 2 and "steps.jsonl" in r.stderr and "is damaged" in r.stderr and r.stderr.count("\n") == 1
    assert not any((tmp_path / d / "index.html").exists() for d in ("r1", "r2", "r3"))


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_report_from_runs_gives_the_same_figures(report_dir, report, tmp_path):
    runs = [c["runs"][d]["run_dir"] for c in report["cases"] for d in DETECTORS]
    r = orthosim("report", "--from-runs", *runs, "--out", str(tmp_path / "again"), "--size", "320x240")
    assert r.returncode == 0, r.stderr
    again = json.loads((tmp_path / "again" / "report.json").read_text())
    for a, b in zip(report["cases"], again["cases"]):
        assert a["runs"] == b["runs"] and a["distance_map"] == b["distance_map"] and a["contacts"] == b["contacts"]

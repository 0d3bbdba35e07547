"""The clinical evidence table: every row's verdict held, the fit behind the "clinical" rate law, the page.

Each row of `orthosim/evidence/evidence.toml` is run on the model as `orthosim evidence` runs it
(coarse parametric model, monthly steps: seconds) and must land where `VERDICTS` says: inside
its published interval, or outside with the one-line reason the page shows. A new row needs its
verdict here; a change to the model that moves a row across its interval fails here. The
validation rows (not fitted) are the table's claim: at least 10 of them, at least 8 inside, and
every centre-of-resistance row among them and inside, predicted by the ligament from the root.
"""

from __future__ import annotations

import io
import json
import math
import shutil
from importlib import resources
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from cli_helpers import orthosim
from orthosim.evidence import load_evidence, run_evidence
from orthosim.errors import CaseError
from orthosim.mechanics.ratelaw import DAYS_PER_MONTH, PARAMETER_SETS, RateLaw

VERDICTS = {
    "monini2019_upper_canine_rate": "inside",
    "monini2019_lower_canine_rate": "inside",
    "ccd2018_upper_canine_rate": "outside",  # the law is fitted to Monini's slower canines
    "ccd2018_lower_canine_rate": "outside",  # likewise, and the bone factor to Monini's lower canine
    "theodorou2019_plateau_50_250": "inside",
    "theodorou2019_above_250": "outside",  # the law saturates: no faster above 250 cN
    "papageorgiou2005_cr_single_rooted": "inside",
    "papageorgiou2005_cr_single_rooted_real": "inside",
    "yoshida_upper_incisor_cr": "inside",
    "yoshida_upper_incisor_cr_real": "inside",
    "fea_upper_first_molar_cr": "inside",
    "fea_upper_first_molar_cr_real": "inside",
    "fea_upper_first_molar_cr_lingual": "inside",
    "fea_upper_first_molar_cr_lingual_real": "inside",
    "smith_burstone1984_controlled_tipping": "inside",
    "smith_burstone1984_controlled_tipping_real": "inside",
    "smith_burstone1984_translation": "inside",
    "smith_burstone1984_translation_real": "inside",
    "ccd2018_canine_retraction_molar_anchorage": "inside",
    "ccd2018_lower_canine_retraction_molar_anchorage": "outside",  # the lower molars stay under the threshold
    "ccd2018_canine_retraction_implant_anchorage": "inside",
    "becker2018_en_masse_anchorage_difference": "inside",
}
FITTED = {"monini2019_upper_canine_rate", "monini2019_lower_canine_rate", "theodorou2019_plateau_50_250",
          "ccd2018_canine_retraction_molar_anchorage", "becker2018_en_masse_anchorage_difference"}
ROWS = load_evidence()
EVIDENCE_SCHEMA = json.loads(resources.files("orthosim").joinpath("schema/evidence.schema.json").read_text())
PARAMETRIC = [r.id for r in ROWS if r.model == "parametric"]
REAL = [r.id for r in ROWS if r.model == "real"]


@pytest.fixture(scope="module")
def parametric_results():
    return {r.row.id: r for r in run_evidence(with_real=False, rows=tuple(r for r in ROWS if r.model == "parametric"))}


@pytest.fixture(scope="module")
def real_results():
    return {r.row.id: r for r in run_evidence(with_real=True, rows=tuple(r for r in ROWS if r.model == "real"))}


def test_every_row_of_the_table_has_a_verdict_held_here_and_the_table_has_every_topic():
    assert set(VERDICTS) == {r.id for r in ROWS}
    assert len(ROWS) >= 8
    assert {r.topic for r in ROWS} == {"rate", "rate vs force", "centre of resistance", "M/F", "anchorage"}


def test_the_table_claims_ten_validation_rows_eight_inside_and_every_centre_of_resistance_row_among_them():
    validation = [r for r in ROWS if not r.fitted]
    assert {r.id for r in ROWS if r.fitted} == FITTED
    assert len(validation) >= 10 and sum(VERDICTS[r.id] == "inside" for r in validation) >= 8
    centres = [r for r in ROWS if r.topic == "centre of resistance"]
    assert len({r.source for r in centres}) >= 3 and {r.model for r in centres} == {"parametric", "real"}
    assert all(not r.fitted and VERDICTS[r.id] == "inside" for r in centres)
    assert all(not r.fitted for r in ROWS if r.topic == "M/F")


def test_every_row_can_fail_a_finite_interval_around_a_published_number_no_wider_than_it():
    for r in ROWS:
        assert math.isfinite(r.mean) and r.low <= r.mean <= r.high, r.id
        assert r.high - r.low <= max(abs(r.mean), 1.0), r.id


@pytest.mark.slow  # a rate row simulates three months: over the fast tier's 2 s budget
def test_evidence_json_says_each_rows_role_and_counts_validation_apart_in_its_schema():
    from orthosim_render.evidence_page import evidence_json

    rows = tuple(r for r in ROWS if r.topic == "centre of resistance" or r.id == "monini2019_upper_canine_rate")
    results = run_evidence(with_real=True, rows=rows)
    data = evidence_json(results, "clinical")
    jsonschema.validate(data, EVIDENCE_SCHEMA)  # a skipped real row has simulated null
    assert [r["fitted"] for r in data["rows"]] == [r.row.fitted for r in results]
    ran = [r for r in results if r.status != "skipped"]
    assert data["validation"]["rows"] == len(rows) - 1
    assert data["validation"]["inside"] == sum(r.inside and not r.row.fitted for r in ran)
    assert data["calibration"] == {"rows": 1, "inside": 1, "outside": 0, "skipped": 0}


def test_the_fit_uses_exactly_the_rows_marked_fitted():
    from orthosim.evidence.calibration import fitted_rows

    assert {r.id for r in fitted_rows(ROWS)} == FITTED


@pytest.mark.parametrize("row_id", PARAMETRIC)
def test_a_row_on_the_parametric_model_keeps_its_verdict(parametric_results, row_id):
    result = parametric_results[row_id]
    assert math.isfinite(result.value)
    assert result.status == VERDICTS[row_id], (row_id, result.value, result.row.low, result.row.high, result.note)
    if result.status == "outside":
        assert result.row.outside and result.reason == result.row.outside  # the page's one-line reason


@pytest.mark.real_data
@pytest.mark.parametrize("row_id", REAL)
def test_a_row_on_the_real_patient_keeps_its_verdict(real_results, row_id):
    result = real_results[row_id]
    assert result.status == VERDICTS[row_id], (row_id, result.value, result.note)


def test_real_rows_are_skipped_not_failed_when_the_shared_data_is_absent(monkeypatch, tmp_path):
    monkeypatch.setenv("ORTHOSIM_SHARED_DATA", str(tmp_path))
    results = run_evidence(with_real=True, rows=tuple(r for r in ROWS if r.model == "real"))
    assert results and all(r.status == "skipped" and math.isnan(r.value) for r in results)


def test_a_lower_canine_moves_more_slowly_than_an_upper_one_under_the_same_spring(parametric_results):
    upper = parametric_results["monini2019_upper_canine_rate"].value
    lower = parametric_results["monini2019_lower_canine_rate"].value
    assert 0.1 < upper - lower < 0.25  # Monini 2019: 0.71 against 0.57 mm a month


def test_a_molar_held_by_a_mini_implant_does_not_move_and_a_molar_anchor_gives_way(parametric_results):
    assert parametric_results["ccd2018_canine_retraction_implant_anchorage"].value == 0.0
    assert parametric_results["ccd2018_canine_retraction_molar_anchorage"].value > 0.5


def test_the_clinical_constants_are_the_least_squares_fit_to_the_table():
    from orthosim.evidence.calibration import fit_clinical

    fit = fit_clinical()
    shipped = PARAMETER_SETS["clinical"]
    for name in ("threshold_cN", "saturation_cN", "max_rate_mm_per_day", "mandibular_bone_factor"):
        assert getattr(fit.law, name) == pytest.approx(getattr(shipped, name), rel=0.01), name
    assert all(abs(res) < 1.0 for _, _, _, res in fit.residuals)  # each fitted row within its half interval


def test_the_paper_set_keeps_the_replication_values_and_a_case_without_the_table_uses_it():
    from orthosim.exchange.case import CASES_DIR, load_case
    from orthosim.movement.model import MovementSettings

    assert PARAMETER_SETS["paper"] == RateLaw() == RateLaw(20.0, 150.0, 1.0 / 30.0, 200.0, 1.0)
    for name in ("case1_first_premolar_extraction", "case2_second_premolar_extraction", "case3_incisor_space_closure"):
        case = load_case(CASES_DIR / f"{name}.toml")
        assert MovementSettings.from_case(case).rate is PARAMETER_SETS["paper"]


def test_a_case_picks_the_clinical_set_and_may_override_one_constant(tmp_path):
    from orthosim import load_case
    from orthosim.movement.model import MovementSettings

    path = tmp_path / "c.toml"
    path.write_text('[model]\nresolution = "coarse"\n[[loads]]\nteeth = [13]\nforce_cN = 98\n'
                    '[biomechanics]\nparameters = "clinical"\nmax_rate_mm_per_month = 0.9\n')
    law = MovementSettings.from_case(load_case(path)).rate
    clinical = PARAMETER_SETS["clinical"]
    assert law.max_rate_mm_per_day * DAYS_PER_MONTH == pytest.approx(0.9)
    assert (law.threshold_cN, law.saturation_cN, law.mandibular_bone_factor) == (
        clinical.threshold_cN, clinical.saturation_cN, clinical.mandibular_bone_factor)


@pytest.mark.parametrize("table, field, words", [
    ('parameters = "fast"', "biomechanics.parameters", "use one of: paper, clinical"),
    ("threshold_cN = -3", "biomechanics.threshold_cN", "at least 0"),
    ("saturation_cN = 10", "biomechanics.saturation_cN", "must exceed the threshold"),
    ("mandibular_bone_factor = 9", "biomechanics.mandibular_bone_factor", "outside 0.25 to 4"),
    ("max_rate = 1", "biomechanics.max_rate", "unknown key"),
])
def test_a_bad_biomechanics_table_is_one_line_naming_the_file_and_field_with_exit_status_2(tmp_path, table, field, words):
    path = tmp_path / "bad.toml"
    path.write_text(f'[model]\nresolution = "coarse"\n[[loads]]\nteeth = [13]\nforce_cN = 98\n[biomechanics]\n{table}\n')
    done = orthosim("check", str(path))
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    section, key = field.split(".")
    assert len(lines) == 1 and str(path) in lines[0] and f"[{section}] {key}:" in lines[0] and words in lines[0], lines
    assert "Traceback" not in done.stderr


def test_a_damaged_evidence_table_names_the_file_and_the_row(tmp_path):
    text = Path(load_evidence.__defaults__[0]).read_text()
    ratio = next(i for i, r in enumerate(ROWS) if r.kind == "rate_ratio")
    bad = tmp_path / "evidence.toml"
    bad.write_text(text.replace('kind = "rate_ratio"', 'kind = "ratio"', 1))
    with pytest.raises(CaseError, match=rf"evidence\.toml.*rows\[{ratio}\]\.kind.*unknown kind 'ratio'"):
        load_evidence(bad)
    bad.write_text(text.replace("low = 0.71", "low = 0.9", 1))
    with pytest.raises(CaseError, match=r"rows\[0\]\.high.*interval \[0.9, 0.72\] is empty"):
        load_evidence(bad)


@pytest.mark.parametrize("row_id, old, new, field, words", [
    ("papageorgiou2005_cr_single_rooted", "low = 33.0\n", "low = 0.0\n", "high", "wider than 37.5, so the row could hardly fail"),
    ("ccd2018_canine_retraction_implant_anchorage", "high = 0.6\n", "high = 1.5\n", "high", "wider than 1"),
    ("monini2019_upper_canine_rate", "mean = 0.715\n", "", "mean", "a source that gives a class and no number is no row"),
    ("monini2019_upper_canine_rate", "high = 0.72\n", "high = inf\n", "high", "must be finite"),
    ("monini2019_upper_canine_rate", "mean = 0.715\n", "mean = 0.8\n", "mean", "outside its interval"),
    ("monini2019_upper_canine_rate", "fitted = true\n", "", "fitted", "write fitted = true when the value was used to fit a constant"),
])
def test_a_row_that_could_not_fail_or_hides_its_role_is_refused_in_one_line(tmp_path, row_id, old, new, field, words):
    text = Path(load_evidence.__defaults__[0]).read_text()
    index = [r.id for r in ROWS].index(row_id)
    start = text.index(f'id = "{row_id}"')
    bad = tmp_path / "evidence.toml"
    bad.write_text(text[:start] + text[start:].replace(old, new, 1))
    with pytest.raises(CaseError) as err:
        load_evidence(bad)
    message = str(err.value)
    assert "\n" not in message and str(bad) in message and f"rows[{index}].{field}" in message and words in message, message


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_the_evidence_page_opens_in_headless_chromium_with_a_plot_per_row(tmp_path):
    from PIL import Image

    from orthosim_render.report.browser import NAMES, load_page

    if not any(shutil.which(n) for n in NAMES):
        pytest.fail("headless Chromium is not installed: run `bash tools/dev.sh install`")
    out = tmp_path / "evidence"
    done = orthosim("evidence", "--out", str(out), "--no-real")
    assert done.returncode == 0, done.stderr
    data = json.loads((out / "evidence.json").read_text())
    jsonschema.validate(data, EVIDENCE_SCHEMA)
    assert [r["id"] for r in data["rows"]] == [r.id for r in ROWS]
    assert {r["id"] for r in data["rows"] if r["fitted"]} == FITTED
    ran = [r for r in data["rows"] if r["status"] != "skipped"]
    assert data["validation"]["inside"] == sum(r["status"] == "inside" and not r["fitted"] for r in ran)
    assert data["calibration"] == {"rows": len(FITTED), "inside": len(FITTED), "outside": 0, "skipped": 0}
    assert {r["id"]: r["status"] for r in data["rows"] if r["status"] != "skipped"} == {
        k: v for k, v in VERDICTS.items() if k in PARAMETRIC}
    page = load_page(out / "index.html", window=(1400, 1600))
    assert page.problems == []
    assert page.images == len(PARAMETRIC)  # one plot per row run (the skipped real rows have none)
    shot = np.asarray(Image.open(io.BytesIO(page.screenshot_png)).convert("RGB")).astype(int)
    green = np.all(np.abs(shot - [26, 127, 55]) < 40, axis=2).mean()  # the verdicts and interval bands
    assert shot.shape[1] >= 1400 and green > 0.0005, green
    html = (out / "index.html").read_text()
    assert "outside: the rate law saturates" in html
    assert html.index('id="validation"') < html.index('id="calibration"')  # the two lists apart, validation first
    assert f"{data['validation']['inside']} of {len([r for r in ran if not r['fitted']])} validation rows inside" in html
    # a rerun into the same folder replaces it whole
    assert orthosim("evidence", "--out", str(out), "--no-real").returncode == 0


def test_the_report_line_names_the_rows_a_case_falls_under_and_the_papers_cases_no_treatment_row():
    from orthosim.evidence.matching import evidence_for_case
    from orthosim.exchange.case import CASES_DIR, load_case

    def ids(name):
        return {m.row_id for m in evidence_for_case(load_case(CASES_DIR / f"{name}.toml"), ROWS)}

    assert {"monini2019_upper_canine_rate", "ccd2018_canine_retraction_molar_anchorage"} <= ids("canine_retraction_upper")
    reinforced = ids("canine_retraction_upper_reinforced")
    assert "ccd2018_canine_retraction_implant_anchorage" in reinforced
    assert "ccd2018_canine_retraction_molar_anchorage" not in reinforced
    assert "monini2019_lower_canine_rate" in ids("canine_retraction_lower")
    assert "becker2018_en_masse_anchorage_difference" in ids("en_masse_retraction")
    assert ids("normal_occlusion") == set()
    assert not {i for i in ids("case1_first_premolar_extraction") if i.startswith(("monini", "ccd", "becker"))}


@pytest.mark.parametrize("name, molar_mm", [("canine_retraction_upper", (0.8, 1.8)),
                                            ("canine_retraction_upper_reinforced", (0.0, 0.0))])
def test_the_shipped_canine_retraction_closes_the_space_and_the_molar_gives_what_the_trial_found(name, molar_mm):
    from orthosim.exchange.case import CASES_DIR, load_case
    from orthosim.movement import MovementModel, simulate

    case = load_case(CASES_DIR / f"{name}.toml")
    model = MovementModel.build(case)  # its smooth model: the loads are shared by that model's root surfaces
    records = list(simulate(model, "continuous"))
    first, last = records[0], records[-1]
    moved = {t: float(np.linalg.norm(last.poses[t][:3, 3] - first.poses[t][:3, 3])) for t in (13, 16)}
    # the canine reached the second premolar (the premolar, pushed on by it, may give way again after)
    assert any(any({13, 15} == set(p) for p in r.touching) for r in records)
    assert moved[13] > 5.0
    assert molar_mm[0] <= moved[16] <= molar_mm[1] + 1e-12, moved


def test_the_papers_constants_miss_the_canine_trials_which_is_why_the_clinical_set_exists():
    rows = tuple(r for r in ROWS if r.id in ("monini2019_upper_canine_rate", "monini2019_lower_canine_rate"))
    paper = {r.row.id: r for r in run_evidence(PARAMETER_SETS["paper"], with_real=False, rows=rows)}
    upper, lower = paper["monini2019_upper_canine_rate"], paper["monini2019_lower_canine_rate"]
    assert upper.status == "outside" and upper.value < 0.6  # well under the trial's 0.71 mm a month
    assert lower.value > upper.value  # and the lower canine faster than the upper, against the trial

"""The occlusal sliding rule on parametric teeth, and the allowance each model gets by default:
cusps in contact at rest slide along each other; a tooth driven into its antagonist stops; the
allowance is the case's, or the model's own (the deepest interpenetration it has at rest)."""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from orthosim.exchange.case import Load, load_case
from orthosim.model.dentition import Dentition
from orthosim.collision.interpenetration import SLIDE_MAX_MM, SLIDE_MIN_MM, default_occlusal_slide_mm
from orthosim.collision import ExactQueries
from orthosim.movement import MovementModel, simulate

CASES = Path(__file__).resolve().parents[2] / "cases"


def penetrations(model, poses) -> dict:
    return ExactQueries(model.collision).penetrations(model.pairs, poses)


def _exact_distance(model, poses, pair) -> float:
    return ExactQueries(model.collision).distance(pair, poses)


@lru_cache(maxsize=1)
def _normal_occlusion():
    case = load_case(CASES / "normal_occlusion.toml")
    return case, case.build_dentition()


@lru_cache(maxsize=6)
def _run(loads: tuple, steps: int, extractions: tuple = ()):
    case, dent = _normal_occlusion()
    case = replace(case, loads=loads, step_days=10.0, duration_days=10.0 * steps, extractions=extractions)
    model = MovementModel.build(case, dentition=dent)
    return model, list(simulate(model, "continuous"))


def _moved(model, records, n) -> float:
    t = model.dentition.teeth[n]
    return float(np.linalg.norm(t.to_world(t.crown_center, records[-1].poses[n]) - t.to_world(t.crown_center, records[0].poses[n])))


def _with_rest_depths(depths: dict) -> Dentition:
    dent = _normal_occlusion()[1]
    return replace(dent, info={**dent.info, "rest_interpenetration_mm": depths})


def test_a_model_without_rest_interpenetration_slides_by_the_touch_tolerance_and_a_scan_by_its_deepest_overlap():
    assert default_occlusal_slide_mm(_normal_occlusion()[1]) == SLIDE_MIN_MM == 0.05
    assert default_occlusal_slide_mm(_with_rest_depths({"26-37": 0.3012, "16-46": 0.19})) == pytest.approx(0.3012)
    assert default_occlusal_slide_mm(_with_rest_depths({"16-46": 0.01})) == SLIDE_MIN_MM
    assert default_occlusal_slide_mm(_with_rest_depths({"16-46": 1.7})) == SLIDE_MAX_MM  # a broken segmentation


def test_a_case_that_sets_the_slide_keeps_it_and_one_that_does_not_gets_the_models(tmp_path):
    case, dent = _normal_occlusion()
    scan_like = _with_rest_depths({"16-46": 0.2})
    assert case.simulation.occlusal_slide_mm is None
    assert MovementModel.build(case, dentition=dent).settings.occlusal_slide_mm == 0.05
    assert MovementModel.build(case, dentition=scan_like).settings.occlusal_slide_mm == pytest.approx(0.2)
    text = (CASES / "normal_occlusion.toml").read_text() + "\n[simulation]\nocclusal_slide_mm = 0.5\n"
    (tmp_path / "set.toml").write_text(text)
    set_case = load_case(tmp_path / "set.toml")
    assert MovementModel.build(set_case, dentition=scan_like).settings.occlusal_slide_mm == 0.5


def test_a_parametric_second_molar_in_contact_with_its_antagonist_slides_distally_without_sinking_deeper():
    # in the parametric bite the second molars are the teeth of the two arches that touch at rest
    model, records = _run((Load((17,), 150.0, "distal", movement="translation"),), 3)
    assert (17, 47) in records[0].touching
    assert _moved(model, records, 17) > 0.1
    start, end = penetrations(model, records[0].poses), penetrations(model, records[-1].poses)
    for pair, depth in end.items():
        assert depth <= start.get(pair, 0.0) + model.settings.occlusal_slide_mm + 1e-6, (pair, depth)


def test_a_parametric_second_molar_extruded_into_its_antagonist_stops_on_it():
    load = (Load((17,), 150.0, "occlusal", movement="extrusion"),)
    model, records = _run(load, 4)
    _, free = _run(load, 4, (47,))  # the same load with the antagonist gone
    # touching 47 at rest, it may only slide down the cusp's incline, never sink in
    assert _moved(model, records, 17) < 0.75 * _moved(model, free, 17)
    assert penetrations(model, records[-1].poses).get((17, 47), 0.0) <= model.settings.occlusal_slide_mm + 1e-6
    assert _exact_distance(model, records[-1].poses, (17, 47)) < 0.05


def test_a_parametric_first_molar_extruded_onto_its_antagonist_stops_where_it_first_touches():
    # 16 stands 0.47 mm above 46: a contact the treatment makes, held to the touch tolerance
    model, records = _run((Load((16,), 150.0, "occlusal", movement="extrusion"),), 6)
    assert _moved(model, records, 16) > 0.4
    assert _exact_distance(model, records[-1].poses, (16, 46)) < 0.05
    assert records[-1].max_penetration_mm <= model.settings.touch_tolerance_mm + 1e-6

"""Upper-versus-lower contacts on the real bite stop a tooth moved into the other arch in any
direction, while cusps in contact at rest may slide (the occlusal rule, README "Occlusion"), and
the scan's own interpenetration is the rest state, not a collision. These runs set `[occlusion]
closure = "none"`: the rule without the bite's closure, which real-jaw cases use by default."""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from fulljaw_helpers import full_jaw
from orthosim.exchange.case import Load, Occlusion, load_case
from orthosim.collision import ExactQueries
from orthosim.movement import MovementModel, simulate

CASE = Path(__file__).resolve().parents[2] / "cases" / "open_full_jaw_patient26.toml"


@lru_cache(maxsize=6)
def _run(loads: tuple, steps: int, extractions: tuple = ()):
    # the slide allowance's own rule: the bite's closure (tests/movement/test_closure.py) off
    case = replace(load_case(CASE), loads=loads, step_days=10.0, duration_days=10.0 * steps, extractions=extractions,
                   occlusion=Occlusion(closure="none"))
    model = MovementModel.build(case, dentition=full_jaw()[0])
    return model, list(simulate(model, "continuous"))


def penetrations(model, poses) -> dict:
    return ExactQueries(model.collision).penetrations(model.pairs, poses)


def _moved(model, records, n) -> float:
    t = model.dentition.teeth[n]
    return float(np.linalg.norm(t.to_world(t.crown_center, records[-1].poses[n]) - t.to_world(t.crown_center, records[0].poses[n])))


@pytest.mark.real_data
def test_the_scans_interpenetration_is_the_rest_state_not_a_collision():
    model, records = _run((Load((12,), 1.0, "mesial", movement="translation"),), 1)  # a load too weak to move
    assert records[0].raw_penetration_mm > 0.25  # 26-37 overlap 0.30 mm in the scan
    assert records[0].max_penetration_mm == 0.0 and records[-1].max_penetration_mm == 0.0
    assert not any(r.collisions for r in records)


@pytest.mark.real_data
def test_an_upper_incisor_retracted_sideways_into_the_lower_incisors_stops_just_touching():
    load = Load((21,), 100.0, "lingual", movement="translation")
    model, records = _run((load,), 4)
    moved = _moved(model, records, 21)
    assert 0.05 < moved < 0.6  # it moved, then the lower incisor's labial face stopped it
    last = records[-1]
    assert any(31 in e.pair and 21 in e.pair for r in records for e in r.collisions)
    assert ExactQueries(model.collision).distance((21, 31), last.poses) < 0.05  # just touching, not sunk in
    assert last.max_penetration_mm < 0.06
    assert not records[-1].moving or 21 not in records[-1].moving  # it no longer moves at the end


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.real_data
def test_cusps_in_contact_at_rest_slide_along_each_other_instead_of_stopping_every_horizontal_move():
    # 16 overlaps 46 by 0.19 mm in the scan; moved mesially it slides over the lower molar's cusps
    load = Load((16,), 150.0, "mesial", movement="translation")
    model, records = _run((load,), 2)
    assert _moved(model, records, 16) > 0.1
    start = penetrations(model, records[0].poses)
    end = penetrations(model, records[-1].poses)
    # never deeper than the rest state plus the sliding allowance
    for pair in (16, 46), (16, 47), (16, 45):
        assert end.get(pair, 0.0) <= start.get(pair, 0.0) + model.settings.occlusal_slide_mm + 1e-6, pair


@pytest.mark.real_data
def test_the_scans_own_bite_slides_by_its_deepest_rest_overlap_when_the_case_sets_no_allowance():
    model, _ = _run((Load((12,), 1.0, "mesial", movement="translation"),), 1)
    assert model.case.simulation.occlusal_slide_mm is None
    assert model.settings.occlusal_slide_mm == pytest.approx(0.301, abs=0.002)  # 26-37 overlap in the scan


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.real_data
def test_an_upper_molar_extruded_into_the_lower_molar_it_bites_on_is_stopped():
    load = (Load((16,), 150.0, "occlusal", movement="extrusion"),)
    model, records = _run(load, 3)
    _, free = _run(load, 3, (46, 47, 45))  # the same load with its antagonists gone
    assert _moved(model, records, 16) < 0.5 * _moved(model, free, 16)
    start, end = penetrations(model, records[0].poses), penetrations(model, records[-1].poses)
    for pair in (16, 46), (16, 47), (16, 45):
        assert end.get(pair, 0.0) <= start.get(pair, 0.0) + model.settings.occlusal_slide_mm + 1e-6, pair

"""The paper's three cases on real teeth (Open-Full-Jaw patient 26, both arches in their scanned
bite), with the continuous detector: who moves, who stays, the space closing, no tooth sunk in."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import pytest

from orthosim.exchange.case import load_case
from orthosim.collision import ExactQueries
from orthosim.movement import MovementModel, simulate
from orthosim.movement.report import RunReport

CASES = Path(__file__).resolve().parent.parent / "cases"


@lru_cache(maxsize=3)
def _run(name):
    model = MovementModel.build(load_case(CASES / name))
    report = RunReport(model, "continuous")
    for _ in report.collect(simulate(model, "continuous")):
        pass
    return model, report.metrics(), report.last


def _moved(metrics, teeth):
    return {n: metrics["teeth"][str(n)]["moved_mm"] for n in teeth}


@pytest.mark.real_data
def test_real_case1_first_molars_and_second_premolars_move_into_the_space_canines_and_incisors_stay():
    model, m, _ = _run("open_full_jaw_case1_first_premolar_extraction.toml")
    assert min(_moved(m, (16, 26, 36, 46)).values()) > 0.5, _moved(m, (16, 26, 36, 46))
    assert min(_moved(m, (15, 25, 35, 45)).values()) > 0.2, _moved(m, (15, 25, 35, 45))
    stayers = _moved(m, (13, 12, 11, 21, 22, 23, 33, 32, 31, 41, 42, 43))
    assert max(stayers.values()) < 0.05, stayers
    assert m["max_penetration_mm"] <= model.settings.occlusal_slide_mm + 0.01  # cusps slid, none sank further


@pytest.mark.real_data
def test_real_case2_first_molars_and_first_premolars_move_canines_and_lateral_incisors_stay():
    model, m, _ = _run("open_full_jaw_case2_second_premolar_extraction.toml")
    movers = _moved(m, (16, 14, 26, 24, 36, 34, 46, 44))
    assert min(movers.values()) > 0.3, movers
    stayers = _moved(m, (13, 12, 23, 22, 33, 32, 43, 42))
    assert max(stayers.values()) < 0.05, stayers
    assert m["max_penetration_mm"] <= model.settings.occlusal_slide_mm + 0.01


@pytest.mark.real_data
def test_real_case3_the_opened_diastema_closes_in_both_arches():
    model, m, last = _run("open_full_jaw_case3_diastema.toml")
    gap = {tuple(d["pair"]): (d["initial_mm"], d["final_mm"]) for d in m["distances"]}
    # the space was opened: the incisors start 2 mm further apart than in the scan (0.2-0.4 mm)
    assert ExactQueries(model.collision).distance((11, 21), model.dentition.rest_poses()) > 2.0
    assert ExactQueries(model.collision).distance((41, 31), model.dentition.rest_poses()) > 2.0
    for pair in ((11, 21), (41, 31)):
        before, after = gap[pair]
        assert after < before - 0.5, (pair, before, after)
        assert ExactQueries(model.collision).distance(pair, last.poses) < 0.1, pair
    assert max(_moved(m, (12, 22, 32, 42, 13, 23)).values()) < 0.05
    assert m["max_penetration_mm"] < 0.06

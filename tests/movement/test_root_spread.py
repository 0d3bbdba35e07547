"""A run on crowns with estimated roots says how far its answer hangs on them: each moving tooth's
movement over the plausible roots (`moved_mm_range`), holding the run's own figure; a run on
seen roots says nothing of the kind."""

from __future__ import annotations

import json
import warnings
from importlib import resources

import jsonschema
import numpy as np
import pytest

from orthosim.exchange.case import load_case
from orthosim.mechanics.ligament import root_support
from orthosim.movement import MovementModel, simulate
from orthosim.movement.report import RunReport
from orthosim.movement.rootspread import ROOT_CROWN_SPREAD, stretched_root
from orthosim_bench.scanarch import write_labelled_arch

FRONT = {13, 12, 11, 21, 22, 23, 43, 42, 41, 31, 32, 33}


@pytest.fixture(scope="module")
def coarse():
    from orthosim.model.parametric import parametric_dentition

    return parametric_dentition("coarse")


def test_a_stretched_root_is_longer_stiffer_and_keeps_its_crown(coarse):
    tooth = coarse.teeth[13]
    longer = stretched_root(tooth, ROOT_CROWN_SPREAD[1])
    assert longer.root_length == pytest.approx(tooth.root_length * ROOT_CROWN_SPREAD[1])
    crown = tooth.mesh.vertices[:, 1] >= 0
    assert np.array_equal(longer.mesh.vertices[crown], tooth.mesh.vertices[crown])
    a, b = root_support(tooth), root_support(longer)
    assert b.embedded_area_mm2 > a.embedded_area_mm2
    assert b.center_of_resistance[1] < a.center_of_resistance[1]


def _run(case_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = MovementModel.build(load_case(case_path))
        report = RunReport(model, "continuous")
        for record in simulate(model, "continuous"):
            report.add(record)
        return model, report.metrics()


@pytest.mark.slow
def test_a_run_on_estimated_roots_gives_each_moving_tooth_a_range_holding_its_movement(coarse, tmp_path):
    upper = write_labelled_arch(coarse, "upper", tmp_path, "front", subdivisions=1, teeth=FRONT)
    lower = write_labelled_arch(coarse, "lower", tmp_path, "front", subdivisions=1, teeth=FRONT)
    case = tmp_path / "case.toml"
    case.write_text(f'[case]\nname = "front"\n\n[model]\nkind = "labelled-scan"\nupper = "{upper.name}"\n'
                    f'lower = "{lower.name}"\n\n[treatment]\nduration_days = 60\nstep_days = 30\n\n'
                    '[[loads]]\nteeth = [13]\nforce_cN = 100\ndirection = "distal"\n')
    model, metrics = _run(case)
    assert model.settings.resistance_rule == "ligament"
    canine = metrics["teeth"]["13"]
    low, high = canine["moved_mm_range"]
    assert low <= canine["moved_mm"] <= high
    assert high - low > 0.01  # a longer root moves slower: the answer hangs on the root
    lower = metrics["teeth"]["31"]  # carried by the mandible's hinge at most: not a moving tooth
    assert "moved_mm_range" not in lower and lower.get("moved_in_mandible_mm", lower["moved_mm"]) < 0.01
    assert metrics["root_spread"]["root_crown_ratio_factors"] == list(ROOT_CROWN_SPREAD)
    schema = json.loads(resources.files("orthosim").joinpath("schema/metrics.schema.json").read_text())
    written = json.loads(json.dumps(metrics, default=lambda a: np.asarray(a).tolist()))
    for key in ("teeth", "root_spread"):  # the run's own fields (`orthosim run` adds the model's and more)
        jsonschema.validate(written[key], schema["properties"][key])

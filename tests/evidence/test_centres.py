"""The centre-of-resistance and M/F rows are predictions of the ligament, not of the rule or the rate law.

As M/F at an upper central incisor's bracket rises from 0 to 14 mm, the ligament's centre of
rotation must pass through the four classical movements in their order: uncontrolled tipping,
controlled tipping, translation, root movement. The rows' values come from the root's geometry
alone: the rate law under test does not move them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from orthosim.evidence import load_evidence, run_evidence
from orthosim.evidence.centres import MF_RANGE_MM, _bisect, movement_class, rotation_centre_mm, turning
from orthosim.evidence.run import evidence_models
from orthosim.mechanics.biomechanics import bracket_point
from orthosim.mechanics.ratelaw import PARAMETER_SETS

ORDER = ["uncontrolled tipping", "controlled tipping", "translation", "root movement"]
GEOMETRY_TOPICS = ("centre of resistance", "M/F")


def _classes_as_mf_rises(bench, model: str, fdi: int = 11) -> list[str]:
    tooth, support = bench.dentition(model).teeth[fdi], bench.support(model, fdi)
    bracket = bracket_point(tooth)
    apex = np.asarray(tooth.apex, float)
    translation = _bisect(lambda x: turning(support, bracket, x), 0.0, 30.0)
    grid = sorted(set(np.linspace(*MF_RANGE_MM, 281).tolist()) | {translation})
    seen = []
    for mf in grid:
        name = "translation" if mf == translation else movement_class(support, bracket, apex, mf)
        if not seen or seen[-1] != name:
            seen.append(name)
    return seen


def test_an_upper_incisor_passes_through_the_four_movements_in_order_as_m_over_f_rises():
    assert _classes_as_mf_rises(evidence_models(with_real=False), "parametric") == ORDER


@pytest.mark.real_data
def test_the_real_upper_incisor_passes_through_the_four_movements_in_order_too():
    bench = evidence_models(with_real=True)
    if not bench.has("real"):
        pytest.skip("the real patient's data (../shared/data) is absent")
    assert _classes_as_mf_rises(bench, "real") == ORDER


def test_the_centre_of_rotation_moves_from_near_the_centre_of_resistance_through_the_apex_to_the_crown():
    bench = evidence_models(with_real=False)
    tooth, support = bench.dentition("parametric").teeth[11], bench.support("parametric", 11)
    bracket = bracket_point(tooth)
    below_apex = float(support.center_of_resistance[1] - tooth.apex[1])
    at = {mf: rotation_centre_mm(support, bracket, mf) for mf in (0.0, 8.0, 14.0)}
    assert -below_apex < at[0.0] < 0.0  # a force alone: the tooth turns about a point between the CR and the apex
    assert at[8.0] < at[0.0]  # a counter-couple moves it apically
    assert 0.0 < at[14.0] < float(bracket[1] - support.center_of_resistance[1])  # past translation: on the crown side


def test_the_geometry_rows_do_not_depend_on_the_rate_law():
    rows = tuple(r for r in load_evidence() if r.topic in GEOMETRY_TOPICS and r.model == "parametric")
    clinical = {r.row.id: r.value for r in run_evidence(PARAMETER_SETS["clinical"], with_real=False, rows=rows)}
    paper = {r.row.id: r.value for r in run_evidence(PARAMETER_SETS["paper"], with_real=False, rows=rows)}
    assert clinical == paper and all(math.isfinite(v) for v in clinical.values())

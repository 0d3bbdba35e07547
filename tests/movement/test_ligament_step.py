"""The step with each tooth held by its ligament: which cases use it, how a tooth moves by its
compliance, where an anchor unit's reactions go, and the ligament's bad input refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from case_helpers import BASE, refused, write
from cli_helpers import orthosim as run
from orthosim.exchange.case import load_case
from orthosim.mechanics.biomechanics import RateLaw, build_mechanics
from orthosim.mechanics.ligament import EMBEDDED_SHARE_OF_REFERENCE
from orthosim.mechanics.ligamentmotion import ligament_motion
from orthosim.model.parametric import parametric_dentition

CASES = __import__("pathlib").Path(__file__).resolve().parents[2] / "cases"
LAW = RateLaw()


@pytest.fixture(scope="module")
def dent():
    return parametric_dentition("coarse")


@pytest.mark.parametrize("name, rule", [("case1_first_premolar_extraction", "literature"),
                                        ("normal_occlusion", "literature"),
                                        ("canine_retraction_upper", "ligament"),
                                        ("open_full_jaw_case1_first_premolar_extraction", "ligament")])
def test_the_papers_cases_keep_the_rule_and_every_other_case_moves_by_the_ligament(name, rule):
    case = load_case(CASES / f"{name}.toml")
    assert case.simulation.resistance_rule == rule


def test_a_case_may_still_ask_for_the_rule_or_the_ligament(tmp_path):
    ask = load_case(write(tmp_path, BASE + '[simulation]\nresistance_rule = "ligament"\n'))
    assert ask.simulation.resistance_rule == "ligament"
    clinical = BASE + '[biomechanics]\nparameters = "clinical"\n[simulation]\nresistance_rule = "literature"\n'
    assert load_case(write(tmp_path, clinical)).simulation.resistance_rule == "literature"


def test_a_force_through_the_centre_of_resistance_moves_it_at_the_rate_laws_speed_hardly_turning(dent):
    mech = build_mechanics(dent.teeth[11], "ligament", law=LAW)
    pose = np.eye(4)
    force = np.array([0.0, 0.0, -100.0])
    m = ligament_motion(mech, pose, force, mech.center_of_resistance, np.zeros(3), "round", False, LAW)
    tipped = ligament_motion(mech, pose, force, mech.bracket, np.zeros(3), "round", False, LAW)
    # an asymmetric root has no exact centre: what turn is left is a few per cent of the bracket's
    assert np.linalg.norm(m.omega) < 0.05 * np.linalg.norm(tipped.omega)
    speed = LAW.rate(100.0, mech.root_area_mm2 / EMBEDDED_SHARE_OF_REFERENCE)
    assert m.velocity @ force / 100.0 == pytest.approx(speed)


def test_a_force_at_the_bracket_on_a_round_wire_tips_the_crown_with_it_and_the_root_against_it(dent):
    mech = build_mechanics(dent.teeth[11], "ligament", law=LAW)
    force = np.array([0.0, 0.0, -100.0])  # lingual
    m = ligament_motion(mech, np.eye(4), force, mech.bracket, np.zeros(3), "round", False, LAW)
    crown, apex = m.displacement(np.array([mech.bracket, mech.apex]), 1.0)
    assert crown[2] < 0 < apex[2]


def test_a_bodily_load_on_a_rectangular_wire_slides_the_tooth_along_the_force(dent):
    mech = build_mechanics(dent.teeth[16], "ligament", law=LAW)
    force = np.array([-60.0, 0.0, 80.0])
    m = ligament_motion(mech, np.eye(4), force, mech.bracket, np.zeros(3), "rectangular", True, LAW)
    assert not m.omega.any()
    assert np.cross(m.velocity, force) == pytest.approx(np.zeros(3), abs=1e-12)


RETRACTION = """
[model]
kind = "parametric"
resolution = "coarse"
[treatment]
extractions = [14, 24, 34, 44]
duration_days = 30
step_days = 30
[wire]
type = "rectangular"
[biomechanics]
parameters = "clinical"
[[loads]]
teeth = [13, 23]
force_cN = 98
direction = "distal"
movement = "translation"
"""


def _initial_loads(path):
    from orthosim.movement import MovementModel
    from orthosim.movement.forces import forces
    from orthosim.movement.simulation import initial_state

    model = MovementModel.build(load_case(path))
    state, _ = initial_state(model, "circles")
    return model, forces(model, state, state.centers).loads


@pytest.mark.slow
def test_an_anchor_unit_takes_the_reaction_shared_by_stiffness_and_a_mini_implant_takes_it_alone(tmp_path):
    unit = RETRACTION + '[[anchorage]]\nkind = "teeth"\nactive = [13, 23]\nteeth = [15, 16, 17, 25, 26, 27]\n'
    model, loads = _initial_loads(write(tmp_path, unit))
    for canine, side in ((13, (15, 16, 17)), (23, (25, 26, 27))):  # each side takes its own canine's reaction
        shares = {n: sum(a.force_cN for a in loads[n]) for n in side}
        assert sum(shares.values()) == pytest.approx(-loads[canine][0].force_cN)
        assert np.linalg.norm(shares[side[1]]) > np.linalg.norm(shares[side[0]])  # the molar's bigger root takes more
    implant = RETRACTION + '[[anchorage]]\nkind = "mini-implant"\nactive = [13, 23]\n'
    _, alone = _initial_loads(write(tmp_path, implant))
    assert set(alone) == {13, 23}


@pytest.mark.parametrize("table, field, text", [
    ("[ligament]\nmodulus_mpa = 200", "ligament.modulus_mpa", "from 0.01 to 68.9"),
    ("[ligament]\npoisson = 0.5", "ligament.poisson", "from 0.28 to 0.49"),
    ("[ligament]\nthickness_mm = 0.05", "ligament.thickness_mm", "from 0.15 to 0.38"),
    ("[ligament]\ncrest_below_cej_mm = 3", "ligament.crest_below_cej_mm", "from 0.4 to 1.9"),
    ("[ligament]\nbone_level_mm = { 11 = 40 }", "ligament.bone_level_mm.11", "at most 25 mm"),
    ("[ligament]\nbone_level_mm = { 19 = 4 }", "ligament.bone_level_mm.19", "FDI"),
    ('[[anchorage]]\nkind = "teeth"\nactive = [16]\nteeth = [16, 17]', "anchorage[0].teeth", "also active"),
    ('[[anchorage]]\nkind = "mini-implant"\nactive = [16]\nteeth = [17]', "anchorage[0].teeth", "mini-implant"),
])
def test_a_ligament_or_anchorage_field_out_of_bounds_is_refused_in_one_line(tmp_path, table, field, text):
    msg = refused(tmp_path, BASE + table + "\n")
    assert f"case.toml: {field}" in msg and text in msg, msg


@pytest.mark.slow
@pytest.mark.parametrize("level, problem", [("13.5", "deeper than tooth 11's root"),
                                            ("12.999", "no root surface apical of")])
def test_a_bone_level_that_leaves_no_root_stops_orthosim_run_with_exit_2_and_nothing_written(tmp_path, level, problem):
    text = BASE.replace('kind = "parametric"', 'kind = "parametric"\nresolution = "coarse"')
    case = write(tmp_path, text + f'[simulation]\nresistance_rule = "ligament"\n[ligament]\nbone_level_mm = {{ 11 = {level} }}\n')
    result = run("run", case, "--out", tmp_path / "out", "--no-render")
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "ligament.bone_level_mm.11" in lines[0] and problem in lines[0], lines
    assert "Traceback" not in result.stderr and not (tmp_path / "out").exists()

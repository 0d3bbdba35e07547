"""Case files: the shipped cases load, and every kind of bad input is refused with its own message."""

import math
from pathlib import Path

import pytest

from case_helpers import BASE, refused, write

from orthosim.exchange.case import load_case
from orthosim.errors import CaseError

CASES = Path(__file__).resolve().parents[2] / "cases"


@pytest.mark.parametrize("name", ["normal_occlusion", "case1_first_premolar_extraction",
                                  "case2_second_premolar_extraction", "case3_incisor_space_closure"])
def test_shipped_cases_load(name):
    case = load_case(CASES / f"{name}.toml")
    assert case.model.kind == "parametric"
    assert case.steps >= 1


def test_case1_extracts_first_premolars_and_pushes_first_molars_mesially():
    case = load_case(CASES / "case1_first_premolar_extraction.toml")
    assert set(case.extractions) == {14, 24, 34, 44}
    assert {t for load in case.loads for t in load.teeth} == {16, 26, 36, 46}
    assert all(load.direction == "mesial" and load.force_cN > 0 for load in case.loads)


def test_case3_opens_a_diastema_and_loads_the_four_central_incisors():
    case = load_case(CASES / "case3_incisor_space_closure.toml")
    assert case.model.diastema_mm > 0
    assert {t for load in case.loads for t in load.teeth} == {11, 21, 31, 41}


def test_base_case_is_valid(tmp_path):
    case = load_case(write(tmp_path, BASE))
    assert case.extractions == (14,) and case.loads[0].teeth == (16,)


def test_missing_file_names_the_path(tmp_path):
    with pytest.raises(CaseError, match="no such case file"):
        load_case(tmp_path / "absent.toml")


def test_malformed_toml(tmp_path):
    assert "not valid TOML" in refused(tmp_path, "[model\nkind = 1")


def test_unknown_key_at_top_level_and_inside_a_load(tmp_path):
    assert "wires: unknown key" in refused(tmp_path, BASE + "\n[wires]\ntype = 'round'\n")
    assert "loads[0].forse_cN: unknown key" in refused(tmp_path, BASE.replace("force_cN = 150", "forse_cN = 150"))


def test_unknown_tooth(tmp_path):
    msg = refused(tmp_path, BASE.replace("teeth = [16]", "teeth = [19]"))
    assert "loads[0].teeth[0]: unknown tooth 19" in msg and "FDI" in msg


def test_tooth_not_in_the_model(tmp_path):
    # third molars are optional and off by default
    assert "tooth 18" in refused(tmp_path, BASE.replace("teeth = [16]", "teeth = [18]"))


def test_extraction_of_an_absent_tooth(tmp_path):
    msg = refused(tmp_path, BASE.replace("extractions = [14]", "extractions = [38]"))
    assert "treatment.extractions[0]" in msg and "cannot be extracted" in msg


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_nan_or_infinite_force(tmp_path, value):
    msg = refused(tmp_path, BASE.replace("force_cN = 150", f"force_cN = {value}"))
    assert "loads[0].force_cN: must be finite" in msg


def test_negative_force(tmp_path):
    assert "loads[0].force_cN: must be at least 0" in refused(tmp_path, BASE.replace("force_cN = 150", "force_cN = -5"))


def test_negative_or_zero_duration_and_step(tmp_path):
    assert "treatment.duration_days: must be positive" in refused(tmp_path, BASE.replace("duration_days = 10", "duration_days = -1"))
    assert "treatment.step_days: must be positive" in refused(tmp_path, BASE.replace("step_days = 1", "step_days = 0"))
    assert "treatment.step_days" in refused(tmp_path, BASE.replace("step_days = 1", "step_days = 20"))


def test_load_on_an_extracted_tooth(tmp_path):
    msg = refused(tmp_path, BASE.replace("teeth = [16]", "teeth = [14]"))
    assert "extracted" in msg and "loads[0].teeth[0]" in msg


def test_round_wire_cannot_translate(tmp_path):
    text = BASE.replace('type = "rectangular"', 'type = "round"') + 'movement = "translation"\n'
    assert "loads[0].movement: a round wire cannot do translation" in refused(tmp_path, text)


def test_unknown_direction_and_zero_vector(tmp_path):
    assert "loads[0].direction: unknown value 'upward'" in refused(tmp_path, BASE.replace('"mesial"', '"upward"'))
    assert "zero vector" in refused(tmp_path, BASE.replace('"mesial"', "[0, 0, 0]"))


def test_load_without_force_or_moment(tmp_path):
    assert "neither a force nor a moment" in refused(tmp_path, BASE.replace("force_cN = 150", "force_cN = 0"))


def test_mesh_model_needs_an_existing_folder(tmp_path):
    text = BASE.replace('kind = "parametric"', 'kind = "meshes"\nfolder = "nowhere"\n[model.files]\n"a.stl" = 16\n')
    assert "model.folder: no such folder" in refused(tmp_path, text)


def test_parametric_only_keys_are_refused_for_mesh_models(tmp_path):
    text = BASE.replace('kind = "parametric"', 'kind = "open-full-jaw"\nthird_molars = true\nfolder = "."')
    assert "model.third_molars: applies only to the parametric model" in refused(tmp_path, text)


def test_duration_gives_step_count(tmp_path):
    case = load_case(write(tmp_path, BASE.replace("duration_days = 10", "duration_days = 9.5")))
    assert case.steps == math.ceil(9.5 / 1)


@pytest.mark.real_data
def test_real_teeth_case_names_the_open_full_jaw_folder():
    path = CASES / "open_full_jaw_patient26.toml"
    case = load_case(path)
    assert case.model.kind == "open-full-jaw"
    upper = {18, 17, 16, 15, 14, 13, 12, 11, 21, 22, 23, 24, 25, 26, 27}
    assert case.model.present_teeth() == upper | {10 * q + p for q in (3, 4) for p in range(1, 9)}  # the full jaw
    assert case.loads  # with a treatment that moves teeth


@pytest.mark.real_data
@pytest.mark.parametrize("name", ["case1_first_premolar_extraction", "case2_second_premolar_extraction", "case3_diastema"])
def test_the_papers_cases_on_real_teeth_load_with_their_extractions_and_loads(name):
    case = load_case(CASES / f"open_full_jaw_{name}.toml")
    assert case.model.kind == "open-full-jaw" and len(case.model.folders) == 2
    assert case.loads
    assert case.extractions == {"case1_first_premolar_extraction": (14, 24, 34, 44),
                                "case2_second_premolar_extraction": (15, 25, 35, 45), "case3_diastema": ()}[name]
    assert case.model.diastema_mm == (2.0 if name == "case3_diastema" else 0.0)


# --- [simulation] table (movement parameters) ---------------------------------------------------

def _sim_case(tmp_path, table: str):
    p = tmp_path / "sim.toml"
    p.write_text("[model]\nkind = \"parametric\"\nresolution = \"coarse\"\n" + table)
    return p


def test_simulation_parameters_default_to_the_documented_values(tmp_path):
    from orthosim.exchange.case import load_case

    sim = load_case(_sim_case(tmp_path, "")).simulation
    assert (sim.force_share, sim.restitution, sim.resistance_rule, sim.resistance_fraction) == (0.5, 0.5, "literature", 0.4)


def test_simulation_parameters_are_read(tmp_path):
    from orthosim.exchange.case import load_case

    sim = load_case(_sim_case(tmp_path, "[simulation]\nforce_share = 0.3\nrestitution = 1.0\n"
                                        "resistance_rule = \"paper\"\nresistance_fraction = 0.5\n")).simulation
    assert (sim.force_share, sim.restitution, sim.resistance_rule, sim.resistance_fraction) == (0.3, 1.0, "paper", 0.5)


@pytest.mark.parametrize("line, field", [
    ("force_share = 1.2", "simulation.force_share"),
    ("restitution = 1.5", "simulation.restitution"),
    ("resistance_rule = \"middle\"", "simulation.resistance_rule"),
    ("resistance_fraction = 0.8", "simulation.resistance_fraction"),
])
def test_bad_simulation_parameters_are_refused_naming_the_field(tmp_path, line, field):
    from orthosim.exchange.case import load_case
    from orthosim.errors import CaseError

    with pytest.raises(CaseError, match=field.replace(".", r"\.")):
        load_case(_sim_case(tmp_path, f"[simulation]\n{line}\n"))

"""Planning a batch: cases x detectors x --set sweeps, each variant validated before any work."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from batch_helpers import SMALL_CASE
from orthosim.batch import BatchError, parse_sweep, plan_batch
from orthosim.exchange.case import CASES_DIR


@pytest.fixture
def cases(tmp_path: Path) -> Path:
    folder = tmp_path / "cases"
    folder.mkdir()
    (folder / "a.toml").write_text(SMALL_CASE)
    (folder / "b.toml").write_text(SMALL_CASE.replace('name = "small"', 'name = "other"'))
    (folder / "notes.txt").write_text("not a case")
    return folder


def test_sweep_is_the_cartesian_product_of_cases_detectors_and_values(cases):
    variants = plan_batch([cases], ["discrete", "exact"],
                          [parse_sweep("treatment.step_days=1,2,4"), parse_sweep("loads.0.force_cN=50,100")])
    assert len(variants) == 2 * 2 * 3 * 2
    assert len({v.run_id for v in variants}) == len(variants)
    seen = set()
    for v in variants:
        data = tomllib.loads(v.case_text)  # the exact case that will run
        settings = dict(v.settings)
        assert data["treatment"]["step_days"] == int(settings["treatment.step_days"])
        assert data["loads"][0]["force_cN"] == int(settings["loads.0.force_cN"])
        assert data["loads"][0]["teeth"] == [16, 26]  # the rest of the case is kept
        seen.add((v.source.name, v.detector, settings["treatment.step_days"], settings["loads.0.force_cN"]))
    assert len(seen) == 24
    # the first case, detector and --set vary slowest
    assert [v.source.name for v in variants[:12]] == ["a.toml"] * 12
    assert variants[0].run_id == "a__discrete__treatment.step_days=1__loads.0.force_cN=50"
    assert variants[1].run_id == "a__exact__treatment.step_days=1__loads.0.force_cN=50"


def test_without_detectors_each_variant_keeps_its_own_and_a_sweep_can_set_it(cases):
    own = plan_batch([cases / "a.toml"])
    assert [v.detector for v in own] == ["discrete"]
    swept = plan_batch([cases / "a.toml"], sweeps=[parse_sweep("treatment.detector=continuous,exact")])
    assert [v.detector for v in swept] == ["continuous", "exact"]


def test_values_are_read_as_toml_numbers_text_and_arrays():
    assert parse_sweep("loads.0.force_cN=50,2.5").values == (50, 2.5)
    assert parse_sweep("simulation.resistance_rule=paper,literature").values == ("paper", "literature")
    assert parse_sweep("loads.0.direction=[1, 0, 0],[0,0,1],mesial").values == ([1, 0, 0], [0, 0, 1], "mesial")


def test_a_table_the_case_lacks_is_added(cases):
    (v,) = plan_batch([cases / "a.toml"], sweeps=[parse_sweep("simulation.force_share=0.3")])
    assert tomllib.loads(v.case_text)["simulation"] == {"force_share": 0.3}


@pytest.mark.parametrize("sweep, field", [
    ("loads.0.force_cN=100,-5", "loads[0].force_cN"),
    ("treatment.stepdays=1", "treatment.stepdays"),
    ("simulation.force_share=0.5,1.5", "simulation.force_share"),
    ("loads.3.force_cN=100", "--set loads.3.force_cN"),
])
def test_a_bad_variant_is_refused_before_any_work_naming_variant_and_field(cases, tmp_path, sweep, field):
    with pytest.raises(BatchError) as err:
        plan_batch([cases / "a.toml"], sweeps=[parse_sweep(sweep)])
    message = str(err.value)
    assert "\n" not in message
    assert str(cases / "a.toml") in message and field in message
    assert f"[{sweep.split('=')[0]}=" in message  # the variant: the swept value that broke it


@pytest.mark.parametrize("text", ["force_cN", "loads.0.force_cN=", "=1,2", "a..b=1", "loads.0.force_cN=1,,2",
                                  "loads.0.force_cN=1,1"])
def test_malformed_set_options_are_refused(text):
    with pytest.raises(BatchError, match="--set"):
        parse_sweep(text)


def test_a_folder_means_its_case_files_and_missing_paths_are_named(cases, tmp_path):
    assert [v.source.name for v in plan_batch([cases])] == ["a.toml", "b.toml"]
    with pytest.raises(BatchError, match="no such case file or folder"):
        plan_batch([tmp_path / "nowhere"])
    with pytest.raises(BatchError, match="unknown detector"):
        plan_batch([cases], ["fast"])


def test_cases_of_the_same_name_in_two_folders_get_distinct_run_ids(cases, tmp_path):
    other = tmp_path / "other"
    other.mkdir()
    (other / "a.toml").write_text(SMALL_CASE)
    ids = [v.run_id for v in plan_batch([cases / "a.toml", other / "a.toml"])]
    assert len(set(ids)) == 2 and all(i.startswith("a__discrete") for i in ids)


def test_mesh_folders_are_made_absolute_so_the_variant_file_runs_from_anywhere(tmp_path):
    teeth = tmp_path / "teeth"
    teeth.mkdir()
    import trimesh

    trimesh.creation.icosphere(subdivisions=2, radius=4.0).export(teeth / "t.stl")
    case = tmp_path / "m.toml"
    case.write_text('[model]\nkind = "meshes"\nfolder = "teeth"\n[model.files]\n"t.stl" = 11\n'
                    '[treatment]\nduration_days = 2\nstep_days = 1\n')
    (v,) = plan_batch([case])
    assert Path(tomllib.loads(v.case_text)["model"]["folder"]) == teeth.resolve()


def test_shipped_parametric_cases_plan_with_their_own_detectors():
    names = ["case1_first_premolar_extraction", "case2_second_premolar_extraction", "case3_incisor_space_closure"]
    variants = plan_batch([CASES_DIR / f"{n}.toml" for n in names], sweeps=[parse_sweep("loads.0.force_cN=50,100")])
    assert len(variants) == 3 * 2
    assert {v.detector for v in variants} == {tomllib.loads((CASES_DIR / f"{n}.toml").read_text())["treatment"]["detector"]
                                              for n in names}
    with pytest.raises(BatchError, match=r"normal_occlusion.toml \[loads.0.force_cN=50\].*the case has no loads"):
        plan_batch([CASES_DIR / "normal_occlusion.toml"], sweeps=[parse_sweep("loads.0.force_cN=50")])

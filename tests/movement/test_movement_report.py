"""What a run writes: metrics.json as the issue's output contract states it, and distances.csv."""

import csv
import json

import numpy as np
import pytest

from collision_helpers import median_split_tree
from orthosim import load_case
from orthosim.collision import CollisionModel
from orthosim.analysis.metrics import tooth_to_tooth_distances
from orthosim.movement import MovementModel, simulate
from orthosim.movement.report import RunReport, read_steps
from orthosim.model.parametric import parametric_dentition


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("run")
    p = tmp / "case.toml"
    p.write_text("""
[case]
name = "short case 1"
[model]
kind = "parametric"
resolution = "coarse"
[treatment]
extractions = [14, 24, 34, 44]
duration_days = 21
step_days = 7
[[loads]]
teeth = [16, 26, 36, 46]
force_cN = 150
movement = "translation"
""")
    case = load_case(p)
    dent = parametric_dentition("coarse")
    model = MovementModel.build(case, dent, CollisionModel.from_dentition(dent, tree_builder=median_split_tree))
    report = RunReport(model, "discrete")  # per-step detail spooled, then written beside metrics.json
    records = list(report.collect(simulate(model, "discrete")))
    report.write(tmp / "out")
    return model, records, tmp / "out"


def test_metrics_json_holds_the_contract(run):
    model, records, out = run
    m = json.loads((out / "metrics.json").read_text())
    for key in ("case", "detector", "steps", "teeth", "total_distance_mm", "max_penetration_mm", "collisions", "distances"):
        assert key in m
    assert m["case"] == "short case 1" and m["detector"] == "discrete" and m["steps"] == 3
    assert set(m["teeth"]) == {str(n) for n in model.dentition.fdis}
    t16 = m["teeth"]["16"]
    assert np.asarray(t16["final_pose"]).shape == (4, 4)
    assert np.allclose(t16["final_pose"], records[-1].poses[16])
    assert t16["moved_mm"] > 0.2 and m["teeth"]["13"]["moved_mm"] == 0.0
    assert m["teeth"]["14"]["extracted"] and not m["teeth"]["15"]["extracted"]
    assert {"initial", "final"} == set(m["total_distance_mm"])


def test_distances_are_the_papers_crown_centre_distances_with_extraction_spaces_bridged(run):
    model, records, out = run
    m = json.loads((out / "metrics.json").read_text())
    expected = tooth_to_tooth_distances(model.dentition, records[-1].poses, set(model.extracted))
    assert [d["pair"] for d in m["distances"]] == [list(d.pair) for d in expected]
    assert [d["final_mm"] for d in m["distances"]] == pytest.approx([d.distance_mm for d in expected])
    assert m["total_distance_mm"]["final"] == pytest.approx(sum(d.distance_mm for d in expected))
    assert [15, 13] in [d["pair"] for d in m["distances"]]


def test_each_step_records_poses_contacts_distances_penetration_collisions_and_forces(run):
    _, records, out = run
    assert json.loads((out / "metrics.json").read_text())["per_step_file"] == "steps.jsonl"
    steps = list(read_steps(out))
    assert [s["step"] for s in steps] == [0, 1, 2, 3]
    assert [s["time_days"] for s in steps] == [0, 7, 14, 21]
    later = steps[1]
    assert len(later["poses"]) == 24 and "16" in later["poses"] and "14" not in later["poses"]
    assert later["touching"] and later["distances_mm"]
    assert later["total_distance_mm"] == pytest.approx(sum(d["mm"] for d in later["distances_mm"]))
    assert "max_penetration_mm" in later and isinstance(later["collisions"], list)
    assert np.allclose(later["applied_cN"]["16"], records[1].forces.applied[16])
    assert later["propagated_cN"]  # the molars push the second premolars: forces passed on


def test_distances_csv_has_one_row_per_adjacent_pair(run):
    _, records, out = run
    rows = list(csv.DictReader((out / "distances.csv").open()))
    assert len(rows) == len(records[0].distances)
    first = rows[0]
    assert set(first) == {"pair", "initial_mm", "final_mm"}
    assert first["pair"] == f"{records[0].distances[0].pair[0]}-{records[0].distances[0].pair[1]}"
    assert float(first["final_mm"]) == pytest.approx(records[-1].distances[0].distance_mm, abs=1e-4)
    assert not list(out.glob(".*"))  # written atomically: no temporary files left


def test_loaded_teeth_report_their_centre_of_resistance_and_movement(run):
    model, _, out = run
    t16 = json.loads((out / "metrics.json").read_text())["teeth"]["16"]
    assert t16["movement"] == "translation"
    assert t16["moment_to_force_mm"] == pytest.approx(model.mechanics[16].bracket_lever_mm)  # the wire's counter-moment
    assert np.allclose(t16["center_of_resistance_local_mm"], model.mechanics[16].center_of_resistance)


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_memory_stays_flat_in_the_number_of_steps_as_per_step_detail_streams_to_disk(run, tmp_path):
    import tracemalloc

    model, records, _ = run
    report = RunReport(model, "discrete", steps_file=tmp_path / "steps.jsonl")
    for rec in records:
        report.add(rec)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    for _ in range(3000):  # a long run's worth of steps
        report.add(records[-1])
    grown = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    assert grown < 1_000_000, f"{grown / 1e6:.1f} MB kept for 3,000 steps"  # was ~10 kB a step kept in a list
    report.write(tmp_path)
    assert sum(1 for _ in read_steps(tmp_path)) == len(records) + 3000

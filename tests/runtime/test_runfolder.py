"""A run folder is read only when its run.json, written last, marks a finished run of this orthosim version."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from orthosim import __version__
from orthosim.runtime.runfolder import RUN_FILE, RunFolderError, read_finished_run, write_run_record


@pytest.fixture()
def case_file(tmp_path):
    p = tmp_path / "case.toml"
    p.write_text('[model]\nkind = "parametric"\n')
    return p


def test_a_finished_run_is_read_back_with_its_case_hash(tmp_path, case_file):
    import hashlib

    write_run_record(tmp_path / "run", case_file, "continuous", {"wall_s": 1.5})
    record = read_finished_run(tmp_path / "run")
    assert record["complete"] is True and record["orthosim_version"] == __version__
    assert record["case_sha256"] == hashlib.sha256(case_file.read_bytes()).hexdigest()
    assert record["detector"] == "continuous" and record["wall_s"] == 1.5


def test_a_folder_without_run_json_is_an_unfinished_run(tmp_path):
    (tmp_path / "metrics.json").write_text("{}")
    with pytest.raises(RunFolderError, match="did not finish"):
        read_finished_run(tmp_path)


@pytest.mark.parametrize("content, field", [
    ("{not json", "unreadable"),
    (json.dumps({"orthosim_version": __version__, "complete": False}), "complete"),
    (json.dumps({"orthosim_version": "0.0.1", "complete": True}), "orthosim_version"),
])
def test_damaged_unfinished_or_foreign_run_records_are_refused_in_one_line(tmp_path, content, field):
    (tmp_path / RUN_FILE).write_text(content)
    with pytest.raises(RunFolderError, match=field) as err:
        read_finished_run(tmp_path)
    assert "\n" not in str(err.value) and "orthosim run" in str(err.value)


def _finished_run(folder, case_file):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "metrics.json").write_text(json.dumps({"steps": 2, "collisions": 0, "max_penetration_mm": 0.125}))
    (folder / "steps.jsonl").write_text('{"step": 0}\n{"step": 1}\n')
    write_run_record(folder, case_file, "continuous")
    return folder


@pytest.mark.parametrize("damage, problem", [
    (lambda f: (f / "metrics.json").write_text((f / "metrics.json").read_text().replace("0.125", "0.126")), "is damaged"),
    (lambda f: (f / "steps.jsonl").write_bytes((f / "steps.jsonl").read_bytes()[:-3]), "is damaged"),
    (lambda f: (f / "steps.jsonl").unlink(), "is missing"),
    (lambda f: (f / RUN_FILE).write_text(json.dumps({k: v for k, v in json.loads((f / RUN_FILE).read_text()).items()
                                                     if k != "output_sha256"})), "holds no checksums"),
])
def test_a_run_whose_files_changed_since_it_finished_is_refused_in_one_line(tmp_path, case_file, damage, problem):
    """A digit changed in metrics.json, steps cut short or deleted: the run is no longer the one run.json
    vouches for, and readers (report --from-runs, batch resume) must not use it."""
    run = _finished_run(tmp_path / "run", case_file)
    read_finished_run(run)  # whole: accepted
    damage(run)
    with pytest.raises(RunFolderError, match=problem) as err:
        read_finished_run(run)
    assert "\n" not in str(err.value) and "orthosim run" in str(err.value)


def test_files_added_to_a_finished_run_folder_are_no_damage(tmp_path, case_file):
    run = _finished_run(tmp_path / "run", case_file)
    (run / "notes.txt").write_text("seen by Dr. K")
    (run / "frames").mkdir()
    assert read_finished_run(run)["output_sha256"].keys() == {"metrics.json", "steps.jsonl"}


def recording_run(case_path, out_dir, options):
    """A batch run function that leaves a finished run folder at once (no simulation)."""
    _finished_run(Path(out_dir), Path(case_path))
    return json.loads((Path(out_dir) / "metrics.json").read_text())


def test_a_batch_runs_a_damaged_finished_run_again_with_one_warning_and_reuses_the_others(tmp_path, case_file):
    import warnings

    from orthosim.batch import BatchOptions, parse_sweep, plan_batch, run_batch
    from orthosim.batch.table import DamagedRunWarning

    case_file.write_text(case_file.read_text() + '[[loads]]\nteeth = [16]\nforce_cN = 100\n')
    vs = plan_batch([case_file], sweeps=[parse_sweep("loads.0.force_cN=100,150")])
    options = BatchOptions(workers=1, progress=False)
    assert [r.status for r in run_batch(vs, tmp_path / "out", recording_run, options)] == ["ok", "ok"]
    damaged = tmp_path / "out" / vs[0].run_id / "metrics.json"
    damaged.write_text(damaged.read_text().replace("0.125", "9.125"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rows = run_batch(vs, tmp_path / "out", recording_run, options)
    said = [str(w.message) for w in caught if issubclass(w.category, DamagedRunWarning)]
    assert len(said) == 1 and "\n" not in said[0] and str(damaged) in said[0] and "running" in said[0], said
    assert [(r.status, r.reused) for r in rows] == [("ok", False), ("ok", True)]
    assert rows[0].max_penetration_mm == 0.125  # the run's own figure, not the damaged one

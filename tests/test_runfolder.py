"""A run folder is read only when its run.json, written last, marks a finished run of this orthosim version."""

from __future__ import annotations

import json

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

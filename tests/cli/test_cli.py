"""The command line as a user meets it: commands listed, runs that write real output, clean errors."""

import json
import os
from pathlib import Path

import pytest
from cli_helpers import orthosim

ROOT = Path(__file__).resolve().parents[2]


def test_help_lists_every_command_with_one_line():
    r = orthosim("--help")
    assert r.returncode == 0
    for command in ("run", "demo", "check", "bench", "spheretree", "collide"):
        line = next(l for l in r.stdout.splitlines() if l.strip().startswith(command + " "))
        assert len(line.split(None, 1)[1]) > 10 and not line.endswith("...")  # a real one-line summary


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_run_without_render_writes_metrics_of_the_initial_model(tmp_path):
    r = orthosim("run", "cases/case1_first_premolar_extraction.toml", "--out", str(tmp_path / "o"), "--no-render")
    assert r.returncode == 0, r.stderr
    metrics = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert metrics["extracted"] == [14, 24, 34, 44]
    assert len(metrics["teeth"]) == 28
    assert abs(metrics["occlusion"]["overjet_mm"] - 2.0) < 0.5
    # the extraction spaces are bridged: the canine and second premolar become neighbours
    pairs = [d["pair"] for d in metrics["distances"]]
    assert [15, 13] in pairs and [23, 25] in pairs and [13, 14] not in pairs
    assert not list((tmp_path / "o").glob(".*"))  # no temporary files left behind
    from orthosim.runtime.runfolder import read_finished_run

    assert read_finished_run(tmp_path / "o")["detector"] == "continuous"  # run.json marks it finished


@pytest.mark.parametrize("text, expected", [
    ("[model]\nkind = 'parametric'\n[[loads]]\nteeth = [99]\nforce_cN = 1\n", "loads[0].teeth[0]: unknown tooth 99"),
    ("[model\n", "not valid TOML"),
])
def test_bad_case_gives_one_line_error_nonzero_exit_and_no_output(tmp_path, text, expected):
    case = tmp_path / "bad.toml"
    case.write_text(text)
    out = tmp_path / "o"
    r = orthosim("run", str(case), "--out", str(out), "--no-render")
    assert r.returncode == 2
    assert expected in r.stderr and str(case) in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not out.exists()


def test_missing_case_file(tmp_path):
    r = orthosim("check", str(tmp_path / "none.toml"))
    assert r.returncode == 2 and "no such case file" in r.stderr and "Traceback" not in r.stderr


def test_bad_size_option_is_refused():
    r = orthosim("run", "cases/normal_occlusion.toml", "--size", "big")
    assert r.returncode == 2 and "WIDTHxHEIGHT" in r.stderr


def test_outputs_get_ordinary_file_permissions(tmp_path):
    from orthosim.storage.atomic import write_json

    target = tmp_path / "m.json"
    write_json(target, {"a": 1})
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask

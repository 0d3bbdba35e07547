"""The numpy tally (`orthosim.storage.numpytally`): what earlier runs spent on the numpy forms of the
kernels counts toward compiling them, so a user who only makes short runs compiles once instead of
paying numpy's price on every run; the tally belongs to one compile (sources and numba's cache
folder), is checked when read, and a real drawn run adds to it from its simulation child."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from orthosim.geometry import signeddistance
from orthosim.storage import numpytally
from orthosim.storage.cacheentry import DamagedEntryWarning

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture()
def fresh_tally(tmp_path, monkeypatch):
    monkeypatch.setenv("ORTHOSIM_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    numpytally.forget_this_process()
    yield numpytally.tally_path()
    numpytally.forget_this_process()


def _later_process() -> None:
    numpytally.forget_this_process()  # what a new process knows: only the file


def test_what_a_process_spent_is_carried_into_later_runs_and_added_up(fresh_tally):
    assert numpytally.carried("queries-s", __file__) == 0.0
    numpytally.spend("queries-s", 2.5, __file__)
    numpytally.keep()
    numpytally.keep()  # kept once: a second keep adds nothing new
    _later_process()
    assert numpytally.carried("queries-s", __file__) == 2.5
    numpytally.spend("queries-s", 1.0, __file__)
    numpytally.keep()
    _later_process()
    assert numpytally.carried("queries-s", __file__) == 3.5


def test_another_numba_cache_or_an_edited_kernel_starts_from_nothing(fresh_tally, tmp_path, monkeypatch):
    source = tmp_path / "kernels.py"
    source.write_text("# kernels\n")
    numpytally.spend("queries-s", 4.0, str(source))
    numpytally.keep()
    _later_process()
    assert numpytally.carried("queries-s", str(source)) == 4.0
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "other-numba"))
    _later_process()
    assert numpytally.carried("queries-s", str(source)) == 0.0  # that cache compiles on its own count
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    source.write_text("# kernels, edited\n")  # numba recompiles an edited source: so does the count restart
    _later_process()
    assert numpytally.carried("queries-s", str(source)) == 0.0


@pytest.mark.parametrize("damage", [b"", b"{not json", b'{"entry": {}, "payload": {}}'])
def test_a_damaged_tally_is_one_warning_counts_as_nothing_and_is_written_anew(fresh_tally, damage):
    numpytally.spend("queries-s", 5.0, __file__)
    numpytally.keep()
    fresh_tally.write_bytes(damage)
    _later_process()
    with pytest.warns(DamagedEntryWarning, match="numpy tally"):
        assert numpytally.carried("queries-s", __file__) == 0.0
    numpytally.spend("queries-s", 1.0, __file__)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DamagedEntryWarning)
        numpytally.keep()
    _later_process()
    assert numpytally.carried("queries-s", __file__) == 1.0


def test_an_edited_count_fails_its_checksum(fresh_tally):
    numpytally.spend("queries-s", 5.0, __file__)
    numpytally.keep()
    document = json.loads(fresh_tally.read_text())
    key = next(iter(document["payload"]))
    document["payload"][key] = 500.0  # a count changed by hand: not trusted
    fresh_tally.write_text(json.dumps(document))
    _later_process()
    with pytest.warns(DamagedEntryWarning, match="checksum"):
        assert numpytally.carried("queries-s", __file__) == 0.0


def test_a_folder_that_cannot_be_written_keeps_no_tally_and_fails_nothing(tmp_path, monkeypatch):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("ORTHOSIM_CACHE", str(blocker))
    numpytally.forget_this_process()
    numpytally.spend("queries-s", 1.0, __file__)
    numpytally.keep()  # no error
    assert numpytally.carried("queries-s", __file__) == 0.0
    numpytally.forget_this_process()


def test_earlier_runs_numpy_seconds_make_compiling_pay_sooner(fresh_tally, monkeypatch):
    from orthosim.system import firstrun

    monkeypatch.setattr(firstrun, "in_numba_cache", lambda *kernels: False)  # a machine that never compiled
    monkeypatch.setattr(signeddistance, "_numpy_seconds", [0.0])
    monkeypatch.setattr(signeddistance, "_preferred", [])
    limit = signeddistance.PAYS_AFTER_S
    assert not signeddistance.compiled_pays()
    numpytally.spend(signeddistance.TALLY, 0.6 * limit, *signeddistance._KERNEL_SOURCES)  # one earlier run
    numpytally.keep()
    _later_process()
    assert not signeddistance.compiled_pays()  # not yet: 0.6 of what compiling costs
    numpytally.spend(signeddistance.TALLY, 0.6 * limit, *signeddistance._KERNEL_SOURCES)  # a second one
    numpytally.keep()
    _later_process()
    assert signeddistance.compiled_pays()  # the third run compiles, without a numpy second of its own


@pytest.mark.slow  # a drawn run of the paper's case 1 on numpy forms (about 10 s)
def test_a_drawn_run_adds_its_simulation_childs_numpy_seconds(tmp_path):
    env = {**os.environ, "ORTHOSIM_CACHE": str(tmp_path / "cache"), "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    case = ROOT / "cases" / "case1_first_premolar_extraction.toml"
    command = [sys.executable, "-c", "from orthosim.cli import entry; entry()", "run", str(case),
               "--out", str(tmp_path / "run"), "--size", "64x48", "--frames-per-step", "1", "-q"]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    record = json.loads((tmp_path / "run" / "run.json").read_text())
    assert record["options"]["simulate_in_process"] is False  # the simulation ran in the forked child
    entry = json.loads((tmp_path / "cache" / "firstrun" / "numpy-tally.json").read_text())
    assert entry["entry"]["kind"] == "numpy-tally"
    (seconds,) = entry["payload"].values()
    assert 0.0 < seconds < 600.0  # the child's numpy queries, kept although it ended with os._exit

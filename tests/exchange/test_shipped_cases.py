"""The shipped case files: listed and copied by `orthosim cases`, found from a checkout (and, through
the wheel's `orthosim/cases/`, from an installed package: tests/test_wheel_install.py)."""

from __future__ import annotations

from pathlib import Path

from cli_helpers import orthosim

from orthosim.exchange.case import CASES_DIR, DEFAULT_CASE, load_case

ROOT = Path(__file__).resolve().parents[2]


def test_from_a_checkout_the_shipped_cases_are_the_repository_cases_folder():
    assert CASES_DIR == ROOT / "cases" and DEFAULT_CASE.is_file()
    assert load_case(DEFAULT_CASE).name  # the demo's and the bench's case reads


def test_orthosim_cases_lists_every_shipped_case_and_marks_those_needing_the_real_data():
    done = orthosim("cases")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    listed = {line.split()[0]: line for line in lines[:-1]}
    assert set(listed) == {p.stem for p in CASES_DIR.glob("*.toml")}
    assert "needs the Open-Full-Jaw data" in listed["open_full_jaw_patient26"]
    assert "needs the Open-Full-Jaw data" not in listed["case1_first_premolar_extraction"]
    assert lines[-1].startswith(f"{len(listed)} cases in ")


def test_a_copied_case_is_the_shipped_text_and_a_second_copy_is_refused(tmp_path):
    done = orthosim("cases", "--copy", "case3_incisor_space_closure", tmp_path)
    assert done.returncode == 0, done.stderr
    copy = tmp_path / "case3_incisor_space_closure.toml"
    assert copy.read_text() == (CASES_DIR / copy.name).read_text()
    again = orthosim("cases", "--copy", "case3_incisor_space_closure.toml", tmp_path)
    assert again.returncode == 2 and "already exists" in again.stderr and len(again.stderr.strip().splitlines()) == 1
    unknown = orthosim("cases", "--copy", "case9", tmp_path / "x.toml")
    assert unknown.returncode == 2 and "case9: is not a shipped case" in unknown.stderr
    assert not (tmp_path / "x.toml").exists()

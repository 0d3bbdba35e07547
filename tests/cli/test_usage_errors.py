"""A user who mistypes an option, a value or a command gets one line, `orthosim: error: ...`, and
exit 2, like every other error; `--help` and a bare group still show click's help. `orthosim cases
--copy` onto a file that exists is refused in one line and leaves the file as it was."""

from __future__ import annotations

import pytest

from cli_helpers import orthosim
from orthosim.exchange.case import CASES_DIR

USAGE = [
    (["run", "--gl", "vulkan", "case.toml"], "orthosim: error: --gl: 'vulkan' is not one of auto, egl, osmesa"),
    (["stage", "plan", "case.toml", "--out", "o", "--export", "obj"], "orthosim: error: --export: 'obj' is not one of stl, ply, glb"),
    (["run", "--bogus"], "orthosim: error: No such option '--bogus'"),
    (["nosuch"], "orthosim: error: No such command 'nosuch'"),
    (["run"], "orthosim: error: Missing argument 'CASE'"),
]


@pytest.mark.parametrize("args, line", USAGE, ids=[" ".join(a) for a, _ in USAGE])
def test_a_usage_error_is_one_line_and_exit_2(tmp_path, args, line):
    r = orthosim(*args, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith(line), r.stderr
    assert "Usage:" not in r.stderr and "Traceback" not in r.stderr and r.stdout == ""


def test_help_and_a_bare_group_still_show_the_usage(tmp_path):
    r = orthosim("run", "--help", cwd=tmp_path)
    assert r.returncode == 0 and r.stdout.startswith("Usage: ") and "--gl" in r.stdout
    bare = orthosim(cwd=tmp_path)
    assert bare.returncode == 2 and "Usage: " in bare.stdout + bare.stderr and "Commands" in bare.stdout + bare.stderr


@pytest.mark.parametrize("name", ["notes.txt", "case.toml", "no_suffix"])
def test_copying_a_shipped_case_onto_an_existing_file_is_refused_and_never_overwrites(tmp_path, name):
    existing = tmp_path / name
    existing.write_text("my own notes\n")
    r = orthosim("cases", "--copy", "case3_incisor_space_closure", existing, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and r.stderr.startswith(f"orthosim: error: {existing}: already exists"), r.stderr
    assert existing.read_text() == "my own notes\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # no temporary file left beside it


def test_copying_into_a_folder_writes_the_case_readable_by_others(tmp_path):
    r = orthosim("cases", "--copy", "case3_incisor_space_closure", tmp_path / "mine", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    copied = tmp_path / "mine" / "case3_incisor_space_closure.toml"
    assert copied.read_text() == (CASES_DIR / "case3_incisor_space_closure.toml").read_text()
    assert copied.stat().st_mode & 0o044  # not mkstemp's private 0600
    again = orthosim("cases", "--copy", "case3_incisor_space_closure", tmp_path / "mine", cwd=tmp_path)
    assert again.returncode == 2 and "already exists" in again.stderr

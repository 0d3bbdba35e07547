"""Every `orthosim run` option is checked before any work: a bad one is one line naming it, exit 2,
before the model is built or any child process starts, and no output folder appears."""

from __future__ import annotations

import pytest

from cli_helpers import orthosim
from cli_helpers import quick_case

BAD_OPTIONS = [
    (["--view", "sideways"], "--view"),
    (["--view", "frontal", "--view", "frontal"], "--view"),
    (["--size", "0x480"], "WIDTHxHEIGHT"),
    (["--seconds", "0"], "--seconds"),
    (["--fps", "500"], "--fps"),
    (["--frames-per-step", "2", "--seconds", "3"], "--frames-per-step"),
    (["--export-scene", "obj"], "--export-scene"),
    (["--export-scene", "glb", "--export-steps", "9999"], "--export-steps"),
    (["--detector", "psychic"], "--detector"),
]


@pytest.mark.parametrize("args, named", BAD_OPTIONS, ids=[" ".join(a) for a, _ in BAD_OPTIONS])
def test_a_bad_option_is_one_line_before_the_model_or_any_child_process(tmp_path, args, named):
    out = tmp_path / "o"
    # --verbose prints a line as each phase ends: a model built (or a simulation child started) would show
    r = orthosim("run", quick_case(tmp_path), "--out", out, "--verbose", *args)
    # click's own usage lines come with a choice or format it refuses; beside them, one line says what is wrong
    lines = [line for line in r.stderr.splitlines() if line.strip() and not line.startswith(("Usage: ", "Try '"))]
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and named in lines[0], r.stderr
    assert "Traceback" not in r.stderr and "leaked" not in r.stderr
    assert not out.exists() and not list(tmp_path.glob(".o.*"))  # no folder, no staging folder beside it


def test_an_out_folder_that_cannot_be_made_is_one_line_before_the_model(tmp_path):
    # tests run as root, where permission bits do not stop a write; a file where a parent folder
    # should be stops it for anyone
    (tmp_path / "notes.txt").write_text("x")
    r = orthosim("run", quick_case(tmp_path), "--out", tmp_path / "notes.txt" / "run", "--verbose", "--no-render")
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "--out" in lines[0] and "not a folder" in lines[0], r.stderr
    assert (tmp_path / "notes.txt").read_text() == "x"

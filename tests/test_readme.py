"""The README's Python example runs as written and shows what it promises."""

import re
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).resolve().parent.parent / "README.md"


def test_collision_api_example_runs_and_each_detector_reports_the_contact(capsys):
    text = README.read_text()
    section = text.split("## Python API: one collision query", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    exec(compile(code, "README.md", "exec"), {})
    lines = dict(line.split(" ", 1) for line in capsys.readouterr().out.strip().splitlines())
    assert set(lines) == {"circles", "discrete", "continuous", "exact"}
    assert all(v.startswith("True") for v in lines.values())  # pushed 0.5 mm into its neighbour
    toc = float(lines["continuous"].split()[1])
    assert 0.6 < toc < 0.7  # 1 mm of a 1.5 mm move, found no later than the meshes touch


@pytest.mark.slow  # builds, simulates, draws and stages: over the fast tier's 2 s budget (tests/conftest.py)
def test_python_api_example_runs_as_written_with_public_names_only(capsys, tmp_path, monkeypatch):
    section = README.read_text().split("## Python API\n", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    imports = re.findall(r"^(?:from|import) .*$", code, re.M)
    assert imports == ["import orthosim", "from orthosim_render import render_frame"]
    assert not re.search(r"orthosim\.[a-z_]+\.", code)  # orthosim.NAME only, never a module below it
    (tmp_path / "cases").symlink_to(README.parent / "cases")  # the example's paths, from the repository root
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)
    lines = capsys.readouterr().out.strip().splitlines()
    days = [line for line in lines if line.startswith("day ")]
    assert len(days) == 6 and days[0].startswith("day 0:")  # step 0, then five steps
    for line in days:  # orthosim.contacts at a record's poses finds the pairs the step found touching
        touching, found = re.search(r"(\d+) pairs touching, (\d+) found again", line).groups()
        assert touching == found
    assert scope["record"].time_days == 5 * scope["case"].step_days
    assert "frame (480, 640, 3) uint8" in lines
    rgb = scope["rgb"]
    assert rgb._repr_png_().startswith(b"\x89PNG") and len(np.unique(rgb.reshape(-1, 3), axis=0)) > 10
    assert re.fullmatch(r"\d+ stages: holds", next(line for line in lines if " stages:" in line))
    written = tmp_path / "out" / "staging_api"
    assert {"stages.json", "staging.csv", "ipr.csv", "movement.csv", "certificate.json"} <= {p.name for p in written.iterdir()}
    assert list((written / "models").glob("stage_00_lower.stl"))
    assert lines[-1].startswith("error: cases/no_such_case.toml: no such case file")


def test_readme_names_every_run_option_and_shipped_case_and_nothing_else():
    from click.testing import CliRunner

    from orthosim.cli import main

    text = README.read_text()
    section = text.split("`run` options", 1)[1].split("###", 1)[0]
    in_readme = set(re.findall(r"`(--[a-z-]+)", section))
    help_text = CliRunner().invoke(main, ["run", "--help"], terminal_width=200).output
    in_help = set(re.findall(r"(?<![\w-])(--[a-z][a-z-]+)", help_text)) - {"--help"}
    assert in_readme == in_help
    table = text.split("The shipped cases are in `cases/`", 1)[1].split("```", 1)[0]
    listed = set(re.findall(r"^\| `([\w.]+\.toml)` \|", table, re.M))
    shipped = {p.name for p in (README.parent / "cases").glob("*.toml")}
    assert listed == shipped

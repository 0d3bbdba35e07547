"""The README's Python example runs as written and shows what it promises."""

import re
from pathlib import Path

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

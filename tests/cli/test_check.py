"""`orthosim check` reads like a linter: every problem of every file, one line each, then a count."""

import pytest
from cli_helpers import orthosim

from orthosim.errors import CaseError
from orthosim.exchange.case import load_case, read_case

THREE_PROBLEMS = """\
[case]
name = "three problems"
colour = "red"

[model]
kind = "parametric"
resolution = "coarse"

[treatment]
duration_days = 10
step_days = -1

[[loads]]
teeth = [99]
force_cN = 50
"""

GOOD = """\
[case]
name = "good"

[model]
kind = "parametric"
resolution = "coarse"

[treatment]
duration_days = 4
step_days = 2

[[loads]]
teeth = [13]
force_cN = 50
"""


def test_check_lists_every_problem_of_every_file_then_a_count_and_exits_2(tmp_path):
    three, broken, good = tmp_path / "three.toml", tmp_path / "broken.toml", tmp_path / "good.toml"
    three.write_text(THREE_PROBLEMS)
    broken.write_text('[case\nname = "x"\n')
    good.write_text(GOOD)
    done = orthosim("check", three, broken, good)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    problems, rest = done.stderr.strip().splitlines(), done.stdout.strip().splitlines()
    assert len(problems) == 4 and len(rest) == 2  # five lines, one per problem and the good file's, and the count
    assert problems[0] == f"{three}: [case] colour: unknown key; expected one of: name, description"
    assert problems[1].startswith(f"{three}: [treatment] step_days: must be positive, got -1; use a value above 0")
    assert problems[2].startswith(f"{three}: [loads[0]] teeth[0]: unknown tooth 99; use an FDI number")
    assert problems[3].startswith(f"{broken}: not valid TOML") and "fix the syntax" in problems[3]
    assert rest[0].startswith(f"{good}: ok (good;")
    assert rest[1] == "4 problems in 2 of 3 files"


def test_a_good_file_alone_exits_0():
    done = orthosim("check", "cases/normal_occlusion.toml")
    assert done.returncode == 0 and done.stderr == ""
    assert done.stdout.splitlines()[-1] == "1 file checked, no problems"


def test_every_unknown_key_is_listed_and_load_case_raises_the_first(tmp_path):
    path = tmp_path / "keys.toml"
    path.write_text(GOOD.replace("[treatment]\n", "[treatment]\nspeed = 2\nstep = 1\n").replace("[case]\n", "[case]\nauthor = 1\n"))
    case, problems = read_case(path)
    assert case is None
    assert [(p.field, p.problem) for p in problems] == [("case.author", "unknown key"), ("treatment.speed", "unknown key"),
                                                         ("treatment.step", "unknown key")]
    with pytest.raises(CaseError) as raised:
        load_case(path)
    assert str(raised.value) == str(problems[0])

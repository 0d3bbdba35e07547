"""Every number of a case must be one a real mouth allows: a value outside its range is refused
before any work, in one line naming the file, the field and the allowed range."""

from __future__ import annotations

import pytest

from orthosim.exchange.case import RANGES, load_case
from case_helpers import BASE, refused, write
from cli_helpers import orthosim as run

# (what to replace in BASE, what to put instead, the field named, the range named)
OUT_OF_RANGE = [
    ("kind = \"parametric\"", "kind = \"parametric\"\ndiastema_mm = 1e12", "model.diastema_mm", "from 0 to 10 mm"),
    ("kind = \"parametric\"", "kind = \"parametric\"\ndiastema_mm = 10.5", "model.diastema_mm", "from 0 to 10 mm"),
    ("kind = \"parametric\"", "kind = \"parametric\"\nresolution = 100000", "model.resolution", "256"),
    ("duration_days = 10", "duration_days = 4000", "treatment.duration_days", "at most 1825 days"),
    ("step_days = 1", "step_days = 400", "treatment.step_days", "at most 365 days"),
    ("force_cN = 150", "force_cN = 1e4", "loads[0].force_cN", "from 0 to 500 cN"),
    ("force_cN = 150", "force_cN = 150\nmoment_cNmm = -1e5", "loads[0].moment_cNmm", "from -5000 to 5000 cN*mm"),
    ("force_cN = 150", "force_cN = 150\nmoment_cNmm = 6000", "loads[0].moment_cNmm", "from -5000 to 5000 cN*mm"),
    ("force_cN = 150", "force_cN = 150\npoint = [0, 100, 0]", "loads[0].point", "from -30 to 30 mm"),
    ("[[loads]]", "[target.16]\nmesial_mm = 25\n[[loads]]", "target.16.mesial_mm", "20 mm"),
    ("[[loads]]", "[start.16]\nrotation_deg = 120\n[[loads]]", "start.16.rotation_deg", "90 deg"),
]


@pytest.mark.parametrize("old,new,field,allowed", OUT_OF_RANGE, ids=[f"{c[2]}={c[1].split('= ')[-1]}" for c in OUT_OF_RANGE])
def test_a_number_no_mouth_allows_is_refused_in_one_line_naming_field_and_range(tmp_path, old, new, field, allowed):
    text = BASE.replace(old, new)
    if "duration_days = 4000" in text:
        text = text.replace("step_days = 1", "step_days = 30")  # one limit at a time
    if "step_days = 400" in text:
        text = text.replace("duration_days = 10", "duration_days = 800")
    msg = refused(tmp_path, text)
    assert f"case.toml: {field}:" in msg and allowed in msg, msg


def test_the_edges_of_every_range_are_accepted(tmp_path):
    """The bounds themselves are real mouths: a 10 mm diastema, 500 cN, 5000 cN*mm, a 5-year plan."""
    text = (BASE.replace("kind = \"parametric\"", "kind = \"parametric\"\ndiastema_mm = 10")
            .replace("duration_days = 10", "duration_days = 1825").replace("step_days = 1", "step_days = 365")
            .replace("force_cN = 150", "force_cN = 500\nmoment_cNmm = -5000\npoint = [0, 30, -30]"))
    case = load_case(write(tmp_path, text))
    assert case.model.diastema_mm == RANGES["diastema_mm"][1] == 10.0
    assert case.loads[0].force_cN == 500.0 and case.loads[0].moment_cNmm == -5000.0
    assert case.duration_days == 1825.0 and case.step_days == 365.0


def test_a_diastema_of_1e12_mm_stops_orthosim_run_with_exit_2_and_one_line(tmp_path):
    """The issue's report: once a traceback from deep in the model builder (argmax of an empty sequence)."""
    case = write(tmp_path, BASE.replace("kind = \"parametric\"", "kind = \"parametric\"\ndiastema_mm = 1e12"))
    result = run("run", case, "--out", tmp_path / "out", "--no-render")
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "model.diastema_mm: must be at most 10 mm, got 1e+12" in lines[0], lines
    assert "Traceback" not in result.stderr and not (tmp_path / "out").exists()

"""A small parametric case written to a temporary folder, for the movement tests."""

from __future__ import annotations

from orthosim.exchange.case import Case, load_case


def coarse_case(tmp_path, extractions, load: str, wire: str = "rectangular", days: float = 56, step: float = 7,
                detector: str | None = None) -> Case:
    """Coarse parametric teeth with `extractions`, one `[[loads]]` entry (`load`: its TOML lines),
    `wire`, `days` of treatment in steps of `step` days and, when given, the case's `detector`."""
    p = tmp_path / "case.toml"
    detector_line = "" if detector is None else f'detector = "{detector}"\n'
    p.write_text(f"""
[model]
kind = "parametric"
resolution = "coarse"
[treatment]
extractions = {list(extractions)}
duration_days = {days}
step_days = {step}
{detector_line}[wire]
type = "{wire}"
[[loads]]
{load}
""")
    return load_case(p)

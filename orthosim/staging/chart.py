"""The staging outputs: stages.json (every tooth's pose at every stage), staging.csv (the staging
chart: one row per tooth and stage, each movement component), ipr.csv, and the summary line.

All written atomically (`orthosim.storage.atomic`); the caller writes run.json after them.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from orthosim import __version__
from orthosim.storage.atomic import write_json, write_text
from orthosim.staging.ipr import USUAL_MAX_PER_CONTACT_MM
from orthosim.staging.plan import StagingPlan
from orthosim.staging.target import COMPONENTS, UNITS

CHART_COLUMNS = ("stage", "fdi") + tuple(f"{c}_{UNITS[c]}" for c in COMPONENTS) + ("progress", "held")
IPR_COLUMNS = ("fdi_a", "fdi_b", "ipr_mm", "per_surface_mm", "before_stage", "above_guideline")


def stages_record(plan: StagingPlan, case_file: str | Path | None = None) -> dict:
    """The stages.json content: limits, counts, IPR, order constraints, and per stage FDI -> pose
    (4x4 row-major nested lists, local -> arch frame, mm)."""
    return {
        "orthosim_version": __version__,
        "case_file": None if case_file is None else str(case_file),
        "limits": {f"{c}_{UNITS[c]}": float(getattr(plan.limits, c)) for c in COMPONENTS},
        "stages": plan.n_stages,
        "lower_bound": plan.lower_bound,
        "ipr_total_mm": round(plan.ipr_total_mm, 4),
        "ipr": [{"fdi_a": r.a, "fdi_b": r.b, "ipr_mm": round(r.amount_mm, 4), "direction": r.direction} for r in plan.ipr],
        "order_constraints": list(plan.order_constraints),
        "planning_s": plan.planning_s,
        "teeth": list(plan.teeth),
        "poses": [{"stage": k, "progress": {str(n): float(plan.progress[k, i]) for i, n in enumerate(plan.teeth)},
                   "poses": {str(n): T for n, T in plan.poses(k).items()}} for k in range(plan.n_stages + 1)],
    }


def chart_csv(plan: StagingPlan) -> str:
    """staging.csv: per stage (1..N) and tooth, the stage's movement components and the progress
    (0..1) reached; `held` is 1 where the planner held the tooth back at that stage."""
    comps = plan.stage_components()
    held = set(plan.held)
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(CHART_COLUMNS)
    for k in range(plan.n_stages):
        for i, n in enumerate(plan.teeth):
            w.writerow([k + 1, n, *(f"{v:.4f}" for v in comps[k, i]), f"{plan.progress[k + 1, i]:.4f}",
                        int((k + 1, n) in held)])
    return out.getvalue()


def ipr_csv(plan: StagingPlan) -> str:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(IPR_COLUMNS)
    for r in plan.ipr:
        w.writerow([r.a, r.b, f"{r.amount_mm:.3f}", f"{r.amount_mm / 2:.3f}", 1, int(r.amount_mm > USUAL_MAX_PER_CONTACT_MM)])
    return out.getvalue()


def write_outputs(plan: StagingPlan, out_dir: str | Path, case_file: str | Path | None = None) -> dict[str, Path]:
    out_dir = Path(out_dir)
    paths = {"chart": out_dir / "staging.csv", "ipr": out_dir / "ipr.csv", "stages": out_dir / "stages.json"}
    write_text(paths["chart"], chart_csv(plan))
    write_text(paths["ipr"], ipr_csv(plan))
    write_json(paths["stages"], stages_record(plan, case_file))
    return paths


def summary_line(plan: StagingPlan, name: str = "") -> str:
    over = [f"{r.a}-{r.b}" for r in plan.ipr if r.amount_mm > USUAL_MAX_PER_CONTACT_MM]
    text = (f"{name + ': ' if name else ''}{plan.n_stages} stages (lower bound {plan.lower_bound}), "
            f"IPR total {plan.ipr_total_mm:.2f} mm at {len(plan.ipr)} contact{'s' if len(plan.ipr) != 1 else ''}")
    if over:
        text += f" ({', '.join(over)} above the usual {USUAL_MAX_PER_CONTACT_MM} mm per contact)"
    return text


def max_stage_components(plan: StagingPlan) -> np.ndarray:
    """(6,) the largest absolute stage component of any tooth (mm, mm, mm, deg, deg, deg)."""
    c = plan.stage_components()
    return np.abs(c).reshape(-1, len(COMPONENTS)).max(axis=0) if c.size else np.zeros(len(COMPONENTS))

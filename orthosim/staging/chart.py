"""The staging outputs: stages.json (every tooth's pose at every stage), staging.csv (the staging
chart: one row per tooth and stage, each movement component), ipr.csv, movement.csv (the movement
table), the summary line, and the numbers the staging page draws (`staging_chart`, `movement_table`).

All written atomically (`orthosim.storage.atomic`); the caller writes run.json after them.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orthosim import __version__
from orthosim.storage.atomic import write_json, write_text
from orthosim.staging.ipr import USUAL_MAX_PER_CONTACT_MM
from orthosim.staging.plan import StagingPlan
from orthosim.exchange.target import COMPONENTS, UNITS

CHART_COLUMNS = ("stage", "fdi") + tuple(f"{c}_{UNITS[c]}" for c in COMPONENTS) + ("progress", "held")
IPR_COLUMNS = ("fdi_a", "fdi_b", "ipr_mm", "per_surface_mm", "before_stage", "above_guideline")


def stages_record(plan: StagingPlan, case_file: str | Path | None = None) -> dict:
    """The stages.json content: the case (absolute path and SHA-256, so `stage verify` finds it and
    knows it unchanged), limits, counts, IPR, order constraints, and per stage FDI -> pose (4x4
    row-major nested lists, local -> arch frame, mm)."""
    from orthosim.storage.checksums import file_sha256

    return {
        "orthosim_version": __version__,
        "case_file": None if case_file is None else str(Path(case_file).resolve()),
        "case_sha256": None if case_file is None else file_sha256(case_file),
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
    paths["movement"] = out_dir / "movement.csv"
    write_text(paths["movement"], movement_csv(plan))
    write_json(paths["stages"], stages_record(plan, case_file))
    return paths


def summary_line(plan: StagingPlan, name: str = "") -> str:
    over = [f"{r.a}-{r.b}" for r in plan.ipr if r.amount_mm > USUAL_MAX_PER_CONTACT_MM]
    text = (f"{name + ': ' if name else ''}{plan.n_stages} stages (lower bound {plan.lower_bound}), "
            f"IPR total {plan.ipr_total_mm:.2f} mm at {len(plan.ipr)} contact{'s' if len(plan.ipr) != 1 else ''}")
    if over:
        text += f" ({', '.join(over)} above the usual {USUAL_MAX_PER_CONTACT_MM} mm per contact)"
    return text


@dataclass(frozen=True)
class MovementRow:
    """One tooth's whole movement: the movement table's row."""

    fdi: int
    totals: np.ndarray  # (6,) COMPONENTS order: mm, mm, mm, deg, deg, deg
    stages_moving: int  # stages in which the tooth moves at all
    first_stage: int | None  # first and last stage that move it (None: it stays)
    last_stage: int | None


def movement_table(plan: StagingPlan) -> list[MovementRow]:
    """Per staged tooth in FDI order, its total movement per component and the stages it moves in."""
    moves = np.diff(plan.progress, axis=0) > 0  # (stages, teeth)
    rows = []
    for n in sorted(plan.teeth):
        i = plan.teeth.index(n)
        ks = np.flatnonzero(moves[:, i]) + 1
        rows.append(MovementRow(n, plan.totals[i].copy(), len(ks), int(ks[0]) if len(ks) else None,
                                int(ks[-1]) if len(ks) else None))
    return rows


def movement_csv(plan: StagingPlan) -> str:
    """movement.csv: the movement table (one row per tooth, FDI order)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(("fdi",) + tuple(f"{c}_{UNITS[c]}" for c in COMPONENTS) + ("stages_moving", "first_stage", "last_stage"))
    for r in movement_table(plan):
        w.writerow([r.fdi, *(f"{v:.4f}" for v in r.totals), r.stages_moving, r.first_stage or "", r.last_stage or ""])
    return out.getvalue()


@dataclass(frozen=True, eq=False)
class StagingChart:
    """The staging chart's numbers: teeth (rows, FDI order) by stages (columns 1..N)."""

    teeth: tuple[int, ...]
    amounts: np.ndarray  # (teeth, stages, 6) each stage's movement, COMPONENTS order (mm, mm, mm, deg, deg, deg)
    limit_use: np.ndarray  # (teeth, stages) the largest |component| / its limit: 0 stays, 1 a full stage
    held: frozenset[tuple[int, int]]  # (stage, FDI) held back to avoid a contact
    ipr: tuple[tuple[int, int, int, float], ...]  # (stage done before, FDI a, FDI b, mm)


def staging_chart(plan: StagingPlan) -> StagingChart:
    order = [plan.teeth.index(n) for n in sorted(plan.teeth)]
    comps = plan.stage_components()[:, order, :].transpose(1, 0, 2)  # (teeth, stages, 6)
    use = (np.abs(comps) / plan.limits.array()[None, None, :]).max(axis=2) if comps.size else np.zeros((len(order), 0))
    return StagingChart(tuple(sorted(plan.teeth)), comps, use, frozenset(plan.held),
                        tuple((1, r.a, r.b, float(r.amount_mm)) for r in plan.ipr))

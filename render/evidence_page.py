"""`orthosim evidence`: the evidence table run on the model, written as evidence.json and one self-contained page.

The page counts the validation rows (not fitted: the model meets them or not) apart from the
calibration rows (their values fitted a constant, so they are inside by construction), lists the
two apart, and has one section per row: its role, source and exact figure, what was measured and
under which force system, the published mean and interval, the simulated value, inside or outside
(with the row's one-line reason when outside), and a plot (matplotlib, embedded as a PNG data URI,
so the page opens anywhere without its folder). The rows themselves are run by
`orthosim.evidence`; this module only draws and writes.
"""

from __future__ import annotations

import base64
import io
import json
import math
from pathlib import Path

from orthosim.evidence import RowResult, counts
from orthosim.storage.atomic import write_text

_PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>orthosim: clinical evidence</title>
<style>
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1100px;color:#222}
table.summary{border-collapse:collapse;width:100%;margin-bottom:2em}
table.summary td,table.summary th{border-bottom:1px solid #ccc;padding:.3em .5em;text-align:left;font-size:.9em}
.inside{color:#1a7f37;font-weight:bold}.outside{color:#b42318;font-weight:bold}.skipped{color:#777}
section{border-top:2px solid #ddd;padding-top:1em;margin-top:1.5em;display:flex;gap:1.5em}
section .text{flex:1;font-size:.92em}section img{width:460px;height:auto}
dt{font-weight:bold;margin-top:.4em}dd{margin-left:0}
</style></head><body>
<h1>Tooth movement against clinical evidence</h1>
<p><b>{{ headline }}</b>. Rate law: <b>{{ law_name }}</b> ({{ law_text }}). Each row is set up again on orthosim's
model ({{ model_text }}) and measured the way the source measured it.</p>
{% for group in groups %}<h2>{{ group.title }}</h2><p>{{ group.text }}</p>
<table class="summary" id="{{ group.role }}"><tr><th>row</th><th>topic</th><th>published</th><th>interval</th><th>simulated</th><th>verdict</th></tr>
{% for r in group.rows %}<tr><td><a href="#{{ r.id }}">{{ r.id }}</a></td><td>{{ r.topic }}</td><td>{{ r.published }}</td>
<td>[{{ r.low }}, {{ r.high }}]</td><td>{{ r.value }}</td><td class="{{ r.status }}">{{ r.status }}</td></tr>
{% endfor %}</table>
{% endfor %}{% for r in rows %}<section id="{{ r.id }}"><div class="text"><h2>{{ r.id }}</h2>
<p class="{{ r.status }}">{{ r.status }}{% if r.reason %}: {{ r.reason }}{% endif %}</p>
<dl><dt>Role</dt><dd>{{ r.role }}</dd><dt>Source</dt><dd>{{ r.source }}</dd><dt>Figure</dt><dd>{{ r.figure }}</dd>
<dt>Measured</dt><dd>{{ r.measured }}</dd><dt>Force system</dt><dd>{{ r.force_system }}</dd>
<dt>Published</dt><dd>{{ r.published }}, interval [{{ r.low }}, {{ r.high }}] {{ r.unit }}: {{ r.interval }}</dd>
<dt>Simulated</dt><dd>{{ r.value }} {{ r.unit }}: {{ r.note }}</dd></dl></div>
{% if r.plot %}<img alt="plot of {{ r.id }}" src="data:image/png;base64,{{ r.plot }}">{% endif %}</section>
{% endfor %}</body></html>
"""


def _fmt(x: float) -> str:
    return "n/a" if not math.isfinite(x) else f"{x:.3g}" if abs(x) < 1000 else f"{x:.0f}"


def plot_row(result: RowResult) -> str:
    """The row's plot as base64 PNG: its curve with the published interval (band) and the simulated value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    row, c = result.row, result.curve
    fig, ax = plt.subplots(figsize=(4.6, 3.2), dpi=100)
    try:
        if c.style == "bars":
            ax.bar(c.x, c.y, color="#7aa6d6")
            ax.set_xticks(c.x, c.ticks, rotation=90, fontsize=7)
            ax.axhspan(row.low, row.high, color="#1a7f37", alpha=0.15, label="published interval")
            ax.axhline(result.value, color="#b42318", lw=1.5, label=f"simulated mean {_fmt(result.value)}")
        elif c.series:
            for name, y in c.series.items():
                ax.plot(c.x, y, marker="o", ms=3, label=name)
            ax.axhspan(row.low, row.high, color="#1a7f37", alpha=0.15, label="published interval")
        else:
            ax.plot(c.x, c.y, color="#1f4e79", label="model")
            for name, level in c.marks.items():
                ax.axhline(level, color="#999", ls="--", lw=0.8)
                ax.annotate(name, (c.x[0], level), fontsize=7, color="#555", va="bottom")
            _mark(ax, row, result)
        ax.set_xlabel(c.x_label, fontsize=8)
        ax.set_ylabel(c.y_label, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7)
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png")
    finally:
        plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _mark(ax, row, result: RowResult) -> None:
    """Published interval and simulated value where they sit on the curve's own axes."""
    s = row.setup
    if row.kind == "rate":
        ax.errorbar([s["force_cN"]], [row.mean], yerr=[[row.mean - row.low], [row.high - row.mean]], fmt="s",
                    color="#1a7f37", label="published")
        ax.plot([s["force_cN"]], [result.value], "x", color="#b42318", ms=9, label=f"simulated {_fmt(result.value)}")
    elif row.kind == "rate_ratio":
        for f in (s["force_cN"], s["reference_force_cN"]):
            ax.axvline(f, color="#999", ls=":")
        ax.set_title(f"ratio {_fmt(result.value)}, published [{row.low:g}, {row.high:g}]", fontsize=8)
    elif row.kind == "mf_center":
        ax.axvspan(row.low, row.high, color="#1a7f37", alpha=0.15, label="published M/F")
        ax.axvline(result.value, color="#b42318", label=f"simulated {_fmt(result.value)} mm")


def _reason(result: RowResult, law_name: str) -> str:
    """The row's reason for being outside; the table's reasons are written for the clinical set."""
    if not result.reason or law_name == "clinical":
        return result.reason
    return f"outside under the {law_name!r} constants (the table's reasons are for the clinical set)"


def evidence_json(results: list[RowResult], law_name: str) -> dict:
    """evidence.json: per row its role (`fitted`), published figure, interval, simulated value and
    verdict (NaN as null); the counts of validation rows (the headline) and calibration rows apart."""
    rows = []
    for r in results:
        row = r.row
        rows.append({"id": row.id, "topic": row.topic, "fitted": row.fitted, "source": row.source, "figure": row.figure,
                     "measured": row.measured, "force_system": row.force_system, "unit": row.unit,
                     "published_mean": row.mean, "interval": [row.low, row.high], "interval_note": row.interval,
                     "model": row.model, "simulated": r.value if math.isfinite(r.value) else None,
                     "status": r.status, "inside": r.inside, "reason": _reason(r, law_name), "note": r.note})
    groups = {role: counts(results, role) for role in ("validation", "calibration")}
    return {"rate_law": law_name, "rows": rows,
            **{role: {"rows": c.rows, "inside": c.inside, "outside": c.outside, "skipped": c.skipped}
               for role, c in groups.items()},
            "inside": sum(r.status == "inside" for r in results), "outside": sum(r.status == "outside" for r in results),
            "skipped": sum(r.status == "skipped" for r in results)}


_GROUPS = (
    ("validation", "Validation", "Rows whose values fitted nothing: the model meets them, or misses them, on its own."),
    ("calibration", "Calibration", "Rows whose values fitted the rate law's constants "
     "(orthosim.evidence.calibration): inside by construction, shown to keep the fit honest."),
)


def write_evidence(results: list[RowResult], folder: Path, law_name: str, law_text: str) -> None:
    """evidence.json and index.html into `folder` (each written atomically)."""
    from jinja2 import Environment

    data = evidence_json(results, law_name)
    view = []
    for r in results:
        row = r.row
        view.append({"id": row.id, "topic": row.topic, "role": row.role, "published": f"{_fmt(row.mean)} {row.unit}",
                     "low": _fmt(row.low), "high": _fmt(row.high),
                     "unit": row.unit, "value": _fmt(r.value), "status": r.status, "reason": _reason(r, law_name),
                     "source": row.source, "figure": row.figure, "measured": row.measured,
                     "force_system": row.force_system, "interval": row.interval, "note": r.note,
                     "plot": plot_row(r) if r.curve is not None else ""})
    groups = [{"role": role, "title": title, "text": f"{counts(results, role).line()}. {text}",
               "rows": [v for v in view if v["role"] == role]} for role, title, text in _GROUPS]
    html = Environment(autoescape=True).from_string(_PAGE).render(
        rows=view, groups=groups, law_name=law_name, law_text=law_text, headline=_headline(results),
        model_text="coarse parametric model, monthly steps; the real Open-Full-Jaw patient where a row is about real "
                   "teeth; centres of resistance and rotation from each tooth's periodontal ligament")
    write_text(folder / "evidence.json", json.dumps(data, indent=2) + "\n")
    write_text(folder / "index.html", html)


def _headline(results: list[RowResult]) -> str:
    """'9 of 11 validation rows inside (1 skipped); 5 of 5 calibration rows (fitted) inside'."""
    return f"{counts(results, 'validation').line()}; {counts(results, 'calibration').line()} (fitted)"


def outcome_lines(results: list[RowResult], law_name: str, page: Path) -> list[str]:
    """What `orthosim evidence` prints: the validation count (the headline) and the calibration count,
    then one line per row outside with its role and reason."""
    lines = [f"{_headline(results)}; page: {page}"]
    for r in results:
        if r.status == "outside":
            lines.append(f"  outside ({r.row.role}): {r.row.id}: {_fmt(r.value)} {r.row.unit} not in "
                         f"[{r.row.low:g}, {r.row.high:g}]: {_reason(r, law_name)}")
    return lines

"""The staging page a clinician signs off: DIR/index.html and the charts as pictures in DIR/charts/.

    write_staging_page(run, certificate_record, out_dir, pictures=True)

What it shows, all drawn from the plan and its certificate (numbers from `orthosim.staging.chart`
and `orthosim.staging.certificate`, nothing recomputed here):
  - the staging chart: teeth (rows, FDI order) by stages (columns), each cell shaded by how much of
    its per-stage limit the tooth uses there (the largest component over its limit), held stages
    crossed, IPR marked before the stage it is done at, with the amount;
  - the IPR chart: each arch's teeth at the target seen from the occlusal side, the amount (mm) at
    each contact, contacts without reduction dotted;
  - the movement table: per tooth the whole movement per component and the stages it moves in;
  - the first and last stage from the occlusal and frontal views (the renderer; left out with
    `pictures=False`);
  - the certificate's summary and, per stage, its largest use of a limit and its least clearance.
The page is self-contained: every picture is inlined as a PNG data URI, no script, no request.
Charts are drawn with matplotlib's Agg canvas (no display); files are written atomically.
"""

from __future__ import annotations

import base64
import io
from pathlib import Path

import numpy as np

from orthosim import __version__
from orthosim.model import fdi as F
from orthosim.staging.chart import movement_table, staging_chart
from orthosim.exchange.target import COMPONENTS, UNITS
from orthosim.storage.atomic import write_bytes, write_text

DPI = 110
PICTURE_VIEWS = ("maxillary_occlusal", "mandibular_occlusal", "frontal")
PICTURE_SIZE = (480, 360)
IPR_COLOR = "#c8202a"
HELD_COLOR = "#7a7f87"
COMPONENT_LETTERS = "MBETQR"  # mesial, buccal, extrusion (mm); tip, torque (Q), rotation (degrees)


def _figure(w_in: float, h_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight", metadata={"Software": None})
    return buf.getvalue()


def _short(value: float) -> str:
    """'+.25' for 0.25, '-2.00' for -2: signed, two decimals, no leading zero."""
    text = f"{value:+.2f}"
    return text[0] + text[2:] if text[1:3] == "0." else text


def staging_chart_png(plan) -> bytes:
    """The staging chart (see the module docstring) as PNG bytes."""
    chart = staging_chart(plan)
    n_teeth, n_stages = chart.limit_use.shape
    fig = _figure(max(6.0, 1.6 + 0.32 * n_stages), max(3.0, 0.9 + 0.24 * n_teeth))
    ax = fig.subplots()
    shown = np.where(chart.limit_use > 0, chart.limit_use, np.nan)
    image = ax.imshow(shown, cmap="Blues", vmin=0.0, vmax=1.0, aspect="auto", interpolation="nearest",
                      extent=(0.5, n_stages + 0.5, n_teeth - 0.5, -0.5))
    row = {n: i for i, n in enumerate(chart.teeth)}
    if n_stages <= 24:
        for i in range(n_teeth):
            for k in range(n_stages):
                c = chart.amounts[i, k]
                if chart.limit_use[i, k] > 0:
                    j = int(np.argmax(np.abs(c) / plan.limits.array()))
                    ax.text(k + 1, i, COMPONENT_LETTERS[j] + _short(c[j]), ha="center", va="center",
                            fontsize=5.5, color="white" if chart.limit_use[i, k] > 0.6 else "#1d2b3a")
    for stage, n in chart.held:
        ax.plot(stage, row[n], marker="x", color=HELD_COLOR, markersize=5)
    for stage, a, b, mm in chart.ipr:
        for n in (a, b):
            ax.plot(stage - 0.5, row[n], marker="D", color=IPR_COLOR, markersize=5, clip_on=False)
    if chart.ipr:
        text = "IPR: " + ", ".join(f"{a}/{b} {mm:.2f} mm before stage {stage}" for stage, a, b, mm in chart.ipr)
        ax.text(0.0, -0.08 - 0.6 / n_teeth, text, transform=ax.transAxes, color=IPR_COLOR, fontsize=8, va="top")
    ax.set_yticks(range(n_teeth), [str(n) for n in chart.teeth], fontsize=7)
    step = max(1, n_stages // 30)
    ax.set_xticks(range(1, n_stages + 1, step))
    ax.tick_params(axis="x", labelsize=7)
    ax.set_xlabel("stage (aligner)")
    ax.set_ylabel("tooth (FDI)")
    ax.set_title("Staging chart: share of the per-stage limit used (largest component); x held back, "
                 "\u25c6 IPR before the stage\ncells: the largest component (M mesial, B buccal, E extrusion mm; "
                 "T tip, Q torque, R rotation deg)", fontsize=8)
    cb = fig.colorbar(image, ax=ax, fraction=0.03, pad=0.02)
    cb.set_label("largest |component| / its limit", fontsize=7)
    cb.ax.tick_params(labelsize=7)
    return _png(fig)


def ipr_chart_png(dentition, plan) -> bytes:
    """The IPR chart: both arches at the target from the occlusal side, mm at each contact."""
    from orthosim.collision.broadphase import arch_neighbour_pairs

    target = plan.target
    centres = {n: dentition.teeth[n].to_world(dentition.teeth[n].crown_center, target[n]) for n in plan.teeth}
    ipr = {(r.a, r.b): r.amount_mm for r in plan.ipr}
    fig = _figure(7.0, 8.4)
    axes = fig.subplots(2, 1)  # upper arch above, lower below, incisors facing each other
    for ax, (arch, title) in zip(axes, ((F.Arch.UPPER, "upper arch"), (F.Arch.LOWER, "lower arch"))):
        teeth = [n for n in plan.teeth if F.arch_of(n) is arch]
        ax.set_aspect("equal")
        ax.axis("off")
        if not teeth:
            ax.set_visible(False)
            continue
        for n in teeth:  # occlusal view: x across, z toward the front, as seen from below/above
            x, z = centres[n][0], centres[n][2]
            width = float(np.ptp(dentition.teeth[n].crown_vertices @ dentition.teeth[n].mesial))
            ax.add_patch(_circle((x, z), 0.45 * width))
            ax.text(x, z, str(n), ha="center", va="center", fontsize=7)
        for a, b in arch_neighbour_pairs(teeth):
            key = (min(a, b), max(a, b))
            p = 0.5 * (centres[a] + centres[b])
            if key in ipr:
                ax.plot(p[0], p[2], marker="D", color=IPR_COLOR, markersize=5)
                out = p[[0, 2]] - np.mean([centres[n][[0, 2]] for n in teeth], axis=0)
                out = out / (np.linalg.norm(out) or 1.0)
                ax.annotate(f"{ipr[key]:.2f}", (p[0], p[2]), xytext=tuple(22 * out), textcoords="offset points",
                            color=IPR_COLOR, fontsize=8, ha="center", va="center", weight="bold",
                            arrowprops={"arrowstyle": "-", "color": IPR_COLOR, "lw": 0.6})
            else:
                ax.plot(p[0], p[2], marker=".", color="#b0b4ba", markersize=3)
        total = sum(mm for (a, b), mm in ipr.items() if F.arch_of(a) is arch)
        ax.set_title(f"{title}: IPR {total:.2f} mm in all (mm per contact)", fontsize=9)
        ax.autoscale_view()
        ax.margins(0.12)
        if arch is F.Arch.UPPER:
            ax.invert_yaxis()  # front teeth at the top for both arches
    return _png(fig)


def _circle(xy, r):
    from matplotlib.patches import Circle

    return Circle(xy, r, facecolor="#f3efe4", edgecolor="#6b6f76", lw=0.8)


def stage_pictures(run, stages: tuple[int, ...], size=PICTURE_SIZE) -> dict[int, dict[str, bytes]]:
    """stage -> view -> PNG bytes of the crowns at that stage, FDI labels drawn on."""
    from orthosim_render.frame_state import FrameState
    from orthosim_render.overlay import blend, font_px_for, label_view, text_patch
    from orthosim_render.png import encode_png
    from orthosim_render.renderer import Renderer
    from orthosim_render.scene import DentitionScene

    dent, plan = run.dentition, run.plan
    extracted = frozenset(n for n in dent.fdis if n not in plan.teeth)
    rest = dent.rest_poses()
    out: dict[int, dict[str, bytes]] = {}
    px = font_px_for(size)
    with Renderer(size) as renderer:
        scene = DentitionScene(dent, size, hide_roots=True, show_markers=False)
        for k in stages:
            poses = {**rest, **plan.poses(k)}
            scene.update(FrameState(poses=poses, extracted=extracted))
            out[k] = {}
            for view in PICTURE_VIEWS:
                image = renderer.render(scene, view)
                label_view(image, scene.view(view), dent, poses, plan.teeth, extracted, px)
                blend(image, text_patch(f"stage {k} | {view.replace('_', ' ')}", px), 4, 4)
                out[k][view] = encode_png(image)
    return out


def _data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def page_data(run, certificate: dict, charts: dict[str, bytes], pictures: dict[int, dict[str, bytes]]) -> dict:
    """Everything the template shows (numbers already computed; pictures as data URIs)."""
    plan = run.plan
    rows = [{"fdi": r.fdi, "totals": [float(v) for v in r.totals], "stages": r.stages_moving,
             "span": "" if r.first_stage is None else f"{r.first_stage}-{r.last_stage}"} for r in movement_table(plan)]
    per_stage = []
    for t in certificate["transitions"]:
        moving = [x for x in t["teeth"] if x["largest_ratio"] > 0]
        worst = max(t["teeth"], key=lambda x: x["largest_ratio"])
        least = min((c for c in t["clearances"] if c["relative_motion"]), key=lambda c: c["min_clearance_mm"], default=None)
        per_stage.append({"stage": t["stage"], "moving": len(moving), "largest_ratio": worst["largest_ratio"],
                          "largest_fdi": worst["fdi"], "within": t["within_limits"], "contact_free": t["contact_free"],
                          "least": least, "pairs": len(t["clearances"]), "ipr": t["ipr"]})
    return {
        "version": __version__, "name": run.case.name, "description": getattr(run.case, "description", ""),
        "stages": plan.n_stages, "lower_bound": plan.lower_bound, "teeth": len(plan.teeth),
        "limits": [(c, UNITS[c], float(getattr(plan.limits, c))) for c in COMPONENTS],
        "components": [f"{c} ({UNITS[c]})" for c in COMPONENTS], "movement": rows,
        "ipr": [{"a": r.a, "b": r.b, "mm": r.amount_mm} for r in plan.ipr], "ipr_total": plan.ipr_total_mm,
        "order_constraints": list(plan.order_constraints), "summary": certificate["summary"],
        "method": certificate["method"], "per_stage": per_stage,
        "charts": {k: _data_uri(v) for k, v in charts.items()},
        "pictures": [{"stage": k, "views": [{"view": v.replace("_", " "), "src": _data_uri(png)} for v, png in views.items()]}
                     for k, views in pictures.items()],
    }


def render_page(data: dict) -> str:
    """index.html from the page data (Jinja2, autoescaped)."""
    from jinja2 import Environment, FileSystemLoader, StrictUndefined, select_autoescape

    env = Environment(loader=FileSystemLoader(Path(__file__).parent / "report" / "templates"),
                      autoescape=select_autoescape(["html", "j2"]), undefined=StrictUndefined,
                      trim_blocks=True, lstrip_blocks=True)
    return env.get_template("staging.html.j2").render(page=data)


def write_staging_page(run, certificate: dict, out_dir: str | Path, pictures: bool = True,
                       size: tuple[int, int] = PICTURE_SIZE, viewer: bool = False) -> Path:
    """Write charts/staging_chart.png, charts/ipr_chart.png and index.html into out_dir; returns the page.
    viewer: the page embeds viewer.html, the staging's 3D page written beside it (`orthosim_render.viewer_page`)."""
    out_dir = Path(out_dir)
    charts = {"staging": staging_chart_png(run.plan), "ipr": ipr_chart_png(run.dentition, run.plan)}
    for name, png in charts.items():
        write_bytes(out_dir / "charts" / f"{name}_chart.png", png)
    shots = stage_pictures(run, (0, run.plan.n_stages), size) if pictures else {}
    for k, views in shots.items():
        for view, png in views.items():
            write_bytes(out_dir / "charts" / f"stage_{k:02d}_{view}.png", png)
    page = out_dir / "index.html"
    write_text(page, render_page({**page_data(run, certificate, charts, shots), "viewer": "viewer.html" if viewer else None}))
    return page

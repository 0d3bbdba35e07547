"""`orthosim report`: from finished runs to DIR/index.html, DIR/report.json and DIR/report.pdf.

    build_report(run_dirs, out_dir, pdf=True)

report.json holds every figure the page shows, and the page is rendered from that same data
(a Jinja2 template, autoescaped), so the two cannot disagree. Pictures and plots are PNGs in
DIR/img/ beside the page, referenced by relative paths: the folder opens offline in any browser
and can be moved or zipped whole. Every file is written atomically; index.html is written last.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Sequence

from orthosim import __version__
from orthosim.storage.atomic import write_json, write_text
from orthosim.analysis.distancemap import CLASS_NAMES, CONTACT_MM, NEAR_MM, summarize
from orthosim.analysis.spaceanalysis import GAP_THRESHOLD_MM

from orthosim_render.report import figures
from orthosim_render.report.gather import CaseData, build_dentitions, gather_case, group_runs
from orthosim_render.report.pictures import CONTACT_VIEWS, MAP_VIEWS, VIEW_TITLES, CasePictures, pose_label
from orthosim_render.report.runs import RunData, read_run

TARGET_FPS = 40.0
PICTURE_SIZE = (480, 360)


def _slug(text: str) -> str:
    keep = "".join(c if c.isalnum() else "-" for c in text.lower())
    return "-".join(p for p in keep.split("-") if p)[:60] or "case"


def _shown_path(path: Path) -> str:
    """`path` relative to the working folder when it lies inside it (a report is read elsewhere)."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def case_record(data: CaseData, images: dict) -> dict:
    """Everything the page shows about one case, ready for JSON (mm, degrees, days, per cent)."""
    runs = {}
    for det, r in data.runs.items():
        m = r.metrics
        runs[det] = {
            "run_dir": str(r.run_dir),
            "steps": m["steps"],
            "total_distance_mm": m["total_distance_mm"],
            "max_penetration_mm": m["max_penetration_mm"],
            "initial_penetration_mm": m["initial_penetration_mm"],
            "collisions": m["collisions"],
            "distances": m["distances"],
            "teeth": {n: {**{k: t[k] for k in ("moved_mm", "rotated_deg", "extracted")}, "root": t.get("root")}
                      for n, t in m["teeth"].items()},
            "totals_over_days": [{"day": s["time_days"], "total_mm": s["total_distance_mm"]} for s in r.steps],
            "final_day": r.steps[-1]["time_days"],
            "bite": m.get("bite"),
        }
    throughput = {}
    for det, r in data.runs.items():
        t = dict(r.throughput)
        t["target_fps"] = TARGET_FPS
        t["meets_target"] = None if t["fps"] is None else bool(t["fps"] >= TARGET_FPS)
        throughput[det] = t
    fits = {str(n): {"leaves": f.leaves, "sov_sum": f.sov_sum, "sov_sum_stderr": f.sov_sum_stderr,
                     "surface_coverage": f.surface_coverage, "interior_coverage": f.interior_coverage}
            for n, f in data.fits.items()}
    first = next(iter(data.runs.values()))
    return {
        "name": data.name,
        "case_file": _shown_path(data.case_file),
        "case_sha256": data.case_sha256,
        "extracted": list(data.extracted),
        # teeth whose root was built for a crown-only input (orthosim.model.rootsynthesis), not scanned
        "estimated_roots": [n for n in data.dentition.fdis if data.dentition.teeth[n].root_kind == "estimated"],
        "duration_days": first.duration_days,
        "detectors": data.detectors,
        "poses": {p: pose_label(p) for p in data.pose_names},
        "runs": runs,
        "distance_map": {p: summarize(m) for p, m in data.inter_arch.items()},
        "contact_areas": {p: summarize(m) for p, m in data.contact_areas.items()},
        "contacts": {det: [row.as_dict() for row in rows] for det, rows in data.contacts.items()},
        "largest_interpenetration_mm": {det: data.runs[det].metrics["max_penetration_mm"] for det in data.runs},
        "space_analysis": {p: {a: s.as_dict() for a, s in arches.items()} for p, arches in data.space.items()},
        "bolton_percent": data.bolton,
        "widths_mm": {str(n): w for n, w in data.widths_mm.items()},
        "sphere_tree_fit": fits,
        "sphere_tree_fit_mean_sov_sum": (sum(f["sov_sum"] for f in fits.values()) / len(fits)) if fits else None,
        "throughput": throughput,
        "evidence_rows": [{"id": m.row_id, "topic": m.topic, "why": m.why} for m in data.evidence],
        "images": images,
    }


def build_report(runs: Sequence[RunData | str | Path], out_dir: str | Path, *, pdf: bool = False,
                 size: tuple[int, int] = PICTURE_SIZE, fits: bool = True, progress=None) -> dict:
    """Write the report of `runs` (RunData or run folders) into out_dir; returns the report.json data."""
    started = time.perf_counter()
    out_dir = Path(out_dir)
    runs = [r if isinstance(r, RunData) else read_run(r) for r in runs]
    groups = group_runs(runs)
    img = out_dir / "img"
    img.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda text: None)

    from orthosim_render.renderer import Renderer

    cases = []
    dentitions = build_dentitions(groups)  # before the renderer's GL context: builds in forked processes
    used_slugs: set[str] = set()
    figures.distance_colorbar(img / "distance-colorbar.png")
    with Renderer(size) as renderer:
        for group in groups:
            say(f"{group[0].case_name}: {', '.join(r.detector for r in group)}")
            data = gather_case(group, dentitions, fits=fits)
            slug = _slug(data.name)
            while slug in used_slugs:
                slug += "-x"
            used_slugs.add(slug)
            pics = CasePictures(renderer, data, size)
            images: dict = {"contacts": {}, "distance_map": {}}
            for pose in data.pose_names:
                images["contacts"][pose] = {v: pics.contacts(pose, v, img / f"{slug}-contacts-{pose}-{v}.png").path.name
                                            for v in CONTACT_VIEWS}
                images["distance_map"][pose] = {v: pics.distance_map(pose, v, img / f"{slug}-map-{pose}-{v}.png").path.name
                                                for v in MAP_VIEWS}
            images["distance_bars"] = figures.distance_bars(data, img / f"{slug}-distances.png").name
            images["total_lines"] = figures.total_lines(data, img / f"{slug}-totals.png").name
            images = _prefixed(images, "img/")
            record = case_record(data, images)
            record["anchor"] = slug
            record["viewer"] = _case_viewer(data, out_dir, slug)
            cases.append(record)
    report = {
        "orthosim_version": __version__,
        "target_fps": TARGET_FPS,
        "thresholds_mm": {"contact": CONTACT_MM, "near": NEAR_MM, "clinical_gap": GAP_THRESHOLD_MM},
        "distance_classes": list(CLASS_NAMES),
        "colorbar": "img/distance-colorbar.png",
        "cases": cases,
        "build_s": time.perf_counter() - started,
    }
    write_json(out_dir / "report.json", report)
    write_text(out_dir / "index.html", render_page(report))
    if pdf:
        from orthosim_render.report.browser import print_pdf

        print_pdf(out_dir / "index.html", out_dir / "report.pdf")
    report["build_s"] = time.perf_counter() - started
    return report


def _case_viewer(data: CaseData, out_dir: Path, slug: str) -> str:
    """scenes/<slug>/viewer.html (and animation.glb): the contact figure's poses in 3D; its path in the report."""
    from orthosim_render.viewer_page import write_pose_viewer

    page = write_pose_viewer(data, out_dir / "scenes" / slug)["viewer"]
    return page.relative_to(out_dir).as_posix()


def _prefixed(images, prefix: str):
    if isinstance(images, dict):
        return {k: _prefixed(v, prefix) for k, v in images.items()}
    return prefix + images


def render_page(report: dict) -> str:
    """index.html from the report data (Jinja2, autoescaped)."""
    from jinja2 import Environment, FileSystemLoader, StrictUndefined, select_autoescape

    env = Environment(loader=FileSystemLoader(Path(__file__).parent / "templates"),
                      autoescape=select_autoescape(["html", "j2"]), undefined=StrictUndefined,
                      trim_blocks=True, lstrip_blocks=True)
    env.filters["mm"] = lambda v, digits=2: "–" if v is None else f"{v:.{digits}f}"
    return env.get_template("report.html.j2").render(report=report, view_titles=VIEW_TITLES,
                                                     contact_views=CONTACT_VIEWS, map_views=MAP_VIEWS)

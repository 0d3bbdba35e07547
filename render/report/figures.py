"""The report's plots, drawn with matplotlib's Agg canvas (no pyplot, no display): the paper's
distance figures (Figures 3-5) per case, and the distance map's colour bar.

  - tooth-to-tooth distance per adjacent pair (the paper's centre distance in the occlusal plane):
    the initial value and each detector's final value as bars, one panel per arch, with a tick per
    pair where the gap between the two crowns would pass the 1 mm clinical threshold (centre
    distance = half of each mesiodistal width + 1 mm);
  - the total over the arch against treatment days, one line per detector.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from orthosim.storage.atomic import write_bytes
from orthosim.analysis.distancemap import CONTACT_MM, NEAR_MM
from orthosim.model.fdi import Arch, arch_of
from orthosim.analysis.spaceanalysis import GAP_THRESHOLD_MM

DETECTOR_COLORS = {"circles": "#e0882b", "discrete": "#3c78c8", "continuous": "#2e9e5b", "exact": "#8a4fbf"}
INITIAL_COLOR = "#9aa0a8"
DPI = 110


def _figure(w_in: float, h_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, out: Path) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight", metadata={"Software": None})
    write_bytes(out, buf.getvalue())
    return out


def distance_bars(data, out: Path) -> Path:
    """Per adjacent pair: initial and each detector's final tooth-to-tooth distance (mm)."""
    detectors = data.detectors
    first = data.runs[detectors[0]].metrics["distances"]
    fig = _figure(11.0, 6.4)
    axes = fig.subplots(2, 1)
    for ax, arch in zip(axes, (Arch.UPPER, Arch.LOWER)):
        rows = [i for i, r in enumerate(first) if arch_of(r["pair"][0]) is arch]
        if not rows:
            ax.set_visible(False)
            continue
        x = np.arange(len(rows))
        n_bars = 1 + len(detectors)
        width = 0.8 / n_bars
        ax.bar(x - 0.4 + width / 2, [first[i]["initial_mm"] for i in rows], width, color=INITIAL_COLOR, label="initial")
        for k, det in enumerate(detectors, start=1):
            dist = data.runs[det].metrics["distances"]
            ax.bar(x - 0.4 + width * (k + 0.5), [dist[i]["final_mm"] for i in rows], width,
                   color=DETECTOR_COLORS.get(det, None), label=f"final, {det}")
        pairs = [tuple(first[i]["pair"]) for i in rows]
        limit = [(data.widths_mm[a] + data.widths_mm[b]) / 2 + GAP_THRESHOLD_MM for a, b in pairs]
        ax.hlines(limit, x - 0.45, x + 0.45, colors="#c0143c", linewidth=1.6,
                  label=f"gap of {GAP_THRESHOLD_MM:g} mm (clinical threshold)")
        ax.set_xticks(x, [f"{a}-{b}" for a, b in pairs], fontsize=8)
        ax.set_ylabel("distance (mm)")
        ax.set_title(f"{'maxillary' if arch is Arch.UPPER else 'mandibular'} arch: tooth-to-tooth distance per adjacent pair",
                     fontsize=10)
        top = max(max(limit), max(first[i]["initial_mm"] for i in rows))
        ax.set_ylim(0, top * 1.12)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.14), frameon=False)
    fig.tight_layout()
    return _save(fig, out)


def total_lines(data, out: Path) -> Path:
    """The summed tooth-to-tooth distance (mm) against treatment days, one line per detector."""
    fig = _figure(7.5, 3.8)
    ax = fig.subplots()
    for det in data.detectors:
        steps = data.runs[det].steps
        ax.plot([s["time_days"] for s in steps], [s["total_distance_mm"] for s in steps], label=det,
                color=DETECTOR_COLORS.get(det, None), linewidth=1.8)
    ax.set_xlabel("treatment day")
    ax.set_ylabel("total tooth-to-tooth distance (mm)")
    ax.set_title("total over both arches (smaller: a closer fit)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, out)


def distance_colorbar(out: Path) -> Path:
    """The distance map's colour bar: penetration, contact, near (graded) and far."""
    from matplotlib.colors import LinearSegmentedColormap
    from matplotlib.patches import Rectangle

    from orthosim_render.scene import CONTACT_COLOR, CROWN_COLOR
    from orthosim_render.report.pictures import NEAR_STOPS, PENETRATION_COLOR

    fig = _figure(7.5, 0.95)
    ax = fig.add_axes([0.03, 0.45, 0.94, 0.32])
    # contact is narrow on a mm scale: it gets a block of its own, as penetration and far do,
    # and the graded part from CONTACT_MM to NEAR_MM is drawn to scale
    ax.add_patch(Rectangle((-0.9, 0), 0.5, 1, color=PENETRATION_COLOR))
    ax.add_patch(Rectangle((-0.4, 0), 0.5, 1, color=CONTACT_COLOR))
    ax.add_patch(Rectangle((NEAR_MM, 0), 0.5, 1, color=CROWN_COLOR, ec="#555"))
    cmap = LinearSegmentedColormap.from_list("near", [(s, c) for s, c in NEAR_STOPS])
    ax.imshow(np.linspace(0, 1, 256)[None], extent=(CONTACT_MM, NEAR_MM, 0, 1), aspect="auto", cmap=cmap)
    ax.set_xlim(-0.9, NEAR_MM + 0.5)
    ax.set_ylim(0, 1)
    ax.set_yticks([])
    ticks = [-0.65, -0.15, 0.1, 0.5, 1.0, 1.5, NEAR_MM, NEAR_MM + 0.25]
    ax.set_xticks(ticks, ["penetration", f"contact\n< {CONTACT_MM:g} mm", f"{CONTACT_MM:g}", "0.5", "1", "1.5",
                          f"{NEAR_MM:g} mm", "far"], fontsize=8)
    ax.set_title("distance to the opposing arch (exact, on the meshes)", fontsize=9)
    return _save(fig, out)

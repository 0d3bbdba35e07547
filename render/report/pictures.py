"""The report's rendered pictures: occlusal contact areas (the paper's Figure 7) and the inter-arch
distance map, each from the clinical views, before and after treatment, with FDI labels, a legend,
the extraction gaps and a scale bar drawn on by `orthosim_render.overlay`.

One renderer (one GL context) for the whole report and one scene per dentition; crowns only (the
roots would hide the occlusal surfaces the figures are about); each picture is a PNG beside the page.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orthosim.storage.atomic import write_bytes
from orthosim.analysis.distancemap import CONTACT_MM, NEAR_MM, PENETRATION, CONTACT, NEAR, classify
from orthosim.model.fdi import arch_of

from orthosim_render.frame_state import FrameState
from orthosim_render.overlay import (GAP_COLOR, blend, draw_scale_bar, font_px_for, label_view, legend_patch, text_patch)
from orthosim_render.png import encode_png
from orthosim_render.scene import CONTACT_COLOR, CROWN_COLOR, DentitionScene, paint_crowns

CONTACT_VIEWS = ("maxillary_occlusal", "mandibular_occlusal", "frontal")
MAP_VIEWS = ("maxillary_occlusal", "mandibular_occlusal")
VIEW_TITLES = {"maxillary_occlusal": "maxillary occlusal", "mandibular_occlusal": "mandibular occlusal",
               "frontal": "frontal"}
PENETRATION_COLOR = (0.42, 0.0, 0.62)  # deep violet: unlike any lit enamel or the contact red
# near: orange at CONTACT_MM through yellow and green to blue at NEAR_MM (far keeps the enamel colour)
NEAR_STOPS = ((0.0, (1.00, 0.55, 0.00)), (0.33, (1.00, 0.84, 0.00)), (0.66, (0.36, 0.78, 0.36)), (1.0, (0.23, 0.48, 0.84)))


def _rgb8(c) -> tuple[int, int, int]:
    return tuple(int(round(255 * v)) for v in c)


def near_color(distance_mm: np.ndarray) -> np.ndarray:
    """(n,) mm in [CONTACT_MM, NEAR_MM] -> (n, 3) linear RGB along NEAR_STOPS."""
    t = np.clip((np.asarray(distance_mm, float) - CONTACT_MM) / (NEAR_MM - CONTACT_MM), 0.0, 1.0)
    xs = [s for s, _ in NEAR_STOPS]
    return np.stack([np.interp(t, xs, [c[i] for _, c in NEAR_STOPS]) for i in range(3)], axis=1)


def distance_colors(distance_mm: np.ndarray) -> np.ndarray:
    """(n,) signed mm -> (n, 3) colours of the distance map: penetration, contact, near (graded), far."""
    d = np.asarray(distance_mm, float)
    cls = classify(d)
    out = np.tile(np.asarray(CROWN_COLOR, float), (len(d), 1))
    out[cls == PENETRATION] = PENETRATION_COLOR
    out[cls == CONTACT] = CONTACT_COLOR
    near = cls == NEAR
    out[near] = near_color(d[near])
    return out


def contact_colors(distance_mm: np.ndarray) -> np.ndarray:
    """(n,) signed mm -> (n, 3): contact (< CONTACT_MM) in the contact red, interpenetration violet,
    the rest enamel: the paper's Figure 7."""
    d = np.asarray(distance_mm, float)
    cls = classify(d)
    out = np.tile(np.asarray(CROWN_COLOR, float), (len(d), 1))
    out[cls == CONTACT] = CONTACT_COLOR
    out[cls == PENETRATION] = PENETRATION_COLOR
    return out


CONTACT_LEGEND = ((f"contact (< {CONTACT_MM:g} mm)", _rgb8(CONTACT_COLOR), "box"),
                  ("interpenetration", _rgb8(PENETRATION_COLOR), "box"), ("extracted (gap)", GAP_COLOR, "ring"))
MAP_LEGEND = (("extracted (gap)", GAP_COLOR, "ring"),)


@dataclass(frozen=True)
class Picture:
    path: Path  # where the PNG was written
    kind: str  # "contacts" | "distance_map"
    pose: str  # "initial" or a detector name
    view: str


class CasePictures:
    """Draws one case's pictures with a shared renderer; `render(...)` writes one PNG and returns it."""

    def __init__(self, renderer, data, size: tuple[int, int]):
        self.renderer = renderer
        self.data = data
        self.size = size
        self.scene = DentitionScene(data.dentition, size, hide_roots=True, show_markers=False)
        self.font_px = font_px_for(size)

    def _draw(self, pose_name: str, view: str, colors: dict[int, np.ndarray], title: str, legend) -> np.ndarray:
        d = self.data
        poses = d.poses[pose_name]
        paint_crowns(self.scene, colors)
        state = FrameState(poses=poses, extracted=frozenset(d.extracted))
        self.scene.update(state)
        image = self.renderer.render(self.scene, view)
        # a band below the picture for the legend and the scale bar, so they never cover a tooth
        band_h = 2 * self.font_px + 4
        band = np.empty((band_h, image.shape[1], image.shape[2]), np.uint8)
        band[:] = image[0, 0]
        image = np.concatenate([image, band])
        cam = self.scene.view(view)
        shown = [n for n in d.present if arch_of(n) in cam.arches]
        label_view(image, cam, d.dentition, poses, shown, d.extracted, self.font_px)
        m = max(4, self.font_px // 2)
        blend(image, text_patch(title, self.font_px), m, m)
        day = _day_text(d, pose_name)
        patch = text_patch(day, self.font_px)
        blend(image, patch, image.shape[1] - patch.shape[1] - m, m)
        leg = legend_patch(max(9, self.font_px - 2), legend, horizontal=True)
        blend(image, leg, m, image.shape[0] - leg.shape[0] - 3)
        centre = np.mean([d.dentition.teeth[n].to_world(d.dentition.teeth[n].crown_center, poses[n]) for n in shown], axis=0)
        draw_scale_bar(image, cam, centre, self.size, 10.0, self.font_px)
        return image

    def contacts(self, pose_name: str, view: str, out: Path) -> Picture:
        """The contact areas of `pose_name` from `view` (the paper's Figure 7), written to `out`."""
        return self._picture("contacts", self.data.contact_areas[pose_name], contact_colors, CONTACT_LEGEND,
                             pose_name, view, out)

    def distance_map(self, pose_name: str, view: str, out: Path) -> Picture:
        """The inter-arch distance map of `pose_name` from `view`, written to `out`."""
        return self._picture("distance_map", self.data.inter_arch[pose_name], distance_colors, MAP_LEGEND,
                             pose_name, view, out)

    def _picture(self, kind: str, maps, colouring, legend, pose_name: str, view: str, out: Path) -> Picture:
        colors = {n: colouring(m.distance_mm) for n, m in maps.items()}
        image = self._draw(pose_name, view, colors, f"{VIEW_TITLES[view]} | {pose_label(pose_name)}", legend)
        write_bytes(out, encode_png(image))
        return Picture(out, kind, pose_name, view)


def pose_label(pose_name: str) -> str:
    return "before" if pose_name == "initial" else f"after, {pose_name}"


def _day_text(data, pose_name: str) -> str:
    run = next(iter(data.runs.values())) if pose_name == "initial" else data.runs[pose_name]
    day = 0.0 if pose_name == "initial" else run.steps[-1]["time_days"]
    return f"day {day:g} of {run.duration_days:g}"

"""The viewer page checked against orthosim's own frames, through per-tooth ids (tests and the bench).

`viewer.html` has a test mode (URL fragment `test&step=K&view=NAME&w=W&h=H`) in which it draws
every tooth in a flat id colour at W x H and writes each tooth's pixel count and centroid into the
page (`<html data-viewer-test>`). Headless Chromium opens it (WebGL2 through SwiftShader, the
software GPU Chromium ships); the same step and view drawn by the offscreen label pass
(`orthosim_render.semantic_labels`) gives the same figures from our renderer. Pixel equality across
two renderers is not the claim: the same teeth visible, each tooth's centroid within a few pixels.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

WEBGL_FLAGS = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader")
_PROBE = "JSON.stringify({test: document.documentElement.dataset.viewerTest || null, " \
         "drawn: document.documentElement.dataset.drawn || null, errors: document.documentElement.dataset.errors || null, " \
         "frame_ms: FRAMES && window.orthosimViewer ? window.orthosimViewer.frameMs(FRAMES) : null})"


@dataclass(frozen=True)
class ToothPicture:
    """Each visible tooth of one picture: FDI -> (pixels, (column, row) centroid, row 0 at the top)."""

    teeth: dict[int, tuple[int, tuple[float, float]]]
    size: tuple[int, int]

    def visible(self, min_pixels: int) -> set[int]:
        return {n for n, (count, _) in self.teeth.items() if count >= min_pixels}


@dataclass(frozen=True)
class ViewerLoad:
    """What opening the page showed: its id picture (test mode), its console errors, when it first drew."""

    picture: ToothPicture | None
    errors: list[str] = field(default_factory=list)
    drawn_ms: float | None = None  # ms from navigation to the first drawn frame
    screenshot_png: bytes = b""
    frame_ms: float | None = None  # ms to draw one frame, over `measure_frames` frames (asked for)


def open_viewer(page: str | Path, *, step: int | None = None, view: str = "frontal", size: tuple[int, int] = (320, 240),
                test: bool = True, screenshot: bool = False, window: tuple[int, int] = (640, 480),
                timeout_s: float = 120.0, measure_frames: int = 0) -> ViewerLoad:
    """Open `page` in headless Chromium at keyframe `step` and `view` (test mode: the id picture at
    `size`); `screenshot`: also the page as a reader sees it at `window`, its panels hidden;
    `measure_frames`: draw that many frames after loading and time them."""
    from orthosim_render.report.browser import load_page

    parts = (["test", f"w={size[0]}", f"h={size[1]}"] if test else []) + [f"view={view}"]
    parts += [f"step={step}"] if step is not None else []
    parts += ["bare=1"] if screenshot else []
    loaded = load_page(page, screenshot=screenshot, window=window, timeout_s=timeout_s, fragment="&".join(parts),
                       extra_flags=WEBGL_FLAGS, evaluate=_PROBE.replace("FRAMES", str(int(measure_frames))))
    probe = json.loads(loaded.value or "{}")
    errors = list(loaded.problems) + (json.loads(probe["errors"]) if probe.get("errors") else [])
    picture = None
    if probe.get("test"):
        data = json.loads(probe["test"])
        picture = ToothPicture({int(k): (int(v["pixels"]), tuple(v["centroid"])) for k, v in data["teeth"].items()},
                               tuple(data["size"]))
    drawn = float(probe["drawn"]) if probe.get("drawn") else None
    return ViewerLoad(picture, errors, drawn, loaded.screenshot_png, probe.get("frame_ms"))


def label_picture(dentition, state, view: str, size: tuple[int, int] = (320, 240)) -> ToothPicture:
    """The same figures from the offscreen label pass: `state` (a FrameState) drawn from `view` at
    `size`, contact markers left out (the id picture shows teeth only)."""
    from orthosim_render.frame import cached_renderer as _renderer
    from orthosim_render.scene import DentitionScene
    from orthosim_render.semantic_labels import render_labelled

    scene = DentitionScene(dentition, size, show_markers=False)
    scene.update(state)
    _, frame = render_labelled(_renderer(size), scene, view)
    teeth = {}
    rows, cols = np.indices(frame.labels.shape)
    for entry in frame.legend:
        if entry.kind == "tooth":
            mask = frame.labels == entry.id
            teeth[entry.teeth[0]] = (int(mask.sum()), (float(cols[mask].mean()), float(rows[mask].mean())))
    return ToothPicture(teeth, tuple(size))


def disagreements(viewer: ToothPicture, reference: ToothPicture, *, max_px: float = 3.0, min_pixels: int = 20) -> list[str]:
    """Where the viewer's id picture and the label pass disagree: a tooth well visible in one
    (`min_pixels` or more) and absent from the other, or a centroid more than `max_px` away."""
    problems = []
    for name, one, other in (("viewer", viewer, reference), ("frame", reference, viewer)):
        for n in sorted(one.visible(min_pixels) - set(other.teeth)):
            problems.append(f"tooth {n}: {one.teeth[n][0]} px in the {name}, none in the other")
    for n in sorted(set(viewer.teeth) & set(reference.teeth)):
        (a_px, a), (b_px, b) = viewer.teeth[n], reference.teeth[n]
        gap = float(np.hypot(a[0] - b[0], a[1] - b[1]))
        if gap > max_px and min(a_px, b_px) >= min_pixels:
            problems.append(f"tooth {n}: centroid {gap:.2f} px away ({a_px} px in the viewer, {b_px} in the frame)")
    return problems

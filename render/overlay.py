"""Captions drawn onto rendered frames: case, detector, day N of M, a colour legend, FDI labels.

One overlay for every image orthosim hands to a person: the frames and animations of
`orthosim run` and the pictures of `orthosim report`. It is drawn on the CPU onto the image read
back from the renderer (no GL pass, so it costs no extra frame): text is rasterised once with
Pillow (FreeType, the font Pillow ships, so no system font is needed) into small RGBA patches that
are cached, and each frame only blends the patches it needs onto its pixels with numpy. Patches
are blended where they fit; a patch that would leave the image is clipped.

Legend colours are those of `orthosim_render.scene`: moving teeth (the mint tint on enamel), contacts (the
contact red) and extraction gaps (an amber ring where the extracted tooth's crown stood).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Iterable, Mapping

import numpy as np

from orthosim_render.scene import (CONTACT_COLOR, CROWN_COLOR, ESTIMATED_ROOT_COLOR, GINGIVA_COLOR,
                                  MOVING_TINT)

TEXT_COLOR = (236, 238, 242)
PANEL_COLOR = (16, 18, 24, 178)  # translucent dark panel behind text (RGBA)
GAP_COLOR = (255, 176, 32)
LABEL_COLOR = (20, 22, 28)
LABEL_FILL = (255, 255, 255, 200)


def _rgb8(c) -> tuple[int, int, int]:
    return tuple(int(round(255 * min(max(v, 0.0), 1.0))) for v in c)


MOVING_RGB = _rgb8(np.multiply(CROWN_COLOR, MOVING_TINT))
CONTACT_RGB = _rgb8(CONTACT_COLOR)
LEGEND = (("moving", MOVING_RGB, "box"), ("contact", CONTACT_RGB, "box"), ("extracted (gap)", GAP_COLOR, "ring"))


def model_legend(dentition, hide_roots: bool = False) -> tuple:
    """Legend entries the model itself asks for: estimated roots and a scanned gum, when drawn."""
    if hide_roots:
        return ()
    items = []
    if any(t.root_kind == "estimated" for t in dentition.teeth.values()):
        items.append(("estimated root", _rgb8(ESTIMATED_ROOT_COLOR), "box"))
    if dentition.gingiva:
        items.append(("gum (scan)", _rgb8(GINGIVA_COLOR), "box"))
    return tuple(items)


@lru_cache(maxsize=8)
def _font(px: int):
    from PIL import ImageFont

    return ImageFont.load_default(size=px)


@lru_cache(maxsize=4096)
def text_patch(text: str, px: int, fg: tuple = TEXT_COLOR, bg: tuple = PANEL_COLOR, pad: int = 3) -> np.ndarray:
    """(h, w, 4) uint8 RGBA: `text` at `px` pixels on a rounded panel (cached: captions repeat)."""
    from PIL import Image, ImageDraw

    font = _font(px)
    x0, y0, x1, y1 = font.getbbox(text)
    w, h = x1 - x0 + 2 * pad, y1 - y0 + 2 * pad
    im = Image.new("RGBA", (max(w, 1), max(h, 1)), (0, 0, 0, 0))
    d = ImageDraw.Draw(im)
    d.rounded_rectangle((0, 0, w - 1, h - 1), radius=min(4, h // 3), fill=bg)
    d.text((pad - x0, pad - y0), text, font=font, fill=(*fg, 255))
    return np.asarray(im)


@lru_cache(maxsize=32)
def legend_patch(px: int, items: tuple = LEGEND, horizontal: bool = False) -> np.ndarray:
    """(h, w, 4) uint8 RGBA: each colour (swatch and name) on a translucent panel, one per row, or
    side by side with `horizontal`."""
    from PIL import Image, ImageDraw

    font = _font(px)
    pad, gap = 4, 3
    sw = px  # swatch size
    rows = [font.getbbox(name) for name, _, _ in items]
    item_w = [sw + 6 + b[2] - b[0] for b in rows]
    row_h = max(sw, max(b[3] - b[1] for b in rows))
    if horizontal:
        w = pad * 2 + sum(item_w) + 3 * px * (len(items) - 1) // 2
        h = pad * 2 + row_h
    else:
        w = pad * 2 + max(item_w)
        h = pad * 2 + len(items) * row_h + (len(items) - 1) * gap
    im = Image.new("RGBA", (w, h), (0, 0, 0, 0))
    d = ImageDraw.Draw(im)
    d.rounded_rectangle((0, 0, w - 1, h - 1), radius=4, fill=PANEL_COLOR)
    x0 = pad
    for i, ((name, colour, kind), box) in enumerate(zip(items, rows)):
        y = pad if horizontal else pad + i * (row_h + gap)
        x = x0 if horizontal else pad
        x0 += item_w[i] + 3 * px // 2
        sq = (x, y + (row_h - sw) // 2, x + sw - 1, y + (row_h - sw) // 2 + sw - 1)
        if kind == "ring":
            d.ellipse(sq, outline=(*colour, 255), width=max(2, sw // 6))
        else:
            d.rectangle(sq, fill=(*colour, 255), outline=(255, 255, 255, 160))
        d.text((x + sw + 6 - box[0], y + (row_h - (box[3] - box[1])) // 2 - box[1]), name, font=font,
               fill=(*TEXT_COLOR, 255))
    return np.asarray(im)


@lru_cache(maxsize=16)
def ring_patch(radius_px: int, colour: tuple = GAP_COLOR) -> np.ndarray:
    from PIL import Image, ImageDraw

    s = 2 * radius_px + 1
    im = Image.new("RGBA", (s, s), (0, 0, 0, 0))
    ImageDraw.Draw(im).ellipse((0, 0, s - 1, s - 1), outline=(*colour, 235), width=max(2, radius_px // 5))
    return np.asarray(im)


_PREMULTIPLIED: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


def _premultiplied(patch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(colour * alpha + 128, 255 - alpha), both (h, w, 3) uint16, of an RGBA `patch`: the parts of
    the blend that do not depend on the image, computed once per patch (patches are cached and
    reused every frame). Keyed by identity; the entry holds the patch, so its id is not reused."""
    hit = _PREMULTIPLIED.get(id(patch))
    if hit is not None and hit[0] is patch:
        return hit[1], hit[2]
    if len(_PREMULTIPLIED) > 4096:
        _PREMULTIPLIED.clear()
    alpha = np.repeat(patch[:, :, 3:4].astype(np.uint16), 3, axis=2)
    pre = patch[:, :, :3].astype(np.uint16) * alpha + 128
    inv = 255 - alpha
    _PREMULTIPLIED[id(patch)] = (patch, pre, inv)
    return pre, inv


def blend(image: np.ndarray, patch: np.ndarray, x: int, y: int) -> None:
    """Alpha-blend an RGBA `patch` onto `image` ((h, w, 3 or 4) uint8, in place) with its top left
    corner at column x, row y; clipped at the image's edges. An RGBA image keeps its alpha where
    the patch is transparent and becomes opaque under it.

    Each channel becomes round((patch * a + image * (255 - a)) / 255), in uint16 with the division
    by 255 done as (v + (v >> 8)) >> 8 on v + 128 (exact for every v up to 255 * 255): a frame's
    captions cost tens of microseconds, not the hundreds that a broadcast integer division costs.
    """
    H, W = image.shape[:2]
    ph, pw = patch.shape[:2]
    x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + pw, W), min(y + ph, H)
    if x0 >= x1 or y0 >= y1:
        return
    pre, inv = _premultiplied(patch)
    sy, sx = slice(y0 - y, y1 - y), slice(x0 - x, x1 - x)
    region = image[y0:y1, x0:x1, :3]
    v = region.astype(np.uint16)
    v *= inv[sy, sx]
    v += pre[sy, sx]
    v += v >> 8
    v >>= 8
    region[...] = v
    if image.shape[2] == 4:
        np.maximum(image[y0:y1, x0:x1, 3], patch[sy, sx, 3], out=image[y0:y1, x0:x1, 3])


@dataclass(frozen=True)
class FrameCaption:
    """What the overlay says about a run (model: fixed for the whole run)."""

    case_name: str
    detector: str
    step_days: float  # days per simulation step
    duration_days: float  # the treatment's length, the M of "day N of M"
    labels: bool = False  # FDI numbers on the crowns
    legend: bool = True
    extra_legend: tuple = ()  # (text, rgb8, "box" | "ring") after the usual entries, e.g. `model_legend`

    def day_text(self, step: int) -> str:
        day = step * self.step_days
        shown = f"{day:.0f}" if abs(day - round(day)) < 1e-9 else f"{day:.1f}"
        total = f"{self.duration_days:.0f}" if abs(self.duration_days - round(self.duration_days)) < 1e-9 else f"{self.duration_days:.1f}"
        return f"day {shown} of {total}"


def font_px_for(size: tuple[int, int]) -> int:
    """Caption text height (pixels) for an image of `size` (w, h): readable at 320x240 and 1920x1080."""
    return int(np.clip(round(min(size) / 30), 10, 28))


def label_view(image: np.ndarray, view, dentition, poses: Mapping[int, np.ndarray], teeth: Iterable[int],
               extracted: Iterable[int] = (), font_px: int | None = None) -> None:
    """Write each shown tooth's FDI number at its projected crown centre in `view` (a
    `orthosim_render.cameras.CameraView`), nearest teeth first, skipping a label that would cover one
    already placed (in a frontal view the molars hide behind the premolars); ring each extracted
    tooth's crown where it stood at rest. `image` (h, w, 3|4) uint8 is changed in place."""
    from orthosim.model.fdi import arch_of

    h, w = image.shape[:2]
    px = font_px or font_px_for((w, h))
    shown = [n for n in teeth if arch_of(n) in view.arches]
    if shown:
        T = np.stack([poses[n] for n in shown])
        local = np.stack([dentition.teeth[n].crown_center for n in shown])
        centres = np.einsum("nij,nj->ni", T[:, :3, :3], local) + T[:, :3, 3]
        uv = view.project(centres, (w, h))
        depth = np.linalg.norm(centres - view.pose[:3, 3], axis=1)
        patches = [text_patch(str(n), px, LABEL_COLOR, LABEL_FILL, 2) for n in shown]
        sizes = np.array([p.shape[:2] for p in patches])  # (h, w) each
        corner = np.rint(uv - sizes[:, ::-1] / 2).astype(int)  # (x, y) of each label's top left
        boxes = np.concatenate([corner, corner + sizes[:, ::-1]], axis=1)  # x0, y0, x1, y1
        placed = np.zeros(len(shown), bool)
        for i in np.argsort(depth, kind="stable"):
            b, others = boxes[i], boxes[placed]
            if (len(others) and ((b[0] < others[:, 2]) & (others[:, 0] < b[2])
                                 & (b[1] < others[:, 3]) & (others[:, 1] < b[3])).any()):
                continue
            placed[i] = True
            blend(image, patches[i], int(b[0]), int(b[1]))
    gone = [n for n in extracted if n in dentition.teeth and arch_of(n) in view.arches]
    if gone:
        centres = np.array([dentition.teeth[n].to_world(dentition.teeth[n].crown_center) for n in gone])
        ring = ring_patch(max(4, px * 2 // 3))
        for u, v in view.project(centres, (w, h)):
            blend(image, ring, int(round(u)) - ring.shape[1] // 2, int(round(v)) - ring.shape[0] // 2)


def draw_caption(image: np.ndarray, caption: FrameCaption, step: int, font_px: int | None = None) -> np.ndarray:
    """Case name and detector at the top left, "day N of M" at the top right, the legend at the
    bottom left of `image` ((h, w, 3|4) uint8, changed in place and returned)."""
    h, w = image.shape[:2]
    px = font_px or font_px_for((w, h))
    m = max(4, px // 2)
    blend(image, text_patch(f"{caption.case_name} | {caption.detector}", px), m, m)
    day = text_patch(caption.day_text(step), px)
    blend(image, day, w - day.shape[1] - m, m)
    if caption.legend:
        leg = legend_patch(max(9, px - 2), LEGEND + tuple(caption.extra_legend))
        blend(image, leg, m, h - leg.shape[0] - m)
    return image


class FrameOverlay:
    """The overlay of one run: labels per view (optional), then the caption on the tiled frame.

        overlay = FrameOverlay(caption, dentition, size)
        for each frame: views drawn -> overlay.label(image, view, state) per view -> tile -> overlay.caption(tiled, state)
    """

    def __init__(self, caption: FrameCaption, dentition, size: tuple[int, int]):
        self.caption = caption
        self.dentition = dentition
        self.font_px = font_px_for(size)

    def label(self, image: np.ndarray, view, state) -> np.ndarray:
        if self.caption.labels:
            teeth = [n for n in self.dentition.fdis if n not in state.extracted]
            label_view(image, view, self.dentition, state.poses, teeth, state.extracted, self.font_px)
        elif state.extracted:
            label_view(image, view, self.dentition, state.poses, (), state.extracted, self.font_px)
        return image

    def caption_frame(self, image: np.ndarray, state) -> np.ndarray:
        return draw_caption(image, self.caption, state.step, self.font_px)


def draw_scale_bar(image: np.ndarray, view, at_depth_of: np.ndarray, render_size: tuple[int, int],
                   length_mm: float = 10.0, font_px: int | None = None) -> None:
    """A scale bar of `length_mm`, its label to its left, at the bottom right of `image` ((h, w,
    3|4) uint8, in place; the picture drawn at `render_size` (w, h) is its top part). True at the
    depth of the point `at_depth_of` ((3,) arch frame, mm): perspective makes a bar exact at one
    depth only; callers pass the centre of the crowns shown."""
    h, w = image.shape[:2]
    px = font_px or font_px_for(render_size)
    R = view.pose[:3, :3]
    target = np.asarray(at_depth_of, float)
    a = view.project(np.stack([target, target + R[:, 0] * length_mm]), render_size)
    bar_px = max(1, int(round(abs(a[1, 0] - a[0, 0]))))
    label = text_patch(f"{length_mm:g} mm", px)
    thick = max(2, px // 6)
    tick = label.shape[0] - 4
    patch = np.zeros((tick + 4, bar_px + 8, 4), np.uint8)
    patch[:, :] = PANEL_COLOR
    mid = (tick + 4) // 2
    patch[mid - thick // 2:mid - thick // 2 + thick, 4:4 + bar_px] = (*TEXT_COLOR, 255)
    patch[2:tick + 2, 4:4 + thick] = (*TEXT_COLOR, 255)
    patch[2:tick + 2, 4 + bar_px - thick:4 + bar_px] = (*TEXT_COLOR, 255)
    m = max(4, px // 2)
    y = h - label.shape[0] - 3
    x = w - m - patch.shape[1]
    blend(image, patch, x, y + 2)
    blend(image, label, x - label.shape[1] - 2, y)

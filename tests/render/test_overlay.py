"""The frame overlay: case, detector and day in the corners, the legend, FDI labels where the crowns
are, rings where extracted teeth stood; drawn on the image, never over the whole of it."""

from __future__ import annotations

import numpy as np
import pytest

from orthosim.model.parametric import parametric_dentition
from orthosim_render.cameras import frame_view
from orthosim_render.frame_state import FrameState
from orthosim_render.overlay import FrameCaption, FrameOverlay, blend, text_patch


@pytest.fixture(scope="module")
def dent():
    return parametric_dentition("coarse")


def test_day_counter_reads_day_n_of_m():
    c = FrameCaption("case 1", "continuous", step_days=2.0, duration_days=240.0)
    assert c.day_text(0) == "day 0 of 240" and c.day_text(12) == "day 24 of 240"
    assert FrameCaption("c", "d", 0.5, 10.0).day_text(3) == "day 1.5 of 10"


def test_caption_and_legend_are_drawn_in_the_corners_and_leave_the_middle(dent):
    size = (320, 240)
    image = np.full((240, 320, 3), 30, np.uint8)
    state = FrameState.rest(dent, step=5)
    FrameOverlay(FrameCaption("case 1", "circles", 2.0, 240.0), dent, size).caption_frame(image, state)
    changed = np.any(image != 30, axis=2)
    assert changed[:30, :120].any() and changed[:30, -80:].any() and changed[-60:, :100].any()
    assert not changed[90:150, 120:200].any()


def test_fdi_labels_sit_on_the_projected_crowns_and_gaps_are_ringed(dent):
    size = (480, 360)
    pts = np.concatenate([dent.teeth[n].to_world(dent.teeth[n].mesh.vertices) for n in dent.arch(dent.teeth[11].arch)])
    view = frame_view("maxillary_occlusal", pts, size)
    extracted = frozenset({14, 24})
    state = FrameState(poses=dent.rest_poses(), extracted=extracted)
    plain = np.zeros((360, 480, 3), np.uint8)
    labelled = plain.copy()
    FrameOverlay(FrameCaption("c", "d", 1, 1, labels=True), dent, size).label(labelled, view, state)
    changed = np.any(labelled != plain, axis=2)
    for n in (11, 16, 27):  # each label covers its crown centre
        u, v = view.project(dent.teeth[n].to_world(dent.teeth[n].crown_center), size)[0]
        assert changed[int(v), int(u)], n
    ring = labelled.copy()
    u, v = view.project(dent.teeth[14].to_world(dent.teeth[14].crown_center), size)[0]
    window = ring[int(v) - 12:int(v) + 13, int(u) - 12:int(u) + 13].reshape(-1, 3)
    assert any(p[0] > 200 and 120 < p[1] < 220 and p[2] < 90 for p in window)  # the amber gap ring


def test_blend_clips_at_the_edges_and_keeps_alpha_images_opaque_under_text():
    image = np.zeros((20, 20, 4), np.uint8)
    patch = text_patch("17", 12)
    blend(image, patch, 15, 15)  # runs off the bottom right corner
    assert image[15:, 15:, 3].max() > 0 and image[:15, :15].max() == 0


@pytest.mark.parametrize("channels", [3, 4])
def test_blend_is_the_rounded_alpha_mix_of_patch_and_image_everywhere(channels):
    """Every pixel under a patch becomes round((patch * a + image * (255 - a)) / 255), for every alpha
    from 0 to 255, also where the patch is clipped at the image's edges."""
    rng = np.random.default_rng(7)
    patch = rng.integers(0, 256, (40, 50, 4), dtype=np.uint8)
    patch[0, :, 3] = 0
    patch[1, :, 3] = 255
    patch[2, :50, 3] = np.arange(50) * 5
    for x, y in ((3, 4), (-7, -5), (20, 12)):
        image = rng.integers(0, 256, (30, 45, channels), dtype=np.uint8)
        expected = image.copy()
        x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + 50, 45), min(y + 40, 30)
        p = patch[y0 - y:y1 - y, x0 - x:x1 - x].astype(np.float64)
        under = expected[y0:y1, x0:x1].astype(np.float64)
        a = p[:, :, 3:4] / 255.0
        expected[y0:y1, x0:x1, :3] = np.round(p[:, :, :3] * a + under[:, :, :3] * (1 - a)).astype(np.uint8)
        if channels == 4:
            expected[y0:y1, x0:x1, 3] = np.maximum(under[:, :, 3], p[:, :, 3]).astype(np.uint8)
        blend(image, patch, x, y)
        assert np.array_equal(image, expected)

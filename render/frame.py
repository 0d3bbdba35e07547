"""One simulation step drawn as a picture, for scripts and notebooks: `render_frame(model, record)`.

    from orthosim_render import render_frame
    rgb = render_frame(model, record, view="frontal", size=(640, 480))   # Frame: (480, 640, 3) uint8

The picture is drawn as `orthosim run` draws a step's end (the same scene, colours, light rig and
contact markers) with no text on it. A `Frame` is a numpy array, (h, w, 3) uint8 RGB, that a
Jupyter notebook shows as the picture itself (`_repr_png_`). `render_state` is the drawing under
it, shared with the image-regression helpers (`orthosim_render.regression`); one offscreen
renderer per image size is kept for the life of the process.
"""

from __future__ import annotations

import functools

import numpy as np

from orthosim_render.cameras import check_view
from orthosim_render.frame_state import FrameState


class Frame(np.ndarray):
    """A drawn picture: an (h, w, 3) uint8 RGB numpy array that a notebook shows as a PNG."""

    def _repr_png_(self) -> bytes:
        from orthosim_render.png import encode_png

        return encode_png(np.asarray(self))


@functools.cache
def cached_renderer(size: tuple[int, int]):
    """The offscreen renderer of this image size (w, h pixels), made once per process."""
    from orthosim_render.renderer import Renderer

    return Renderer(size)


def render_state(dentition, state: FrameState, view: str, size: tuple[int, int], *,
                 hide_roots: bool = False, contact_faces: bool = False, labels: bool = False):
    """(h, w, 3) uint8: `state` of `dentition` from camera preset `view`, at `size` (w, h pixels).

    `labels=True`: (image, its `orthosim_render.semantic_labels.LabelFrame`), drawn in the same pass.
    """
    from orthosim_render.scene import DentitionScene

    scene = DentitionScene(dentition, size, hide_roots=hide_roots, contact_faces=contact_faces)
    scene.update(state)
    renderer = cached_renderer((int(size[0]), int(size[1])))
    if labels:
        from orthosim_render.semantic_labels import render_labelled

        return render_labelled(renderer, scene, view)
    return renderer.render(scene, view)


def render_frame(model, record, view: str = "frontal", size: tuple[int, int] = (640, 480), *,
                 contacts: bool = True, hide_roots: bool = False, contact_faces: bool = False) -> Frame:
    """One step of a simulation drawn: `record` (an `orthosim.StepRecord`: poses, moving teeth,
    contacts) of `model` (an `orthosim.MovementModel`, from `orthosim.build`) from camera preset
    `view` ("frontal", "right_buccal", "left_buccal", "maxillary_occlusal", "mandibular_occlusal")
    at `size` (width, height pixels).

    Returns a `Frame`: (height, width, 3) uint8 RGB, shown as a picture in a notebook. contacts:
    draw the contact spheres (False leaves them out); hide_roots: crowns only; contact_faces:
    colour the tooth surface inside each contact sphere. Extracted teeth are not drawn.
    """
    state = FrameState.from_step(record, model.extracted)
    if not contacts:
        state = FrameState(poses=state.poses, extracted=state.extracted, moving=state.moving, step=state.step)
    image = render_state(model.dentition, state, check_view(view), size, hide_roots=hide_roots,
                         contact_faces=contact_faces)
    return np.ascontiguousarray(image[:, :, :3]).view(Frame)

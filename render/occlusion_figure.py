"""The occlusal contact areas of a bite drawn on the teeth: the paper's Figure 7, on any model.

Each facing pair's contact faces (`orthosim.analysis.occlusalcontacts`) are handed to the scene as small
contact spheres on the tooth surface, and the scene's face painting (`DentitionScene`,
`contact_faces`) colours every vertex inside one: the contact areas come out as coloured
patches on the maxillary and mandibular occlusal views (and any other view asked for).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from orthosim.storage.atomic import write_bytes

from orthosim_render.frame_state import FrameState
from orthosim_render.png import encode_png

FIGURE_VIEWS = ("maxillary_occlusal", "mandibular_occlusal")
PATCH_RADIUS_MM = 0.25  # each contact face centre colours the surface this far around it


def contact_state(dentition, contacts, poses=None) -> FrameState:
    """A frame at `poses` (rest by default) whose contacts are the contact faces of `contacts`."""
    touching = [c for c in contacts if c.in_contact]
    points = [p for c in touching for p in (c.points_upper, c.points_lower) if len(p)]
    centers = np.concatenate(points) if points else np.zeros((0, 3))
    return FrameState(poses=poses if poses is not None else dentition.rest_poses(), contact_centers=centers,
                      contact_radii=np.full(len(centers), PATCH_RADIUS_MM),
                      contact_pairs=tuple(c.pair for c in touching))


def render_occlusal_contacts(dentition, contacts, size=(640, 480), views: Sequence[str] = FIGURE_VIEWS,
                             poses=None) -> dict[str, np.ndarray]:
    """view name -> (h, w, 3) uint8 image of the teeth with their occlusal contact areas coloured."""
    from orthosim_render.renderer import Renderer
    from orthosim_render.scene import DentitionScene

    scene = DentitionScene(dentition, size, contact_faces=True, show_markers=False)
    scene.update(contact_state(dentition, contacts, poses))
    with Renderer(size) as renderer:
        return {v: np.asarray(renderer.render(scene, v))[..., :3].copy() for v in views}


def write_occlusal_contacts(dentition, contacts, out_dir: str | Path, size=(640, 480),
                            views: Sequence[str] = FIGURE_VIEWS) -> list[Path]:
    """Write out_dir/contacts_<view>.png for each view (atomically); returns the paths."""
    out = []
    for view, image in render_occlusal_contacts(dentition, contacts, size, views).items():
        path = Path(out_dir) / f"contacts_{view}.png"
        write_bytes(path, encode_png(image))
        out.append(path)
    return out

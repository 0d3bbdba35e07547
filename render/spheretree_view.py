"""The sphere tree of one tooth drawn level by level (the paper's Figure 2).

`render_sphere_tree` returns one image: the tooth itself, then its bounding spheres at each
requested level, side by side, all from the same camera (looking at the labial face, framed so
that the largest level shown fits). Spheres are opaque and lit, so their overlaps and the gaps a
level leaves show the tightness of the fit; the tooth is hidden in the sphere panels.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from orthosim.model.dentition import Dentition
from orthosim.errors import SphereTreeError
from orthosim.spheretree.tree import SphereTree

from orthosim_render.animation import tile
from orthosim_render.frame_state import FrameState

SPHERE_COLOR = (0.45, 0.66, 0.95)


def render_sphere_tree(tooth, tree: SphereTree, levels: Sequence[int] | None = None, size=(480, 480),
                       view: str = "frontal", renderer=None) -> np.ndarray:
    """(h, w * (1 + len(levels)), 3) uint8: the tooth, then its spheres at each of `levels`.

    The tooth is drawn in its local frame (crown up); `levels` default to every level below the
    root. `renderer` may be an existing `orthosim_render.renderer.Renderer` of the same size.
    """
    from orthosim_render.renderer import Renderer
    from orthosim_render.scene import DentitionScene

    levels = list(range(1, tree.depth)) if levels is None else list(levels)
    for k in levels:
        if not 0 <= k < tree.depth:
            raise SphereTreeError(None, "level", f"{k} is not a level of this tree (0 to {tree.depth - 1})",
                                  f"choose a level from 0 to {tree.depth - 1}")
    local = dataclasses.replace(tooth, rest_pose=np.eye(4))
    one = Dentition({tooth.fdi: local}, description=f"tooth {tooth.fdi} alone")
    # frame the camera on the tooth and on every sphere shown (spheres stick out of the surface)
    extent = [tooth.mesh.vertices]
    for k in levels:
        c, r = tree.centers[k], tree.radii[k]
        extent += [c + r[:, None], c - r[:, None]]
    scene = DentitionScene(one, size, marker_style="mesh", marker_subdivisions=3,
                           frame_points=np.concatenate(extent))
    scene.marker_material.baseColorFactor = [*SPHERE_COLOR, 1.0]
    scene.marker_material.emissiveFactor = [0.0, 0.0, 0.0]
    scene.marker_material.roughnessFactor = 0.5
    own = renderer is None
    renderer = renderer or Renderer(size)
    try:
        panels = []
        scene.update(FrameState(poses={tooth.fdi: np.eye(4)}))
        panels.append(renderer.render(scene, view))
        for k in levels:
            scene.update(FrameState(poses={tooth.fdi: np.eye(4)}, extracted={tooth.fdi},
                                    contact_centers=tree.centers[k], contact_radii=tree.radii[k]))
            panels.append(renderer.render(scene, view))
    finally:
        if own:
            renderer.close()
    return tile(panels, columns=len(panels))

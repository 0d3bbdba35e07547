"""Detector 1, the paper's bounding circles: one circle per tooth in the x-z (occlusal) plane.

Each tooth's circle bounds the projection of its crown on the x-z plane (the paper's circles do not
take the roots into account): at the rest pose it is the smallest circle holding that projection;
the circle moves with the tooth's pose. The paper assumes teeth turn only about the vertical; so the circles stay bounding under any
pose, a tilt (the tooth's rest-vertical turned by the pose) widens the radius by the tooth's half
height times the horizontal part of its turned vertical. Overlap is Eq. 1: |c1 - c2| <= r1 + r2.
No narrow phase: circles cannot tell crown from root, or upper from lower teeth.

What a circles contact looks like (`overlap_spheres`): where two circles overlap, the lens between
them; it is drawn as one sphere on the line between the centres, at the middle of the overlap
(radius half its depth along that line, at most LENS_MARKER_MAX_MM), at the mean height of the two crowns' circle centres. It
marks where the detector says the teeth meet and how deep its (coarse) overlap is.
"""

from __future__ import annotations

import numpy as np

from orthosim.collision.model import CollisionModel

# Facing upper and lower teeth project onto each other, so their circles overlap by many mm; a
# marker that large would hide the crowns it marks.
LENS_MARKER_MAX_MM = 1.0


def bounding_circles(model: CollisionModel, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Circles of every body: centres (n, 2) mm as (x, z) in the arch frame, radii (n,) mm.

    poses: (n, 4, 4) local -> arch frame, in model body order.
    """
    c, r = _circles(model, poses)
    return c[:, [0, 2]], r


def _circles(model: CollisionModel, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n, 3) mm, arch frame (their y: mid-crown height), radii (n,) mm."""
    cd = model._circle
    R = poses[:, :3, :3]
    c = np.einsum("nij,nj->ni", R, cd.center_local) + poses[:, :3, 3]
    rest_up = np.stack([b.rest_pose[1, :3] for b in model.bodies])  # R_rest^T e_y, local frame
    up = np.einsum("nij,nj->ni", R, rest_up)  # the rest-vertical under the current pose
    tilt = np.hypot(up[:, 0], up[:, 2])
    return c, cd.r_plane + cd.half_height * tilt


def overlap_spheres(model: CollisionModel, poses: np.ndarray, pair_idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One sphere per body pair (p, 2) marking the lens where its circles overlap (see the module doc):
    centres (p, 3) mm, arch frame, radii (p,) mm (0 for pairs whose circles do not overlap)."""
    c, r = _circles(model, poses)
    a, b = c[pair_idx[:, 0]], c[pair_idx[:, 1]]
    ra, rb = r[pair_idx[:, 0]], r[pair_idx[:, 1]]
    d_xz = np.hypot(b[:, 0] - a[:, 0], b[:, 2] - a[:, 2])
    depth = np.clip(ra + rb - d_xz, 0.0, 2.0 * np.minimum(ra, rb))
    # from a's centre toward b's: the overlap runs from d - rb to ra; its middle is the lens centre
    along = np.where(d_xz > 0, (0.5 * (ra + d_xz - rb)) / np.maximum(d_xz, 1e-12), 0.5)
    centers = a + along[:, None] * (b - a)
    centers[:, 1] = 0.5 * (a[:, 1] + b[:, 1])
    return centers, np.minimum(0.5 * depth, LENS_MARKER_MAX_MM)


def circles_overlap(centers: np.ndarray, radii: np.ndarray, pair_idx: np.ndarray) -> np.ndarray:
    """(p,) bool, Eq. 1 for each body pair (p, 2) of indices into centers (n, 2) / radii (n,)."""
    d = centers[pair_idx[:, 0]] - centers[pair_idx[:, 1]]
    return np.einsum("ij,ij->i", d, d) <= (radii[pair_idx[:, 0]] + radii[pair_idx[:, 1]]) ** 2

"""Detector 1, the paper's bounding circles: one circle per tooth in the x-z (occlusal) plane.

Each tooth's circle bounds the projection of its crown on the x-z plane (the paper's circles do not
take the roots into account): at the rest pose it is the smallest circle holding that projection;
the circle moves with the tooth's pose. The paper assumes teeth turn only about the vertical; so the circles stay bounding under any
pose, a tilt (the tooth's rest-vertical turned by the pose) widens the radius by the tooth's half
height times the horizontal part of its turned vertical. Overlap is Eq. 1: |c1 - c2| <= r1 + r2.
No narrow phase: circles cannot tell crown from root, or upper from lower teeth.
"""

from __future__ import annotations

import numpy as np

from .model import CollisionModel


def bounding_circles(model: CollisionModel, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Circles of every body: centres (n, 2) mm as (x, z) in the arch frame, radii (n,) mm.

    poses: (n, 4, 4) local -> arch frame, in model body order.
    """
    cd = model._circle
    R = poses[:, :3, :3]
    c = np.einsum("nij,nj->ni", R, cd.center_local) + poses[:, :3, 3]
    rest_up = np.stack([b.rest_pose[1, :3] for b in model.bodies])  # R_rest^T e_y, local frame
    up = np.einsum("nij,nj->ni", R, rest_up)  # the rest-vertical under the current pose
    tilt = np.hypot(up[:, 0], up[:, 2])
    return c[:, [0, 2]], cd.r_plane + cd.half_height * tilt


def circles_overlap(centers: np.ndarray, radii: np.ndarray, pair_idx: np.ndarray) -> np.ndarray:
    """(p,) bool, Eq. 1 for each body pair (p, 2) of indices into centers (n, 2) / radii (n,)."""
    d = centers[pair_idx[:, 0]] - centers[pair_idx[:, 1]]
    return np.einsum("ij,ij->i", d, d) <= (radii[pair_idx[:, 0]] + radii[pair_idx[:, 1]]) ** 2

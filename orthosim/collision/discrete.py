"""Detector 2, discrete sphere trees: every overlapping leaf pair of every candidate pair at one pose.

Tooth b's nodes are moved into tooth a's local frame by the pair's relative pose, so each level
costs one small matrix product per surviving node pair. Overlap is Eq. 1 on spheres:
|c1 - c2| <= r1 + r2. Because every tree is conservative (each face lies inside its leaf and all
the leaf's ancestors), two meshes that intersect always have an overlapping leaf pair here.
"""

from __future__ import annotations

import numpy as np

from .descent import descend
from .model import CollisionModel


def overlapping_leaves(model: CollisionModel, poses: np.ndarray, pair_idx: np.ndarray, first_only: bool = False):
    """(pair, leaf a, leaf b): global leaf indices of every overlapping leaf pair.

    poses: (n, 4, 4) local -> arch frame in model body order; pair_idx: (p, 2) body indices.
    """
    return overlapping_leaves_posed(model, pair_idx, poses[pair_idx[:, 0]], poses[pair_idx[:, 1]], first_only)


def overlapping_leaves_posed(model: CollisionModel, pair_idx: np.ndarray, Ta: np.ndarray, Tb: np.ndarray, first_only: bool = False):
    """As `overlapping_leaves`, with each pair's own poses Ta, Tb (p, 4, 4): many poses of the same
    teeth in one call (the accuracy study tests thousands of relative poses at once)."""
    Ra_T = np.transpose(Ta[:, :3, :3], (0, 2, 1))
    R_ab = Ra_T @ Tb[:, :3, :3]  # b's local frame -> a's local frame
    t_ab = np.einsum("pij,pj->pi", Ra_T, Tb[:, :3, 3] - Ta[:, :3, 3])

    def keep(level, pair, na, nb):
        cb = np.einsum("fij,fj->fi", R_ab[pair], model.centers[level][nb]) + t_ab[pair]
        d = model.centers[level][na] - cb
        r = model.radii[level][na] + model.radii[level][nb]
        return np.einsum("ij,ij->i", d, d) <= r * r

    return descend(model, pair_idx, keep, first_only)

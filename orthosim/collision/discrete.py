"""Detector 2, discrete sphere trees: every overlapping leaf pair of every candidate pair at one pose.

All node centres of every tooth are placed in the arch frame by one batched matrix product; the
descent (`descent`) then only gathers and compares, on float32 coordinate arrays (one per axis:
gathers from contiguous 1-D arrays are several times faster than from (n, 3) rows). Overlap is
Eq. 1 on spheres: |c1 - c2| <= r1 + r2 + FLOAT32_MARGIN_MM; the margin (far below any mesh
resolution) absorbs float32 rounding so the test stays conservative. Because every tree is conservative (each face lies inside its leaf and all
the leaf's ancestors), two meshes that intersect always have an overlapping leaf pair here.

The descent runs compiled (`descent_compiled`, numba) when numba is installed and loading or
compiling its kernels pays (`descent.compiled_descent`): the same leaf pairs in the same order,
about 3x faster than the numpy descent (`compiled=False` for it, `True` to compile now).
"""

from __future__ import annotations

import numpy as np

from orthosim.collision.descent import compiled_descent, descend, sphere_overlap_test
from orthosim.collision.model import CollisionModel


def overlapping_leaves(model: CollisionModel, poses: np.ndarray, pair_idx: np.ndarray, first_only: bool = False,
                       world: np.ndarray | None = None, compiled: bool | None = None):
    """(pair, node a, node b): flat node indices of every overlapping leaf pair.

    poses: (n, 4, 4) local -> arch frame in model body order; pair_idx: (p, 2) body indices;
    world: `model.world_centers(poses)` when the caller has it already. compiled: the compiled
    descent when numba is installed (the same results), False for the numpy descent.
    """
    flat = (model.world_centers(poses) if world is None else world).astype(np.float32)
    r = model.radii32
    walk = compiled_descent(compiled)
    if walk is not None:
        return walk.leaf_pairs(model, flat, r, pair_idx, first_only)
    pair, la, lb, _ = descend(model, pair_idx, sphere_overlap_test(model, flat, r), first_only=first_only)
    return pair, la, lb


def overlapping_leaves_posed(model: CollisionModel, pair_idx: np.ndarray, Ta: np.ndarray, Tb: np.ndarray, first_only: bool = False):
    """As `overlapping_leaves`, with each pair's own poses Ta, Tb (p, 4, 4): many poses of the same
    teeth in one call (the accuracy study tests thousands of relative poses at once). Tooth b's
    nodes are moved into tooth a's frame per node pair."""
    Ra_T = np.transpose(Ta[:, :3, :3], (0, 2, 1))
    R_ab = Ra_T @ Tb[:, :3, :3]  # b's local frame -> a's local frame
    t_ab = np.einsum("pij,pj->pi", Ra_T, Tb[:, :3, 3] - Ta[:, :3, 3])
    C = model.centers_flat
    r = model.radii

    def may_touch(pair, na, nb):
        d = C[na] - (np.einsum("fij,fj->fi", R_ab[pair], C[nb]) + t_ab[pair])
        s = r[na] + r[nb]
        return np.einsum("ij,ij->i", d, d) <= s * s

    pair, la, lb, _ = descend(model, pair_idx, may_touch, first_only=first_only, track_pair=True)
    return pair, la, lb

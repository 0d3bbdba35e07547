"""Inside or outside a closed mesh by ray crossings, compiled: `CrossingIndex.contains_exact`'s answers.

The exact contact faces (`contact_area.ContactSurface.faces_touching`) ask, every frame, whether
the centroids of a tooth's candidate faces that are not within the touch tolerance lie inside the
tooth they touch: about a thousand points a call on real crowns of 40k triangles, where numpy's
vectorised crossing count (`orthosim.spheretree.inside.CrossingIndex.crossings`) builds a dozen
temporary arrays of every point-triangle pair and took 7.7 of a frame's 20.7 s of exact faces
(real-jaw case 1, 2026-11-29). Here each point walks the triangles of its bucket in compiled code.
The same ray (+z from the point), the same buckets, and per triangle the same IEEE operations in
the same order as the numpy form (the edge functions, the top-left rule, the barycentric height
summed (b0 z0 + b1 z1) + b2 z2 as numpy's einsum sums three terms), so the same crossings and the
same answer for every point; `tests/collision/test_crossings_compiled.py` holds them equal.
This module is separate from `spheretree.inside` because that module's source is part of the
sphere trees' cache key. Coordinates in mm.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from orthosim.spheretree.inside import CrossingIndex
from orthosim.system.firstrun import announce_compiles

announce_compiles()  # a kernel compiled here (not loaded from numba's cache) says so on stderr


@njit(cache=True, nogil=True)
def _inside(points, tri, area2, origin, bucket, nx, ny, offsets, bucket_tris, out):
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        bx = np.floor((px - origin[0]) / bucket)
        by = np.floor((py - origin[1]) / bucket)
        if not (bx >= 0 and bx < nx and by >= 0 and by < ny):
            out[i] = False
            continue
        key = np.int64(bx) * ny + np.int64(by)
        above = 0
        for s in range(offsets[key], offsets[key + 1]):
            t = bucket_tris[s]
            w0 = _edge_weight(tri[t, 0, 0], tri[t, 0, 1], tri[t, 1, 0], tri[t, 1, 1], px, py)
            w1 = _edge_weight(tri[t, 1, 0], tri[t, 1, 1], tri[t, 2, 0], tri[t, 2, 1], px, py)
            w2 = _edge_weight(tri[t, 2, 0], tri[t, 2, 1], tri[t, 0, 0], tri[t, 0, 1], px, py)
            if w0 >= 0 and w1 >= 0 and w2 >= 0:
                # edge k's weight belongs to the vertex opposite it: (w1, w2, w0) weigh vertices 0, 1, 2
                a = area2[t]
                z = (w1 / a) * tri[t, 0, 2] + (w2 / a) * tri[t, 1, 2] + (w0 / a) * tri[t, 2, 2]
                if z > pz:
                    above += 1
        out[i] = above % 2 == 1


@njit(cache=True, nogil=True, inline="always")
def _edge_weight(e0x, e0y, e1x, e1y, px, py):
    """The edge function of edge e0 -> e1 at (px, py) where the point is on its inner side or on it
    by the top-left rule (the edge going down, or horizontal going right), else -1."""
    dx, dy = e1x - e0x, e1y - e0y
    cross = dx * (py - e0y) - dy * (px - e0x)
    owned = (dy < 0) or (dy == 0 and dx > 0)
    if cross > 0 or (cross == 0 and owned):
        return cross
    return -1.0


def contains(index: CrossingIndex, points: np.ndarray) -> np.ndarray:
    """(p, 3) points, mm -> (p,) bool: inside the closed mesh of `index` (an odd number of crossings
    above), as `index.contains_exact(points)` answers."""
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.zeros(len(points), np.bool_)
    _inside(points, index.tri, index.area2, np.asarray(index.origin, np.float64), float(index.bucket),
            int(index.shape[0]), int(index.shape[1]), index.bucket_offsets, index.bucket_tris, out)
    return out

"""Bounding spheres of many point sets at once: the geometry that makes a sphere tree conservative.

Every node of a tree must hold all vertices of the triangles below it; a sphere that holds a
triangle's three vertices holds the whole triangle (a ball is convex), so coverage is exact, not
sampled. The functions here work on many groups of points together (one group per tree node),
padded into one (groups, max_points, 3) array, so a whole tree level costs a few numpy calls.
All coordinates in mm.
"""

from __future__ import annotations

import numpy as np
from numba import njit


def node_vertex_groups(faces: np.ndarray, node_of_face: np.ndarray, n_nodes: int) -> np.ndarray:
    """Padded vertex indices of each node: (n_nodes, m) int64, rows padded by repeating an entry.

    `faces` (F, 3) int, `node_of_face` (F,) int in [0, n_nodes): the distinct vertices of the faces
    of each node. A node without faces gets a row of -1.
    """
    n_vertices = int(faces.max()) + 1 if len(faces) else 1
    key = np.unique(np.repeat(node_of_face.astype(np.int64), 3) * n_vertices + faces.ravel())
    node, vert = key // n_vertices, key % n_vertices
    counts = np.bincount(node, minlength=n_nodes)
    m = max(int(counts.max()) if len(counts) else 1, 1)
    start = np.cumsum(counts) - counts
    pos = np.arange(len(key)) - np.repeat(start, counts)
    out = np.full((n_nodes, m), -1, dtype=np.int64)
    # Pad each row with its first vertex: a repeated point changes no enclosing sphere.
    first = np.where(counts > 0, vert[np.minimum(start, len(vert) - 1)], -1)
    out[:] = first[:, None]
    out[node, pos] = vert
    return out


def enclosing_spheres(points: np.ndarray, iterations: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """Near-minimal spheres around padded point groups.

    `points` (G, M, 3) mm -> centres (G, 3) mm, radii (G,) mm. The radius is the exact distance to
    the farthest point, so every point is inside; the centre comes from Badoiu-Clarkson steps
    toward the farthest point (within a few per cent of the minimal radius), started at the
    bounding-box centre.
    """
    c = 0.5 * (points.min(axis=1) + points.max(axis=1))
    best_c = c.copy()
    best_r = np.sqrt(((points - c[:, None, :]) ** 2).sum(axis=2).max(axis=1))
    rows = np.arange(len(points))
    for i in range(1, iterations + 1):
        d2 = ((points - c[:, None, :]) ** 2).sum(axis=2)
        far = d2.argmax(axis=1)
        r = np.sqrt(d2[rows, far])
        better = r < best_r
        best_c[better], best_r[better] = c[better], r[better]
        c = c + (points[rows, far] - c) / (i + 1)
    d = np.sqrt(((points - best_c[:, None, :]) ** 2).sum(axis=2).max(axis=1))
    return best_c, d


@njit(cache=True, nogil=True)
def _farthest(points, centers):
    """(G, M, 3) and (G, C, 3) -> (G, C): distance from each centre to the farthest point of its group."""
    g_n, m_n = points.shape[0], points.shape[1]
    c_n = centers.shape[1]
    out = np.empty((g_n, c_n))
    for g in range(g_n):
        for c in range(c_n):
            x, y, z = centers[g, c, 0], centers[g, c, 1], centers[g, c, 2]
            best = 0.0
            for m in range(m_n):
                dx, dy, dz = points[g, m, 0] - x, points[g, m, 1] - y, points[g, m, 2] - z
                d2 = dx * dx + dy * dy + dz * dz
                if d2 > best:
                    best = d2
            out[g, c] = np.sqrt(best)
    return out


def radii_to_cover_each(points: np.ndarray, centers: np.ndarray) -> np.ndarray:
    """(G, M, 3) padded groups and (G, C, 3) candidate centres per group, mm -> (G, C) smallest
    radii holding every point of the group (compiled: the optimising builder asks this for
    millions of candidates)."""
    return _farthest(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(centers, dtype=np.float64))


def radii_to_cover(points: np.ndarray, centers: np.ndarray) -> np.ndarray:
    """(G, M, 3) padded groups and (G, 3) centres, mm -> (G,) smallest radii holding every point."""
    return radii_to_cover_each(points, np.asarray(centers)[:, None, :])[:, 0]

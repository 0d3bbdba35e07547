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

from orthosim.system.firstrun import announce_compiles


def node_vertex_groups(faces: np.ndarray, node_of_face: np.ndarray, n_nodes: int) -> np.ndarray:
    """Padded vertex indices of each node: (n_nodes, m) int64, rows padded by repeating an entry.

    `faces` (F, 3) int, `node_of_face` (F,) int in [0, n_nodes): the distinct vertices of the faces
    of each node, in increasing order. A node without faces gets a row of -1.
    """
    n_vertices = int(faces.max()) + 1 if len(faces) else 1
    if len(node_of_face) and not 0 <= int(node_of_face.min()) <= int(node_of_face.max()) < n_nodes:
        raise ValueError(f"node_of_face must lie in [0, {n_nodes})")  # the compiled gather does not check
    return _node_vertices(np.ascontiguousarray(faces, dtype=np.int64), np.ascontiguousarray(node_of_face, dtype=np.int64),
                          int(n_nodes), n_vertices)


announce_compiles()  # a kernel compiled here (not loaded from numba's cache) says so on stderr


@njit(cache=True, nogil=True)
def _node_vertices(faces, node_of_face, n_nodes, n_vertices):
    """`node_vertex_groups` compiled: faces bucketed by node, each node's vertices gathered once
    (a vertex is stamped with the last node that took it), then sorted (the builder asks this a
    thousand times a tooth; numpy's unique of node x vertex keys cost 3-7 times as much)."""
    n_faces = len(faces)
    first_face = np.zeros(n_nodes + 1, np.int64)
    for f in range(n_faces):
        first_face[node_of_face[f] + 1] += 1
    for i in range(n_nodes):
        first_face[i + 1] += first_face[i]
    fill = first_face[:-1].copy()
    by_node = np.empty(n_faces, np.int64)
    for f in range(n_faces):
        by_node[fill[node_of_face[f]]] = f
        fill[node_of_face[f]] += 1
    stamp = np.full(n_vertices, -1, np.int64)
    start = np.zeros(n_nodes + 1, np.int64)
    verts = np.empty(3 * n_faces, np.int64)
    count = 0
    widest = 1
    for node in range(n_nodes):
        start[node] = count
        for t in range(first_face[node], first_face[node + 1]):
            for a in range(3):
                v = faces[by_node[t], a]
                if stamp[v] != node:
                    stamp[v] = node
                    verts[count] = v
                    count += 1
        verts[start[node]:count].sort()
        widest = max(widest, count - start[node])
    start[n_nodes] = count
    # Pad each row with its first vertex: a repeated point changes no enclosing sphere.
    out = np.full((n_nodes, widest), -1, np.int64)
    for node in range(n_nodes):
        m = start[node + 1] - start[node]
        if m:
            out[node, :m] = verts[start[node]:start[node + 1]]
            out[node, m:] = verts[start[node]]
    return out


@njit(cache=True, nogil=True, inline="always")
def _unpadded(points, g):
    """Length of group g of padded (G, M, >=3) points without its trailing copies of its first point
    (the padding of `node_vertex_groups`): a copy of a point changes no farthest distance."""
    m_n = points.shape[1]
    while m_n > 1 and points[g, m_n - 1, 0] == points[g, 0, 0] and points[g, m_n - 1, 1] == points[g, 0, 1] \
            and points[g, m_n - 1, 2] == points[g, 0, 2]:
        m_n -= 1
    return m_n


@njit(cache=True, nogil=True)
def _badoiu_clarkson(points, iterations):
    """Per group of (G, M, 3): the best centre met in `iterations` steps toward the farthest point."""
    g_n = points.shape[0]
    best_c = np.empty((g_n, 3))
    for g in range(g_n):
        m_n = _unpadded(points, g)
        c = np.empty(3)
        for a in range(3):
            lo, hi = points[g, 0, a], points[g, 0, a]
            for m in range(1, m_n):
                lo, hi = min(lo, points[g, m, a]), max(hi, points[g, m, a])
            c[a] = 0.5 * (lo + hi)
        best_c[g] = c
        best = np.inf
        for i in range(iterations):
            far, far_d2 = 0, -1.0
            for m in range(m_n):
                dx, dy, dz = points[g, m, 0] - c[0], points[g, m, 1] - c[1], points[g, m, 2] - c[2]
                d2 = dx * dx + dy * dy + dz * dz
                if d2 > far_d2:
                    far, far_d2 = m, d2
            if far_d2 < best:
                best = far_d2
                best_c[g] = c
            for a in range(3):
                c[a] += (points[g, far, a] - c[a]) / (i + 2)
    return best_c


def enclosing_spheres(points: np.ndarray, iterations: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """Near-minimal spheres around padded point groups.

    `points` (G, M, 3) mm -> centres (G, 3) mm, radii (G,) mm. The radius is the exact distance to
    the farthest point, so every point is inside; the centre comes from Badoiu-Clarkson steps
    toward the farthest point (within a few per cent of the minimal radius), started at the
    bounding-box centre.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    c = _badoiu_clarkson(points, iterations)
    return c, radii_to_cover(points, c)


@njit(cache=True, nogil=True)
def _farthest(points, centers):
    """(G, M, 3) and (G, C, 3) -> (G, C): distance from each centre to the farthest point of its group."""
    g_n, c_n = points.shape[0], centers.shape[1]
    out = np.empty((g_n, c_n))
    for g in range(g_n):
        m_n = _unpadded(points, g)
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

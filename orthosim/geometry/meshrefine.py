"""Splitting a mesh's long edges without changing its surface: finer triangles where they are long.

Lofted tooth surfaces have long, thin triangles where rings are far apart and where roots join
the trunk. Every consumer that works per triangle is limited by the longest ones: a sphere tree
must give each triangle to one leaf holding all three vertices, so a 2 mm triangle forces a leaf
of at least 1 mm radius there. `split_long_edges` bisects every edge longer than a limit at its
midpoint, pass after pass, until none is left. The split is conforming: an edge is split for both
triangles that share it (no T-junctions), so a closed, manifold mesh stays closed and manifold,
and the surface itself, hence volume, contacts and distances, does not change. Orientation (the
cyclic order of each triangle's vertices) is kept. Lengths in mm.
"""

from __future__ import annotations

import numpy as np

_EDGES = np.array([[0, 1], [1, 2], [2, 0]])  # edge i of a triangle runs from vertex i to vertex i + 1


def _split_once(vertices: np.ndarray, faces: np.ndarray, max_edge: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """One pass: each triangle whose longest edge exceeds `max_edge` asks for that edge to be split;
    every triangle is then cut along the midpoints of its split edges (1, 2 or 3 of them)."""
    ends = faces[:, _EDGES]  # (F, 3, 2) vertex indices
    length = np.linalg.norm(vertices[ends[:, :, 0]] - vertices[ends[:, :, 1]], axis=2)  # (F, 3)
    longest = length.argmax(axis=1)
    rows = np.flatnonzero(length[np.arange(len(faces)), longest] > max_edge)
    if not len(rows):
        return vertices, faces, False
    key = np.sort(ends, axis=2).reshape(-1, 2)
    edges, edge_of = np.unique(key, axis=0, return_inverse=True)
    edge_of = edge_of.reshape(-1, 3)
    split = np.zeros(len(edges), dtype=bool)
    split[edge_of[rows, longest[rows]]] = True
    mid = np.full(len(edges), -1, dtype=np.int64)
    mid[split] = len(vertices) + np.arange(int(split.sum()))
    vertices = np.concatenate([vertices, 0.5 * (vertices[edges[split, 0]] + vertices[edges[split, 1]])])
    m = mid[edge_of]  # (F, 3): midpoint of edge i, or -1
    s = m >= 0
    out = [faces[~s.any(axis=1)]]
    for r in range(3):  # rotate each triangle so its pattern of split edges matches one template
        a, b, c = (faces[:, (r + i) % 3] for i in range(3))
        m0, m1, m2 = (m[:, (r + i) % 3] for i in range(3))
        s0, s1, s2 = (s[:, (r + i) % 3] for i in range(3))
        one = s0 & ~s1 & ~s2  # edge a-b split
        out += [np.column_stack([a, m0, c])[one], np.column_stack([m0, b, c])[one]]
        two = s0 & s1 & ~s2  # edges a-b and b-c split: a corner triangle and a quad cut on its shorter diagonal
        qa, qm0, qm1, qc = a[two], m0[two], m1[two], c[two]
        out.append(np.column_stack([qm0, b[two], qm1]))
        d_a = np.linalg.norm(vertices[qa] - vertices[qm1], axis=1)
        d_c = np.linalg.norm(vertices[qm0] - vertices[qc], axis=1)
        via_a = d_a <= d_c
        out += [np.column_stack([qa, qm0, qm1])[via_a], np.column_stack([qa, qm1, qc])[via_a],
                np.column_stack([qa, qm0, qc])[~via_a], np.column_stack([qm0, qm1, qc])[~via_a]]
    three = s.all(axis=1)
    a, b, c = faces[three].T
    m0, m1, m2 = m[three].T
    out += [np.column_stack([a, m0, m2]), np.column_stack([m0, b, m1]), np.column_stack([m2, m1, c]),
            np.column_stack([m0, m1, m2])]
    return vertices, np.concatenate(out).astype(np.int64), True


def split_long_edges(vertices: np.ndarray, faces: np.ndarray, max_edge: float,
                     max_passes: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) float mm and (m, 3) int triangles -> the same surface with no edge longer than
    `max_edge` mm (or after `max_passes` passes): new vertices are appended, old ones keep their
    indices."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    for _ in range(max_passes):
        vertices, faces, changed = _split_once(vertices, faces, max_edge)
        if not changed:
            break
    return vertices, faces

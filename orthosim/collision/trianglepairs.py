"""Which triangles of one tooth lie within a distance of the paired triangles of another, compiled.

`contact_area` asks, for thousands of a crown's triangles each paired with the dozens of the other
tooth's triangles near it, whether any pair lies within the touch tolerance. In numpy every pair
costs the whole exact distance (six point-to-triangle distances, nine between edges, the edge
crossings) in a dozen passes over temporary arrays; here each triangle's pairs are walked in
compiled code and the walk stops at the first pair within the distance, and a pair is settled by
the cheapest test that can settle it: one triangle wholly beyond the other's plane (farther), two
corners within the distance (nearer), else the exact distance, built the same way as
`contact_area.triangle_distances` (closest points on triangles and between edges, 0 when an edge
passes through the other triangle). Distances in mm.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from orthosim.system.firstrun import announce_compiles

announce_compiles()  # a kernel compiled here (not loaded from numba's cache) says so on stderr


@njit(cache=True, nogil=True, inline="always")
def _dot(a0, a1, a2, b0, b1, b2):
    return a0 * b0 + a1 * b1 + a2 * b2


@njit(cache=True, nogil=True)
def _point_triangle_sq(p, t):
    """Squared distance from point p (3,) to triangle t (3, 3): the closest point by the triangle's
    Voronoi regions (vertices, edges, face)."""
    ab = t[1] - t[0]
    ac = t[2] - t[0]
    ap = p - t[0]
    d1, d2 = np.dot(ab, ap), np.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        q = t[0]
    else:
        bp = p - t[1]
        d3, d4 = np.dot(ab, bp), np.dot(ac, bp)
        cp = p - t[2]
        d5, d6 = np.dot(ab, cp), np.dot(ac, cp)
        vc, vb, va = d1 * d4 - d3 * d2, d5 * d2 - d1 * d6, d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            q = t[1]
        elif d6 >= 0.0 and d5 <= d6:
            q = t[2]
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            q = t[0] + (d1 / (d1 - d3)) * ab
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            q = t[0] + (d2 / (d2 - d6)) * ac
        elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
            q = t[1] + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (t[2] - t[1])
        else:
            denom = va + vb + vc
            if denom == 0.0:  # degenerate triangle: its edges decide (the caller checks them too)
                return np.inf
            q = t[0] + (vb / denom) * ab + (vc / denom) * ac
    g = p - q
    return np.dot(g, g)


@njit(cache=True, nogil=True)
def _segment_segment_sq(p1, q1, p2, q2):
    """Squared distance between segments p1-q1 and p2-q2 (clamped closest points)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = np.dot(d1, d1), np.dot(d2, d2), np.dot(d2, r)
    c, b = np.dot(d1, r), np.dot(d1, d2)
    denom = a * e - b * b
    s = 0.0
    if denom > 1e-12 * max(a * e, 1e-300):
        s = min(max((b * f - c * e) / denom, 0.0), 1.0)
    t = (b * s + f) / max(e, 1e-300)
    if t < 0.0:
        t, s = 0.0, min(max(-c / max(a, 1e-300), 0.0), 1.0)
    elif t > 1.0:
        t, s = 1.0, min(max((b - c) / max(a, 1e-300), 0.0), 1.0)
    g = (p1 + s * d1) - (p2 + t * d2)
    return np.dot(g, g)


@njit(cache=True, nogil=True)
def _edge_crosses(p, q, t):
    """Whether segment p-q passes through triangle t (3, 3) (ray-triangle test, t in [0, 1])."""
    e1, e2, d = t[1] - t[0], t[2] - t[0], q - p
    h = np.cross(d, e2)
    det = np.dot(e1, h)
    if abs(det) <= 1e-15:
        return False
    s = p - t[0]
    u = np.dot(s, h) / det
    w = np.cross(s, e1)
    v = np.dot(d, w) / det
    along = np.dot(e2, w) / det
    return u >= 0.0 and v >= 0.0 and u + v <= 1.0 and 0.0 <= along <= 1.0


@njit(cache=True, nogil=True)
def _beyond_plane(a, b, normal, slack):
    """Whether all corners of a (3, 3) lie on one side of b's plane (unit `normal`), beyond `slack`."""
    lo, hi = np.inf, -np.inf
    for i in range(3):
        h = _dot(a[i, 0] - b[0, 0], a[i, 1] - b[0, 1], a[i, 2] - b[0, 2], normal[0], normal[1], normal[2])
        lo, hi = min(lo, h), max(hi, h)
    return lo > slack or hi < -slack


@njit(cache=True, nogil=True)
def _within(a, b, na, nb, tol):
    """Whether triangles a and b (3, 3), unit normals na and nb (0 when degenerate), lie within `tol`."""
    slack = tol + 1e-9  # mm: rounding
    if _beyond_plane(a, b, nb, slack) or _beyond_plane(b, a, na, slack):
        return False
    tol2 = tol * tol
    for i in range(3):
        if _point_triangle_sq(a[i], b) <= tol2 or _point_triangle_sq(b[i], a) <= tol2:
            return True
    for i in range(3):
        for j in range(3):
            if _segment_segment_sq(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]) <= tol2:
                return True
    for i in range(3):
        if _edge_crosses(a[i], a[(i + 1) % 3], b) or _edge_crosses(b[i], b[(i + 1) % 3], a):
            return True
    return False


@njit(cache=True, nogil=True)
def faces_within(a, a_normals, offsets, theirs, b, b_normals, tol):
    """(k,) bool: whether triangle i of a (k, 3, 3) lies within `tol` mm of any of its paired triangles
    b[theirs[offsets[i]:offsets[i + 1]]] (b (m, 3, 3)); unit normals (k, 3) and (m, 3), all in one frame."""
    out = np.zeros(len(a), np.bool_)
    for i in range(len(a)):
        for p in range(offsets[i], offsets[i + 1]):
            j = theirs[p]
            if _within(a[i], b[j], a_normals[i], b_normals[j], tol):
                out[i] = True
                break
    return out

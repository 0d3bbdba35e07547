"""How deep two posed closed meshes interpenetrate, on every point of their triangles, not only vertices.

    depth = penetration_depth(mesh_a, pose_a, mesh_b, pose_b)        # mm, 0.0 when neither enters the other
    depth = edge_penetration_depth(mesh_a, pose_a, mesh_b, pose_b)   # vertices and edges only: a step's measure

The answer is the larger of two depths, each taken both ways (a in b, b in a):
- surface depth: the deepest point of one surface inside the other solid, as its distance to the
  other's surface. Every point of the triangles counts, so an edge that crosses a face or an edge
  (no vertex inside) reads its true depth: two box ridges crossed at right angles and sunk d along
  their common perpendicular read d / sqrt(2), where a vertex-based measure reads 0. Branch and bound
  on the triangles: the depth at a point is 1-Lipschitz, so a (sub)triangle whose centroid is d deep
  and whose corners lie within r of it holds no point deeper than d + r; triangles that could beat
  the best found by more than `tolerance_mm` are split in four. The result is within `tolerance_mm`
  below the true deepest point and never below the deepest vertex (vertices are measured first).
- overlap depth: the radius of the largest ball found inside both solids, grown from a point of
  either surface (each vertex along its angle-weighted normal, each face's centroid and edge
  midpoints along the face normal) that lies inside the other solid. It sees teeth whose surfaces
  coincide or nearly do (the same tooth twice at one place: about half its thickness), which every
  surface measure reads as 0. The radius reported is the distance from the ball's centre to the
  nearer of the two surfaces, so the ball is truly inside both.

`edge_penetration_depth` is the surface depth on the vertices and edges alone (branch and bound on
segments), a few milliseconds a touching pair of teeth: what a simulation step asks of every pair
that intersects. Both start by dropping, per way, the nodes of one mesh's hierarchy that cannot
reach inside the other (one depth query at a node's centre bounds the whole node).

Inside or outside: the sign of the closest feature's angle-weighted pseudonormal (Baerentzen and
Aanaes 2005), exact for closed, consistently oriented meshes. Closest points are found on a
hierarchy of each mesh's faces (a sphere and a box per node), built once per mesh and kept beside
it (weakly).
Hand-written in numba: FCL answers no inside test and one closest pair per call, and trimesh's
signed distance costs about a millisecond a point; this costs microseconds a point.
Imported on demand only (numba's start-up is not for the drawing side): `orthosim.geometry` does
not import it.
"""

from __future__ import annotations

import weakref

import numpy as np
import trimesh
from numba import njit

DEPTH_TOLERANCE_MM = 0.01  # the surface depth is found to within this below the truth
_LEAF_FACES = 8
_BALL_STEPS = 24  # bisection steps of a ball's radius (root radius / 2**24: far below the tolerance)


# --------------------------------------------------------------------------------- per mesh, once


class MeshGeometry:
    """A mesh's arrays for the depth queries: vertices, faces, pseudonormals, face spheres and a
    bounding-sphere hierarchy of the faces (node `k` covers faces `order[start[k]:start[k] + count[k]]`,
    children `left[k]`, `right[k]`, -1 for a leaf). Read-only once built."""

    def __init__(self, mesh: trimesh.Trimesh):
        V = np.ascontiguousarray(mesh.vertices, float)
        F = np.ascontiguousarray(mesh.faces, np.int64)
        if len(F) == 0:
            raise ValueError("a mesh with no faces has no inside")
        self.V, self.F = V, F
        self.edges, self.face_edges = _edges(V, F)
        self.closed = _closed(F, self.face_edges, len(self.edges))
        self.face_n, self.edge_n, self.vert_n = _pseudonormals(V, F, self.face_edges, len(self.edges))
        tri = V[F]
        self.FC = np.ascontiguousarray(tri.mean(axis=1))
        self.FR = np.linalg.norm(tri - self.FC[:, None, :], axis=2).max(axis=1) * (1 + 1e-12) + 1e-12
        self.lo, self.hi = V.min(axis=0), V.max(axis=0)
        self._build_hierarchy()

    def _build_hierarchy(self) -> None:
        tri = self.V[self.F]
        (self.node_c, self.node_r, self.node_lo, self.node_hi, self.left, self.right, self.start, self.count,
         self.order) = _hierarchy(self.FC, self.FR, tri.min(axis=1), tri.max(axis=1), _LEAF_FACES)

    def args(self) -> tuple:
        """The arrays the compiled queries take, in their order."""
        return (self.V, self.F, self.face_n, self.edge_n, self.vert_n, self.node_c, self.node_r, self.node_lo,
                self.node_hi, self.left, self.right, self.start, self.count, self.order)

    def signed_depth(self, points: np.ndarray) -> np.ndarray:
        """mm each point (this mesh's frame) lies inside the solid; negative outside."""
        pts = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 3))
        return _depths(pts, *self.args())


_GEOMETRY: dict[int, tuple] = {}  # id(mesh) -> (weak reference to it, its MeshGeometry)


def mesh_geometry(mesh: trimesh.Trimesh) -> MeshGeometry:
    """The mesh's `MeshGeometry`, built on first use and kept while the mesh lives."""
    entry = _GEOMETRY.get(id(mesh))
    if entry is None or entry[0]() is not mesh:
        for key in [k for k, (ref, _) in _GEOMETRY.items() if ref() is None]:
            del _GEOMETRY[key]
        entry = _GEOMETRY[id(mesh)] = (weakref.ref(mesh), MeshGeometry(mesh))
    return entry[1]


def _edges(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's edges, (e, 2) vertex pairs (lower index first), and each face's three, (f, 3):
    ab, bc, ca."""
    corners = np.sort(np.stack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1).reshape(-1, 2), axis=1)
    keys, face_edges = np.unique(corners[:, 0] * len(V) + corners[:, 1], return_inverse=True)
    return np.stack([keys // len(V), keys % len(V)], axis=1), face_edges.reshape(-1, 3)


def _closed(F: np.ndarray, face_edges: np.ndarray, n_edges: int) -> bool:
    """Whether the mesh is closed and consistently oriented, so that the pseudonormals tell inside
    from outside: every edge in exactly two faces, which run along it in opposite directions (no
    directed edge twice); trimesh's `is_watertight and is_winding_consistent`, from these arrays."""
    if not np.all(np.bincount(face_edges.reshape(-1), minlength=n_edges) == 2):
        return False
    directed = np.stack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1).reshape(-1, 2)
    keys = directed[:, 0] * (int(F.max()) + 1) + directed[:, 1]
    return len(np.unique(keys)) == len(keys)


def _pseudonormals(V: np.ndarray, F: np.ndarray, face_edges: np.ndarray, n_edges: int):
    """Unit face normals (f, 3), edge pseudonormals per face edge (f, 3, 3: edges ab, bc, ca; the
    sum of the normals of the faces sharing it) and angle-weighted vertex normals (v, 3)."""
    tri = V[F]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    flat = face_edges.reshape(-1)
    per_corner = np.repeat(n, 3, axis=0)
    summed = np.stack([np.bincount(flat, per_corner[:, a], n_edges) for a in range(3)], axis=1)
    edge_n = np.ascontiguousarray(summed[flat].reshape(-1, 3, 3))
    angle_n = []
    for k in range(3):
        u = tri[:, (k + 1) % 3] - tri[:, k]
        w = tri[:, (k + 2) % 3] - tri[:, k]
        cos = np.einsum("ij,ij->i", u, w) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1), 1e-300)
        angle_n.append(n * np.arccos(np.clip(cos, -1.0, 1.0))[:, None])
    corner_n, corner_v = np.concatenate(angle_n), F.T.reshape(-1)  # corner k of every face, k = 0, 1, 2
    vert_n = np.stack([np.bincount(corner_v, corner_n[:, a], len(V)) for a in range(3)], axis=1)
    vert_n /= np.maximum(np.linalg.norm(vert_n, axis=1, keepdims=True), 1e-300)
    return np.ascontiguousarray(n), edge_n, np.ascontiguousarray(vert_n)


# --------------------------------------------------------------------------------- compiled queries


@njit(cache=True, nogil=True)
def _closest_on_triangle(p, a, b, c, q):
    """Closest point of triangle abc to p, into q; returns its feature: 0 face, 1-3 vertex a, b, c,
    4-6 edge ab, bc, ca (the regions of Ericson, Real-Time Collision Detection, 5.1.5)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = ab @ ap
    d2 = ac @ ap
    if d1 <= 0.0 and d2 <= 0.0:
        q[:] = a
        return 1
    bp = p - b
    d3 = ab @ bp
    d4 = ac @ bp
    if d3 >= 0.0 and d4 <= d3:
        q[:] = b
        return 2
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        q[:] = a + v * ab
        return 4
    cp = p - c
    d5 = ab @ cp
    d6 = ac @ cp
    if d6 >= 0.0 and d5 <= d6:
        q[:] = c
        return 3
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        q[:] = a + w * ac
        return 6
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        q[:] = b + w * (c - b)
        return 5
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    q[:] = a + ab * v + ac * w
    return 0


@njit(cache=True, nogil=True)
def _hierarchy(FC, FR, corner_lo, corner_hi, leaf_faces):
    """The faces' bounding hierarchy, depth first from the root: each node halves its faces at the
    median centroid along its centroids' longest extent, down to `leaf_faces` a leaf. A node's sphere
    is centred on its centroids' mean and holds its faces whole; its box holds their corners.
    Compiled: a real tooth's 40,000 faces make 16,000 nodes."""
    n = FC.shape[0]
    most = 2 * n
    centers, radii = np.empty((most, 3)), np.empty(most)
    lo, hi = np.empty((most, 3)), np.empty((most, 3))
    left, right = np.full(most, -1, np.int64), np.full(most, -1, np.int64)
    start, count = np.empty(most, np.int64), np.empty(most, np.int64)
    order = np.arange(n)
    todo = np.empty((most, 4), np.int64)  # (start, end, parent, which child)
    todo[0] = (0, n, -1, 0)
    waiting = 1
    k = 0
    while waiting > 0:
        waiting -= 1
        s, e, parent, side = todo[waiting]
        idx = order[s:e]
        c = np.zeros(3)
        for f in idx:
            for axis in range(3):
                c[axis] += FC[f, axis]
        c /= e - s
        r = 0.0
        for f in idx:
            r = max(r, np.sqrt((FC[f, 0] - c[0]) ** 2 + (FC[f, 1] - c[1]) ** 2 + (FC[f, 2] - c[2]) ** 2) + FR[f])
        centers[k], radii[k] = c, r * (1 + 1e-12) + 1e-12
        for axis in range(3):
            low, high = np.inf, -np.inf
            for f in idx:
                low = min(low, corner_lo[f, axis])
                high = max(high, corner_hi[f, axis])
            lo[k, axis], hi[k, axis] = low, high
        start[k], count[k] = s, e - s
        if parent >= 0:
            if side == 0:
                left[parent] = k
            else:
                right[parent] = k
        if e - s > leaf_faces:
            spread = np.zeros(3)
            for axis in range(3):
                values = FC[idx, axis]
                spread[axis] = values.max() - values.min()
            axis = np.argmax(spread)
            order[s:e] = idx[np.argsort(FC[idx, axis], kind="mergesort")]
            mid = (e - s) // 2
            todo[waiting] = (s + mid, e, k, 1)
            todo[waiting + 1] = (s, s + mid, k, 0)
            waiting += 2
        k += 1
    return (np.ascontiguousarray(centers[:k]), radii[:k].copy(), np.ascontiguousarray(lo[:k]), np.ascontiguousarray(hi[:k]),
            left[:k].copy(), right[:k].copy(), start[:k].copy(), count[:k].copy(), order)


@njit(cache=True, nogil=True, inline="always")
def _node_gap(p, k, node_c, node_r, node_lo, node_hi):
    """A lower bound of the distance from p to node k's faces: the larger of the gaps to its bounding
    sphere and to its box (on a curved shell the box is the tighter one off the surface)."""
    dx = p[0] - node_c[k, 0]
    dy = p[1] - node_c[k, 1]
    dz = p[2] - node_c[k, 2]
    sphere = np.sqrt(dx * dx + dy * dy + dz * dz) - node_r[k]
    bx = max(node_lo[k, 0] - p[0], 0.0, p[0] - node_hi[k, 0])
    by = max(node_lo[k, 1] - p[1], 0.0, p[1] - node_hi[k, 1])
    bz = max(node_lo[k, 2] - p[2], 0.0, p[2] - node_hi[k, 2])
    return max(sphere, np.sqrt(bx * bx + by * by + bz * bz))


@njit(cache=True, nogil=True)
def _depth(p, V, F, face_n, edge_n, vert_n, node_c, node_r, node_lo, node_hi, left, right, start, count, order):
    """Signed depth of p inside the mesh (distance to its surface, positive inside)."""
    return _depth_face(p, V, F, face_n, edge_n, vert_n, node_c, node_r, node_lo, node_hi, left, right, start, count, order)[0]


@njit(cache=True, nogil=True)
def _depth_face(p, V, F, face_n, edge_n, vert_n, node_c, node_r, node_lo, node_hi, left, right, start, count, order):
    """(signed depth of p inside the mesh, the face holding its closest surface point)."""
    best2 = np.inf
    best_f = -1
    best_feat = 0
    bq = np.zeros(3)
    q = np.zeros(3)
    stack = np.empty(128, np.int64)
    gaps = np.empty(128)  # each stacked node's gap, found when it was pushed
    stack[0] = 0
    gaps[0] = 0.0
    top = 1
    while top > 0:
        top -= 1
        k = stack[top]
        gap = gaps[top]
        if gap > 0.0 and gap * gap >= best2:
            continue
        if left[k] < 0:
            for i in range(start[k], start[k] + count[k]):
                f = order[i]
                feat = _closest_on_triangle(p, V[F[f, 0]], V[F[f, 1]], V[F[f, 2]], q)
                d2 = (p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 + (p[2] - q[2]) ** 2
                if d2 < best2:
                    best2 = d2
                    best_f = f
                    best_feat = feat
                    bq[:] = q
            continue
        l, r = left[k], right[k]
        gl = _node_gap(p, l, node_c, node_r, node_lo, node_hi)
        gr = _node_gap(p, r, node_c, node_r, node_lo, node_hi)
        if top + 2 > stack.shape[0]:
            grown = np.empty(2 * stack.shape[0], np.int64)
            grown[:top] = stack[:top]
            stack = grown
            grown_gaps = np.empty(2 * gaps.shape[0])
            grown_gaps[:top] = gaps[:top]
            gaps = grown_gaps
        if gl < gr:  # nearer child popped first
            stack[top], gaps[top] = r, gr
            stack[top + 1], gaps[top + 1] = l, gl
        else:
            stack[top], gaps[top] = l, gl
            stack[top + 1], gaps[top + 1] = r, gr
        top += 2
    if best_feat == 0:
        n = face_n[best_f]
    elif best_feat <= 3:
        n = vert_n[F[best_f, best_feat - 1]]
    else:
        n = edge_n[best_f, best_feat - 4]
    d = np.sqrt(best2)
    if (p - bq) @ n > 0.0:
        return -d, best_f
    return d, best_f


@njit(cache=True, nogil=True)
def _depths(points, V, F, face_n, edge_n, vert_n, node_c, node_r, node_lo, node_hi, left, right, start, count, order):
    out = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        out[i] = _depth(points[i], V, F, face_n, edge_n, vert_n, node_c, node_r, node_lo, node_hi, left, right, start, count, order)
    return out


@njit(cache=True, nogil=True, inline="always")
def _farthest_from_face(corners, V, F, f, q):
    """The largest distance from the corners (k, 3) of a triangle or segment to face f. A point inside
    is no deeper than its distance to any face, and that distance, convex, is largest at a corner:
    no point of the triangle or segment lies deeper than this."""
    fa, fb, fc = V[F[f, 0]], V[F[f, 1]], V[F[f, 2]]
    far = 0.0
    for i in range(corners.shape[0]):
        _closest_on_triangle(corners[i], fa, fb, fc, q)
        far = max(far, np.sqrt(((corners[i] - q) ** 2).sum()))
    return far


@njit(cache=True, nogil=True)
def _surface_depth(tris, best, tol, V, F, face_n, edge_n, vert_n, node_c, node_r, node_lo, node_hi, left, right, start, count, order):
    """The largest depth inside the mesh of any point of the triangles `tris` (t, 3, 3), at least
    `best`, to within tol below the truth (branch and bound, see the module doc)."""
    cap = 1024
    stack = np.empty((cap, 3, 3))
    g = np.zeros(3)
    q = np.zeros(3)
    for t in range(tris.shape[0]):
        stack[0] = tris[t]
        top = 1
        while top > 0:
            top -= 1
            a = stack[top, 0].copy()
            b = stack[top, 1].copy()
            c = stack[top, 2].copy()
            g[:] = (a + b + c) / 3.0
            r = max(np.sqrt(((a - g) ** 2).sum()), np.sqrt(((b - g) ** 2).sum()), np.sqrt(((c - g) ** 2).sum()))
            d, f = _depth_face(g, V, F, face_n, edge_n, vert_n, node_c, node_r, node_lo, node_hi, left, right, start, count, order)
            if d > best:
                best = d
            if d + r <= best + tol:
                continue
            # the bound that ends the search where the surfaces run parallel (d about 0 all over the
            # triangle, which d + r cannot tell)
            if _farthest_from_face(stack[top], V, F, f, q) <= best + tol:
                continue
            if top + 4 > cap:
                grown = np.empty((2 * cap, 3, 3))
                grown[:top] = stack[:top]
                stack = grown
                cap *= 2
            ab = 0.5 * (a + b)
            bc = 0.5 * (b + c)
            ca = 0.5 * (c + a)
            stack[top, 0] = a
            stack[top, 1] = ab
            stack[top, 2] = ca
            stack[top + 1, 0] = ab
            stack[top + 1, 1] = b
            stack[top + 1, 2] = bc
            stack[top + 2, 0] = ca
            stack[top + 2, 1] = bc
            stack[top + 2, 2] = c
            stack[top + 3, 0] = ab
            stack[top + 3, 1] = bc
            stack[top + 3, 2] = ca
            top += 4
    return best


@njit(cache=True, nogil=True)
def _edge_depth(segments, ends, best, tol, V, F, face_n, edge_n, vert_n, node_c, node_r, node_lo, node_hi, left, right,
                start, count, order):
    """The largest depth inside the mesh of any point of the segments (s, 2, 3), at least `best`, to
    within tol below the truth, given the depths of their ends (s, 2). Branch and bound, halving: the
    depth is 1-Lipschitz, so no point of a segment of length L whose ends lie da and db deep is
    deeper than (da + db + L) / 2; and, as in `_surface_depth`, no deeper than its ends' distance
    to the face nearest its midpoint."""
    cap = 256
    stack = np.empty((cap, 2, 3))
    depth = np.empty((cap, 2))
    q = np.zeros(3)
    for t in range(segments.shape[0]):
        stack[0] = segments[t]
        depth[0] = ends[t]
        top = 1
        while top > 0:
            top -= 1
            a = stack[top, 0].copy()
            b = stack[top, 1].copy()
            da, db = depth[top, 0], depth[top, 1]
            length = np.sqrt(((b - a) ** 2).sum())
            if 0.5 * (da + db + length) <= best + tol:
                continue
            g = 0.5 * (a + b)
            d, f = _depth_face(g, V, F, face_n, edge_n, vert_n, node_c, node_r, node_lo, node_hi, left, right, start,
                               count, order)
            if d > best:
                best = d
            if _farthest_from_face(stack[top], V, F, f, q) <= best + tol:
                continue
            if top + 2 > cap:
                grown = np.empty((2 * cap, 2, 3))
                grown[:top] = stack[:top]
                stack = grown
                grown_depth = np.empty((2 * cap, 2))
                grown_depth[:top] = depth[:top]
                depth = grown_depth
                cap *= 2
            stack[top, 0], stack[top, 1] = a, g
            depth[top, 0], depth[top, 1] = da, d
            stack[top + 1, 0], stack[top + 1, 1] = g, b
            depth[top + 1, 0], depth[top + 1, 1] = d, db
            top += 2
    return best


@njit(cache=True, nogil=True, inline="always")
def _pushed(stack, top, a, b):
    """`stack` (node indices, `top` of them in use) with a and b pushed, grown twice over when full."""
    if top + 2 > stack.shape[0]:
        grown = np.empty(2 * stack.shape[0], np.int64)
        grown[:top] = stack[:top]
        stack = grown
    stack[top] = a
    stack[top + 1] = b
    return stack


@njit(cache=True, nogil=True)
def _reaching_faces(node_c, node_r, left, right, start, count, order, n_faces, floor,
                    V, F, face_n, edge_n, vert_n, onode_c, onode_r, onode_lo, onode_hi, oleft, oright, ostart, ocount, oorder):
    """Which faces of a mesh (its hierarchy, placed in the other mesh's frame) can hold a point deeper
    than `floor` inside the other mesh. The depth is 1-Lipschitz, so no point of a node whose centre
    lies d deep is deeper than d + its radius: one query per node visited prunes the whole node, and
    only the nodes near the other's surface or inside it are opened. Every face left out is one the
    three passes would have measured and dropped (all its points below floor)."""
    keep = np.zeros(n_faces, np.bool_)
    stack = np.empty(128, np.int64)
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        k = stack[top]
        if _depth(node_c[k], V, F, face_n, edge_n, vert_n, onode_c, onode_r, onode_lo, onode_hi, oleft, oright,
                  ostart, ocount, oorder) + node_r[k] < floor:
            continue
        if left[k] < 0:
            for i in range(start[k], start[k] + count[k]):
                keep[order[i]] = True
            continue
        stack = _pushed(stack, top, left[k], right[k])
        top += 2
    return keep


@njit(cache=True, nogil=True)
def _surface_within(p, rho, V, F, face_n, edge_n, vert_n, node_c, node_r, node_lo, node_hi, left, right, start, count, order):
    """Whether any point of the mesh's surface lies closer than rho to p (stops at the first found:
    far cheaper than the closest point for a point deep inside, where every face is about as far)."""
    q = np.zeros(3)
    stack = np.empty(128, np.int64)
    stack[0] = 0
    top = 1
    rho2 = rho * rho
    while top > 0:
        top -= 1
        k = stack[top]
        if _node_gap(p, k, node_c, node_r, node_lo, node_hi) >= rho:
            continue
        if left[k] < 0:
            for i in range(start[k], start[k] + count[k]):
                f = order[i]
                _closest_on_triangle(p, V[F[f, 0]], V[F[f, 1]], V[F[f, 2]], q)
                if ((p - q) ** 2).sum() < rho2:
                    return True
            continue
        stack = _pushed(stack, top, left[k], right[k])
        top += 2
    return False


@njit(cache=True, nogil=True)
def _ball_free(p, n, r, tol, own, other):
    """Whether the ball of radius r - tol centred r inside p along -n holds no point of either surface.
    Balls tangent at p grow nested with r, so this turns False once and stays False."""
    c = p - r * n
    rho = max(r - tol, 0.0)
    return not (_surface_within(c, rho, *own) or _surface_within(c, rho, *other))


@njit(cache=True, nogil=True)
def _ball_depth(points, normals, rmax, best, tol, own, other):
    """The radius of the largest ball found inside both solids, grown inward from each surface
    point (own mesh's frame, with its outward normal) that lies inside the other solid; at least
    `best`. own / other: the two meshes' query arrays, `other` already in own's frame."""
    c = np.zeros(3)
    for i in range(points.shape[0]):
        p = points[i]
        n = normals[i]
        if _depth(p, *other) < -tol:
            continue
        # the largest r whose ball is free of both surfaces (bisection: freedom only ends as r
        # grows), tried only where it can beat the best by tol; the ball's centre is then checked
        # to lie inside both solids, and the distance to the nearer surface is what counts
        if not _ball_free(p, n, best + tol, tol, own, other):
            continue
        lo, hi = best + tol, rmax
        for _ in range(_BALL_STEPS):
            mid = 0.5 * (lo + hi)
            if _ball_free(p, n, mid, tol, own, other):
                lo = mid
            else:
                hi = mid
        c[:] = p - lo * n
        inside = min(_depth(c, *own), _depth(c, *other))
        if inside > best:
            best = inside
    return best


# --------------------------------------------------------------------------------- the measure


def _moved(geo: MeshGeometry, M: np.ndarray) -> MeshGeometry:
    """`geo`'s query arrays with its vertices, normals and hierarchy moved by the rigid transform M."""
    R, t = M[:3, :3], M[:3, 3]
    out = object.__new__(MeshGeometry)
    out.__dict__.update(vars(geo))
    out.V = np.ascontiguousarray(geo.V @ R.T + t)
    out.face_n = np.ascontiguousarray(geo.face_n @ R.T)
    out.edge_n = np.ascontiguousarray(geo.edge_n @ R.T)
    out.vert_n = np.ascontiguousarray(geo.vert_n @ R.T)
    out.node_c = np.ascontiguousarray(geo.node_c @ R.T + t)
    out.node_lo = np.full_like(geo.node_lo, -np.inf)  # boxes do not turn with the mesh: the spheres bound alone
    out.node_hi = np.full_like(geo.node_hi, np.inf)
    out.FC = np.ascontiguousarray(geo.FC @ R.T + t)
    return out


def _tangent_points(geo: MeshGeometry, faces: np.ndarray, verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points of the given faces (their corners: `verts`) a ball is grown from, with their outward
    normals: each corner (its vertex's pseudonormal), the centroid and the edges' midpoints (the face
    normal), so that a face's middle is tried whatever the triangulation (a quad's diagonal midpoint
    is its centre)."""
    tri = geo.V[geo.F[faces]]
    mids = 0.5 * (tri + np.roll(tri, -1, axis=1))
    pts = np.concatenate([geo.V[verts], geo.FC[faces], mids.reshape(-1, 3)])
    nrm = np.concatenate([geo.vert_n[verts], geo.face_n[faces], np.repeat(geo.face_n[faces], 3, axis=0)])
    return np.ascontiguousarray(pts), np.ascontiguousarray(nrm)


def penetration_depth(mesh_a: trimesh.Trimesh, pose_a: np.ndarray, mesh_b: trimesh.Trimesh, pose_b: np.ndarray,
                      tolerance_mm: float = DEPTH_TOLERANCE_MM) -> float:
    """mm: how deep two posed closed meshes interpenetrate (module doc), 0.0 when neither surface has a
    point inside the other solid. Poses: (4, 4) local -> common frame. Meshes must be closed and
    consistently oriented (outward normals), as the teeth are."""
    tol = float(tolerance_mm)
    ways = _facing(mesh_a, pose_a, mesh_b, pose_b, tol)
    best = _vertex_depth(ways)
    for own, other, M, moved, faces, verts, _ in ways:  # balls: the coincident and nearly coincident surfaces
        if len(faces):
            other_here = _moved(other, np.linalg.inv(M))  # other's arrays in own's frame
            pts, nrm = _tangent_points(own, faces, verts)
            best = _ball_depth(pts, nrm, float(own.node_r[0]), best, tol, own.args(), other_here.args())
    for own, other, _, moved, faces, *_ in ways:  # every point of the triangles that can reach inside
        if len(faces):
            best = _surface_depth(np.ascontiguousarray(moved[own.F[faces]]), best, tol, *other.args())
    return float(best)


def edge_penetration_depth(mesh_a: trimesh.Trimesh, pose_a: np.ndarray, mesh_b: trimesh.Trimesh, pose_b: np.ndarray,
                           tolerance_mm: float = DEPTH_TOLERANCE_MM) -> float:
    """mm: the deepest point of either mesh's vertices and edges inside the other solid, to within
    `tolerance_mm` below the truth; the measure a simulation step can afford (a few ms a touching
    pair, about what the vertex-based measure costs). Edges crossing faces or edges, with no vertex
    inside, read their real depth (crossed ridges sunk d: d / sqrt(2)). Left to `penetration_depth`:
    a deepest point inside a face of both meshes, and coincident surfaces (the ball)."""
    tol = float(tolerance_mm)
    ways = _facing(mesh_a, pose_a, mesh_b, pose_b, tol)
    best = _vertex_depth(ways)
    for own, other, _, moved, faces, verts, depths in ways:
        if len(faces):
            edges = own.edges[np.unique(own.face_edges[faces])]
            ends = np.searchsorted(verts, edges)  # verts: sorted, and holds every corner of these faces
            best = _edge_depth(np.ascontiguousarray(moved[edges]), np.ascontiguousarray(depths[ends]), best, tol,
                               *other.args())
    return float(best)


def _facing(mesh_a, pose_a, mesh_b, pose_b, tol: float) -> list:
    """Both ways (a in b, b in a): (own, other, own -> other transform, own's vertices in other's frame,
    own's faces that can reach deeper than -tol inside other, their corners (sorted vertex indices)
    and the corners' depths inside other); empty when the root spheres are apart."""
    ga, gb = mesh_geometry(mesh_a), mesh_geometry(mesh_b)
    Ta, Tb = np.asarray(pose_a, float), np.asarray(pose_b, float)
    a_in_b = np.linalg.solve(Tb, Ta)  # a's local frame -> b's
    b_in_a = np.linalg.inv(a_in_b)
    ca = a_in_b[:3, :3] @ ga.node_c[0] + a_in_b[:3, 3]
    if np.linalg.norm(ca - gb.node_c[0]) > ga.node_r[0] + gb.node_r[0]:
        return []
    ways = []
    for own, other, M in ((ga, gb, a_in_b), (gb, ga, b_in_a)):
        R, t = M[:3, :3], M[:3, 3]
        moved = np.ascontiguousarray(own.V @ R.T + t)  # own's vertices in other's frame
        centers = np.ascontiguousarray(own.node_c @ R.T + t)
        faces = np.flatnonzero(_reaching_faces(centers, own.node_r, own.left, own.right, own.start, own.count,
                                               own.order, len(own.F), -tol, *other.args()))
        verts = np.unique(own.F[faces])
        depths = _depths(np.ascontiguousarray(moved[verts]), *other.args())
        ways.append((own, other, M, moved, faces, verts, depths))
    return ways


def _vertex_depth(ways: list) -> float:
    """The deepest vertex of either mesh inside the other (0.0 when none is): never below the
    vertex-based measure, and a first bound for the searches that follow."""
    return max([0.0] + [float(depths.max()) for *_, depths in ways if len(depths)])

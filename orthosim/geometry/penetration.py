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

Depths are signed distances, negated (positive inside), from `geometry.signeddistance`: the closest
point on each mesh's hierarchy of faces and the sign of the closest feature's angle-weighted
pseudonormal, exact for closed, consistently oriented meshes (`MeshSurface.closed`). This module
holds only the searches on top of them. Hand-written in numba: FCL answers no inside test and one
closest pair per call, and trimesh's signed distance costs about a millisecond a point; this costs
microseconds a point. Imported on demand only (numba's start-up is not for the drawing side):
`orthosim.geometry` does not import it. Until compiling pays (`signeddistance.compiled_pays`) the
searches run in numpy (`_edge_depth_numpy` and the others beside the kernels): each branch and bound
replayed in the kernel's order, on `signeddistance`'s numpy queries, so the depths are the same
numbers bit for bit.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from orthosim.geometry.signeddistance import (STACK, MeshSurface, closest_face, closest_on_triangles_numpy,
                                              compiled_pays_for, distance_to_face, distance_to_face_scalar,
                                              mesh_surface, node_gaps_numpy,
                                              signed_distance_scalar, signed_distances, signed_distances_numpy,
                                              squared_distances, surface_within)
from orthosim.system.firstrun import announce_compiles

if TYPE_CHECKING:  # a mesh's two arrays are all it reads: a run's child never imports trimesh for a depth
    import trimesh

DEPTH_TOLERANCE_MM = 0.01  # the surface depth is found to within this below the truth
_BALL_STEPS = 24  # bisection steps of a ball's radius (root radius / 2**24: far below the tolerance)


# --------------------------------------------------------------------------------- compiled


announce_compiles()  # a kernel compiled here (not loaded from numba's cache) says so on stderr


@njit(cache=True, nogil=True)
def _depth_face(p, s):
    """(mm p lies inside the mesh `s`, negative outside; the face holding its closest surface point)."""
    d, f = closest_face(p, s, np.inf)
    return -d, f


@njit(cache=True, nogil=True)
def _depth(p, s):
    """mm p lies inside the mesh `s` (its distance to the surface), negative outside."""
    return -closest_face(p, s, np.inf)[0]


@njit(cache=True, nogil=True, inline="always")
def _farthest_from_face(corners, s, f):
    """The largest distance from the corners (k, 3) of a triangle or segment to face f. A point inside
    is no deeper than its distance to any face, and that distance, convex, is largest at a corner:
    no point of the triangle or segment lies deeper than this."""
    far = 0.0
    for i in range(corners.shape[0]):
        far = max(far, distance_to_face(corners[i], s, f))
    return far


@njit(cache=True, nogil=True, inline="always")
def _copy(dst, src):
    """dst[...] = src for 1-D arrays of one length, element by element: numba's own array assignment
    compiles its shape-mismatch error path (string formatting), seconds of every cold start."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


@njit(cache=True, nogil=True, inline="always")
def _copy_rows(dst, src):
    """`_copy` for 2-D arrays of one shape."""
    for i in range(src.shape[0]):
        _copy(dst[i], src[i])


@njit(cache=True, nogil=True)
def _surface_depth(tris, best, tol, s):
    """The largest depth inside the mesh `s` of any point of the triangles `tris` (t, 3, 3), at least
    `best`, to within tol below the truth (branch and bound, see the module doc)."""
    cap = 1024
    stack = np.empty((cap, 3, 3))
    g = np.zeros(3)
    for t in range(tris.shape[0]):
        _copy_rows(stack[0], tris[t])
        top = 1
        while top > 0:
            top -= 1
            a = stack[top, 0].copy()
            b = stack[top, 1].copy()
            c = stack[top, 2].copy()
            for i in range(3):
                g[i] = (a[i] + b[i] + c[i]) / 3.0
            r = max(np.sqrt(((a - g) ** 2).sum()), np.sqrt(((b - g) ** 2).sum()), np.sqrt(((c - g) ** 2).sum()))
            d, f = _depth_face(g, s)
            if d > best:
                best = d
            if d + r <= best + tol:
                continue
            # the bound that ends the search where the surfaces run parallel (d about 0 all over the
            # triangle, which d + r cannot tell)
            if _farthest_from_face(stack[top], s, f) <= best + tol:
                continue
            if top + 4 > cap:
                grown = np.empty((2 * cap, 3, 3))
                for i in range(top):
                    _copy_rows(grown[i], stack[i])
                stack = grown
                cap *= 2
            ab = 0.5 * (a + b)
            bc = 0.5 * (b + c)
            ca = 0.5 * (c + a)
            _copy(stack[top, 0], a)
            _copy(stack[top, 1], ab)
            _copy(stack[top, 2], ca)
            _copy(stack[top + 1, 0], ab)
            _copy(stack[top + 1, 1], b)
            _copy(stack[top + 1, 2], bc)
            _copy(stack[top + 2, 0], ca)
            _copy(stack[top + 2, 1], bc)
            _copy(stack[top + 2, 2], c)
            _copy(stack[top + 3, 0], ab)
            _copy(stack[top + 3, 1], bc)
            _copy(stack[top + 3, 2], ca)
            top += 4
    return best


@njit(cache=True, nogil=True)
def _edge_depth(segments, ends, best, tol, s):
    """The largest depth inside the mesh `s` of any point of the segments (n, 2, 3), at least `best`,
    to within tol below the truth, given the depths of their ends (n, 2). Branch and bound, halving:
    the depth is 1-Lipschitz, so no point of a segment of length L whose ends lie da and db deep is
    deeper than (da + db + L) / 2; and, as in `_surface_depth`, no deeper than its ends' distance
    to the face nearest its midpoint."""
    cap = 256
    stack = np.empty((cap, 2, 3))
    depth = np.empty((cap, 2))
    for t in range(segments.shape[0]):
        _copy_rows(stack[0], segments[t])
        _copy(depth[0], ends[t])
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
            d, f = _depth_face(g, s)
            if d > best:
                best = d
            if _farthest_from_face(stack[top], s, f) <= best + tol:
                continue
            if top + 2 > cap:
                grown = np.empty((2 * cap, 2, 3))
                grown_depth = np.empty((2 * cap, 2))
                for i in range(top):
                    _copy_rows(grown[i], stack[i])
                    _copy(grown_depth[i], depth[i])
                stack = grown
                depth = grown_depth
                cap *= 2
            _copy(stack[top, 0], a)
            _copy(stack[top, 1], g)
            depth[top, 0], depth[top, 1] = da, d
            _copy(stack[top + 1, 0], g)
            _copy(stack[top + 1, 1], b)
            depth[top + 1, 0], depth[top + 1, 1] = d, db
            top += 2
    return best


@njit(cache=True, nogil=True)
def _reaching_faces(own, other, floor):
    """Which faces of the mesh `own` (its hierarchy's spheres placed in the other mesh's frame) can
    hold a point deeper than `floor` inside the mesh `other`. The depth is 1-Lipschitz, so no point
    of a node whose centre lies d deep is deeper than d + its radius: one query per node visited
    prunes the whole node, and only the nodes near the other's surface or inside it are opened.
    Every face left out is one the three passes would have measured and dropped (all its points
    below floor)."""
    keep = np.zeros(own.faces.shape[0], np.bool_)
    stack = np.empty(STACK, np.int64)
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        k = stack[top]
        if _depth(own.node_center[k], other) + own.node_radius[k] < floor:
            continue
        if own.left[k] < 0:
            for i in range(own.start[k], own.start[k] + own.count[k]):
                keep[own.order[i]] = True
            continue
        stack[top], stack[top + 1] = own.left[k], own.right[k]
        top += 2
    return keep


@njit(cache=True, nogil=True)
def _ball_free(p, n, r, tol, own, other):
    """Whether the ball of radius r - tol centred r inside p along -n holds no point of either surface.
    Balls tangent at p grow nested with r, so this turns False once and stays False."""
    c = p - r * n
    rho = max(r - tol, 0.0)
    return not (surface_within(c, rho, own) or surface_within(c, rho, other))


@njit(cache=True, nogil=True)
def _ball_depth(points, normals, rmax, best, tol, own, other):
    """The radius of the largest ball found inside both solids, grown inward from each surface
    point (own mesh's frame, with its outward normal) that lies inside the other solid; at least
    `best`. own / other: the two meshes' arrays, `other` already in own's frame."""
    c = np.zeros(3)
    for i in range(points.shape[0]):
        p = points[i]
        n = normals[i]
        if _depth(p, other) < -tol:
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
        for i in range(3):
            c[i] = p[i] - lo * n[i]
        inside = min(_depth(c, own), _depth(c, other))
        if inside > best:
            best = inside
    return best


# --------------------------------------------------------------------------------- the same in numpy


def _depth_faces_numpy(points, s):
    """`_depth_face` of each of the points (n, 3) in numpy: ((n,) mm inside `s`, (n,) faces)."""
    d, f = signed_distances_numpy(points, s, np.inf)
    return -d, f


def _depth_face_scalar(p, s) -> tuple[float, int]:
    """`_depth_face` of the one point p (3,) in Python floats: (mm inside `s`, face)."""
    d, f = signed_distance_scalar(p, s, math.inf)
    return -d, f


def _farthest_from_face_numpy(corners, s, f) -> float:
    """`_farthest_from_face` in Python floats: the largest distance from the corners (k, 3) to face f."""
    far = 0.0
    for corner in corners:
        far = max(far, distance_to_face_scalar(corner, s, f))
    return far


def _reaching_faces_numpy(own, other, floor):
    """`_reaching_faces` in numpy, the same faces: the hierarchy opened a level at a time (which
    nodes are opened does not depend on the order they are asked in)."""
    keep = np.zeros(own.faces.shape[0], np.bool_)
    nodes = np.zeros(1, np.int64)
    while len(nodes):
        depth, _ = _depth_faces_numpy(own.node_center[nodes], other)
        nodes = nodes[~(depth + own.node_radius[nodes] < floor)]
        leaf = own.left[nodes] < 0
        for k in nodes[leaf]:
            keep[own.order[own.start[k]:own.start[k] + own.count[k]]] = True
        nodes = np.stack([own.left[nodes[~leaf]], own.right[nodes[~leaf]]], axis=1).reshape(-1)
    return keep


def _edge_depth_numpy(segments, ends, best, tol, s):
    """`_edge_depth` in numpy, the same number: its branch and bound replayed segment by segment in
    the same order (each bound depends on the best depth found so far), one depth query a split. In
    Python floats: the kernel's array operations are per element, so the same on each coordinate."""
    best = float(best)
    for (a, b), (da, db) in zip(segments.tolist(), ends.tolist()):
        stack = [(a, b, da, db)]
        while stack:
            a, b, da, db = stack.pop()
            dx, dy, dz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            if 0.5 * (da + db + length) <= best + tol:
                continue
            g = (0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2]))
            d, face = _depth_face_scalar(g, s)
            if d > best:
                best = d
            if _farthest_from_face_numpy((a, b), s, face) <= best + tol:
                continue
            stack.append((a, g, da, d))
            stack.append((g, b, d, db))
    return best


def _surface_depth_numpy(tris, best, tol, s):
    """`_surface_depth` in numpy, the same number: its branch and bound replayed in the same order."""
    best = float(best)
    for t in range(tris.shape[0]):
        stack = [(tris[t, 0], tris[t, 1], tris[t, 2])]
        while stack:
            a, b, c = stack.pop()
            g = (a + b + c) / 3.0
            r = max(_length(a - g), _length(b - g), _length(c - g))
            d, face = _depth_face_scalar(g, s)
            if d > best:
                best = d
            if d + r <= best + tol:
                continue
            if _farthest_from_face_numpy((a, b, c), s, face) <= best + tol:
                continue
            ab, bc, ca = 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)
            stack.extend([(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)])
    return best


def _length(v) -> float:
    """|v| mm of a (3,) vector, its squares summed x, then y, then z (as the kernels sum them)."""
    x, y, z = float(v[0]), float(v[1]), float(v[2])
    return math.sqrt(x * x + y * y + z * z)


def _surface_within_numpy(p, rho: float, s) -> bool:
    """`surface_within` in numpy: whether any point of the surface of `s` lies closer than rho to p."""
    leaves = np.flatnonzero(s.left < 0)
    near = leaves[node_gaps_numpy(p[None], s, leaves)[0] < rho]
    if not len(near):
        return False
    rows = np.concatenate([np.arange(s.start[k], s.start[k] + s.count[k]) for k in near])
    P = np.repeat(p[None], len(rows), axis=0)
    _, x, y, z = closest_on_triangles_numpy(P, s.triangles[rows])
    return bool(np.any(squared_distances(P, x, y, z) < rho * rho))


def _ball_free_numpy(p, n, r: float, tol: float, own, other) -> bool:
    """`_ball_free` in numpy."""
    c = p - r * n
    rho = max(r - tol, 0.0)
    return not (_surface_within_numpy(c, rho, own) or _surface_within_numpy(c, rho, other))


def _ball_depth_numpy(points, normals, rmax, best, tol, own, other):
    """`_ball_depth` in numpy, the same number: the points' depths inside `other` asked at once (they
    do not depend on the best found), each ball's bisection replayed in order."""
    best = float(best)
    depth, _ = _depth_faces_numpy(points, other)
    for i in np.flatnonzero(~(depth < -tol)):
        p, n = points[i], normals[i]
        if not _ball_free_numpy(p, n, best + tol, tol, own, other):
            continue
        lo, hi = best + tol, float(rmax)
        for _ in range(_BALL_STEPS):
            mid = 0.5 * (lo + hi)
            if _ball_free_numpy(p, n, mid, tol, own, other):
                lo = mid
            else:
                hi = mid
        c = p - lo * n
        inside = min(_depth_face_scalar(c, own)[0], _depth_face_scalar(c, other)[0])
        if inside > best:
            best = inside
    return best


# --------------------------------------------------------------------------------- the measure

_EDGE_KERNELS = (signed_distances, _depth_face, _depth, _edge_depth, _reaching_faces)  # what a step's depth compiles


def _tangent_points(own: MeshSurface, faces: np.ndarray, verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points of the given faces (their corners: `verts`) a ball is grown from, with their outward
    normals: each corner (its vertex's pseudonormal), the centroid and the edges' midpoints (the face
    normal), so that a face's middle is tried whatever the triangulation (a quad's diagonal midpoint
    is its centre)."""
    a = own.arrays
    tri = a.vertices[a.faces[faces]]
    mids = 0.5 * (tri + np.roll(tri, -1, axis=1))
    pts = np.concatenate([a.vertices[verts], tri.mean(axis=1), mids.reshape(-1, 3)])
    nrm = np.concatenate([a.vertex_normals[verts], a.face_normals[faces], np.repeat(a.face_normals[faces], 3, axis=0)])
    return np.ascontiguousarray(pts), np.ascontiguousarray(nrm)


def penetration_depth(mesh_a: trimesh.Trimesh, pose_a: np.ndarray, mesh_b: trimesh.Trimesh, pose_b: np.ndarray,
                      tolerance_mm: float = DEPTH_TOLERANCE_MM) -> float:
    """mm: how deep two posed closed meshes interpenetrate (module doc), 0.0 when neither surface has a
    point inside the other solid. Poses: (4, 4) local -> common frame. Meshes must be closed and
    consistently oriented (outward normals), as the teeth are."""
    tol = float(tolerance_mm)
    compiled = compiled_pays_for(max(len(mesh_a.faces), len(mesh_b.faces)), *_EDGE_KERNELS, _ball_depth, _surface_depth)
    ways = _facing(mesh_a, pose_a, mesh_b, pose_b, tol, compiled)
    best = _vertex_depth(ways)
    ball_depth = _ball_depth if compiled else _ball_depth_numpy
    for own, other, M, moved, faces, verts, _ in ways:  # balls: the coincident and nearly coincident surfaces
        if len(faces):
            other_here = other.moved(np.linalg.inv(M))  # other's arrays in own's frame
            pts, nrm = _tangent_points(own, faces, verts)
            best = ball_depth(pts, nrm, float(own.arrays.node_radius[0]), best, tol, own.arrays, other_here)
    surface_depth = _surface_depth if compiled else _surface_depth_numpy
    for own, other, _, moved, faces, *_ in ways:  # every point of the triangles that can reach inside
        if len(faces):
            best = surface_depth(np.ascontiguousarray(moved[own.arrays.faces[faces]]), best, tol, other.arrays)
    return float(best)


def edge_penetration_depth(mesh_a: trimesh.Trimesh, pose_a: np.ndarray, mesh_b: trimesh.Trimesh, pose_b: np.ndarray,
                           tolerance_mm: float = DEPTH_TOLERANCE_MM) -> float:
    """mm: the deepest point of either mesh's vertices and edges inside the other solid, to within
    `tolerance_mm` below the truth; the measure a simulation step can afford (a few ms a touching
    pair, about what the vertex-based measure costs). Edges crossing faces or edges, with no vertex
    inside, read their real depth (crossed ridges sunk d: d / sqrt(2)). Left to `penetration_depth`:
    a deepest point inside a face of both meshes, and coincident surfaces (the ball)."""
    tol = float(tolerance_mm)
    compiled = compiled_pays_for(max(len(mesh_a.faces), len(mesh_b.faces)), *_EDGE_KERNELS)
    ways = _facing(mesh_a, pose_a, mesh_b, pose_b, tol, compiled)
    best = _vertex_depth(ways)
    for own, other, _, moved, faces, verts, depths in ways:
        if len(faces):
            edges = own.edges[np.unique(own.face_edges[faces])]
            ends = np.searchsorted(verts, edges)  # verts: sorted, and holds every corner of these faces
            best = (_edge_depth if compiled else _edge_depth_numpy)(
                np.ascontiguousarray(moved[edges]), np.ascontiguousarray(depths[ends]), best, tol, other.arrays)
    return float(best)


def _facing(mesh_a, pose_a, mesh_b, pose_b, tol: float, compiled: bool = True) -> list:
    """Both ways (a in b, b in a): (own, other (their `MeshSurface`s), own -> other transform, own's
    vertices in other's frame, own's faces that can reach deeper than -tol inside other, their
    corners (sorted vertex indices) and the corners' depths inside other); empty when the root
    spheres are apart. compiled: numba's kernels, else their numpy forms (the same numbers)."""
    sa, sb = mesh_surface(mesh_a), mesh_surface(mesh_b)
    Ta, Tb = np.asarray(pose_a, float), np.asarray(pose_b, float)
    a_in_b = np.linalg.solve(Tb, Ta)  # a's local frame -> b's
    b_in_a = np.linalg.inv(a_in_b)
    (ca, ra), (cb, rb) = sa.bounding_sphere, sb.bounding_sphere
    if np.linalg.norm(a_in_b[:3, :3] @ ca + a_in_b[:3, 3] - cb) > ra + rb:
        return []
    ways = []
    for own, other, M in ((sa, sb, a_in_b), (sb, sa, b_in_a)):
        R, t = M[:3, :3], M[:3, 3]
        moved = np.ascontiguousarray(own.arrays.vertices @ R.T + t)  # own's vertices in other's frame
        placed = own.arrays._replace(node_center=np.ascontiguousarray(own.arrays.node_center @ R.T + t))
        faces = np.flatnonzero((_reaching_faces if compiled else _reaching_faces_numpy)(placed, other.arrays, -tol))
        verts = np.unique(own.arrays.faces[faces])
        query = signed_distances if compiled else signed_distances_numpy
        depths = -query(np.ascontiguousarray(moved[verts]), other.arrays, np.inf)[0]
        ways.append((own, other, M, moved, faces, verts, depths))
    return ways


def _vertex_depth(ways: list) -> float:
    """The deepest vertex of either mesh inside the other (0.0 when none is): never below the
    vertex-based measure, and a first bound for the searches that follow."""
    return max([0.0] + [float(depths.max()) for *_, depths in ways if len(depths)])

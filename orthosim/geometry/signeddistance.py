"""Signed distance from points to a closed triangle mesh: how far, and on which side of its surface.

    surface = mesh_surface(mesh)                         # built once per mesh, kept while it lives
    d, face = surface.signed_distance(points, cap_mm)    # (n,) mm, negative inside; (n,) closest face

The one place the exact point-to-mesh queries live; the distance map (`analysis.distancemap`), the
bite's closure (`movement.closure`) and the interpenetration depth (`geometry.penetration`) all ask
it. A distance is the minimum over the triangles of the exact point-triangle distance in float64
(the closest point by Ericson's Voronoi regions). The triangles sit in a bounding hierarchy of the
mesh's faces, a sphere and a box per node (`build_hierarchy`); a query descends it nearest node
first and skips every node whose bound lies beyond the best distance found, so no closer triangle
is ever skipped. Inside or outside: the sign of the closest feature's angle-weighted pseudonormal
(Baerentzen and Aanaes 2005), exact for closed, consistently oriented meshes (`MeshSurface.closed`).

Distances can be capped: a point with no surface within `cap_mm` is answered +inf ("far") after a
look at the hierarchy's top, which keeps a whole arch's distance map to a fraction of a second. A
mesh moved by a rigid transform (`MeshSurface.moved`) keeps its hierarchy's spheres, not its boxes.

Compiled with numba: trimesh's closest-point query gathers candidates in Python and FCL answers one
object pair per call; for the 240,000 crown vertices of a real dentition both take seconds or more,
this about one. Every compiled query takes the mesh as one argument, `SurfaceArrays` (a named tuple
of arrays, which numba compiles and caches like its arrays). Imported on demand only (numba's
start-up is not for the drawing side).

Until compiling pays (`compiled_pays`: the kernels already in numba's cache, or enough queries
answered in this process), the same queries run without numba (`signed_distances_numpy`,
`build_hierarchy_numpy`), so that a short first run on a fresh install never waits for numba's
compiler. They give the very numbers the kernels give: the hierarchy built in numpy with the same
IEEE operations per element in the same order; the distances by the kernel's own descent replayed
in Python floats (the same operations, the same nodes in the same order, so among equally near
faces the one the kernel meets first).
"""

from __future__ import annotations

import math
import time
import weakref
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numba import njit

from orthosim.storage import numpytally
from orthosim.system.firstrun import announce_compiles

if TYPE_CHECKING:  # a mesh's two arrays are all it reads: a run's child never imports trimesh for a depth
    import trimesh

LEAF_FACES = 8  # faces in a leaf of the hierarchy
# Nodes a depth-first descent of a hierarchy holds at once: one waiting sibling per level and the two
# children just pushed. `build_hierarchy` halves a node's faces, so a mesh of n faces has at most
# log2(n) + 1 levels: 128 holds any mesh that int64 indices can count.
STACK = 128


class SurfaceArrays(NamedTuple):
    """A mesh as the compiled queries take it (mm, the mesh's frame unless moved). Node `k` of the
    hierarchy covers the faces `order[start[k]:start[k] + count[k]]`, whose corners are
    `triangles[start[k]:start[k] + count[k]]` (one stretch of memory a leaf, faster to read than
    the corners through `faces`); children `left[k]`, `right[k]` (-1 for a leaf), node 0
    the root."""

    vertices: np.ndarray  # (v, 3) float64
    faces: np.ndarray  # (f, 3) int64 vertex indices, counter-clockwise seen from outside
    triangles: np.ndarray  # (f, 3, 3) corners of face order[i] at row i (the hierarchy's order)
    face_normals: np.ndarray  # (f, 3) unit, outward
    face_edges: np.ndarray  # (f, 3) int64 each face's edges ab, bc, ca (indices into edge_normals)
    edge_normals: np.ndarray  # (e, 3) per edge the sum of its two faces' normals
    vertex_normals: np.ndarray  # (v, 3) unit, angle-weighted
    node_center: np.ndarray  # (k, 3) each node's bounding sphere
    node_radius: np.ndarray  # (k,)
    node_lo: np.ndarray  # (k, 3) each node's box (-inf / +inf where the mesh was turned: spheres only)
    node_hi: np.ndarray  # (k, 3)
    left: np.ndarray  # (k,) int64
    right: np.ndarray  # (k,) int64
    start: np.ndarray  # (k,) int64
    count: np.ndarray  # (k,) int64
    order: np.ndarray  # (f,) int64


class MeshSurface:
    """A triangle mesh prepared for signed distances (the model: built once, read-only): its arrays
    for the compiled queries (`arrays`), its unique edges (`edges` (e, 2) vertex pairs, lower index
    first, in the order of `arrays.edge_normals`) and whether it is closed and consistently
    oriented, so that the sign tells inside from outside."""

    def __init__(self, mesh: trimesh.Trimesh):
        V = np.ascontiguousarray(mesh.vertices, float)
        F = np.ascontiguousarray(mesh.faces, np.int64)
        if len(F) == 0:
            raise ValueError("a mesh with no faces has no inside")
        self.edges, face_edges = _edges(V, F)
        self.closed = _closed(F, face_edges, len(self.edges))
        face_n, edge_n, vert_n = _pseudonormals(V, F, face_edges, len(self.edges))
        tri = V[F]
        centroids = tri.mean(axis=1)
        radii = np.linalg.norm(tri - centroids[:, None, :], axis=2).max(axis=1) * (1 + 1e-12) + 1e-12
        build = build_hierarchy if compiled_pays_for(len(F), build_hierarchy) else build_hierarchy_numpy  # same arrays
        tree = build(centroids, radii, tri.min(axis=1), tri.max(axis=1), LEAF_FACES)
        self.arrays = SurfaceArrays(V, F, np.ascontiguousarray(tri[tree[-1]]), face_n, face_edges, edge_n, vert_n, *tree)
        lo, hi = V.min(axis=0), V.max(axis=0)
        self._sphere = (lo + hi) / 2, float(np.linalg.norm(V - (lo + hi) / 2, axis=1).max())

    @property
    def face_edges(self) -> np.ndarray:
        """(f, 3) each face's edges ab, bc, ca, as rows of `edges`."""
        return self.arrays.face_edges

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """((3,), (3,)) mm: the box of the triangles' corners (the hierarchy's root box)."""
        return self.arrays.node_lo[0], self.arrays.node_hi[0]

    @property
    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """((3,) centre, radius) mm: a sphere holding the mesh, centred on its box (tighter than the
        hierarchy's root, which is centred on the faces' mean: what keeps far teeth out of a map)."""
        return self._sphere

    def signed_distance(self, points: np.ndarray, cap_mm: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) points in the mesh's frame (mm) -> ((n,) signed distance to the surface, mm,
        negative inside, +inf where no point of the surface lies within `cap_mm`; (n,) the face
        holding the closest point, -1 beyond the cap). A cap keeps far points cheap."""
        pts = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 3))
        compiled = compiled_pays_for(len(self.arrays.faces), signed_distances)
        query = signed_distances if compiled else signed_distances_numpy  # the same numbers
        return query(pts, self.arrays, float(cap_mm))

    def moved(self, M: np.ndarray) -> SurfaceArrays:
        """The arrays with the mesh moved by the rigid transform M (4, 4): corners, normals and
        spheres turned and shifted; the boxes, which do not turn with it, left unbounded."""
        R, t = M[:3, :3], M[:3, 3]
        a = self.arrays
        return a._replace(vertices=np.ascontiguousarray(a.vertices @ R.T + t),
                          triangles=np.ascontiguousarray(a.triangles @ R.T + t),
                          face_normals=np.ascontiguousarray(a.face_normals @ R.T),
                          edge_normals=np.ascontiguousarray(a.edge_normals @ R.T),
                          vertex_normals=np.ascontiguousarray(a.vertex_normals @ R.T),
                          node_center=np.ascontiguousarray(a.node_center @ R.T + t),
                          node_lo=np.full_like(a.node_lo, -np.inf), node_hi=np.full_like(a.node_hi, np.inf))


_SURFACES: dict[int, tuple] = {}  # id(mesh) -> (weak reference to it, its MeshSurface)


def mesh_surface(mesh: trimesh.Trimesh) -> MeshSurface:
    """The mesh's `MeshSurface`, built on first use and kept while the mesh lives."""
    entry = _SURFACES.get(id(mesh))
    if entry is None or entry[0]() is not mesh:
        for key in [k for k, (ref, _) in _SURFACES.items() if ref() is None]:
            del _SURFACES[key]
        entry = _SURFACES[id(mesh)] = (weakref.ref(mesh), MeshSurface(mesh))
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
    """Unit face normals (f, 3), edge pseudonormals (e, 3: the sum of the normals of the faces
    sharing the edge) and angle-weighted vertex normals (v, 3): each
    face's normal weighted by its angle at the vertex (Baerentzen and Aanaes 2005, "Signed distance
    computation using the angle weighted pseudonormal", IEEE TVCG 11(3)). Only their directions
    count: the sign of (p - closest point) against them."""
    tri = V[F]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    flat = face_edges.reshape(-1)
    per_corner = np.repeat(n, 3, axis=0)
    edge_n = np.ascontiguousarray(np.stack([np.bincount(flat, per_corner[:, a], n_edges) for a in range(3)], axis=1))
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


# --------------------------------------------------------------------------------- compiled


announce_compiles()  # a kernel compiled here (not loaded from numba's cache) says so on stderr


@njit(cache=True, nogil=True)
def build_hierarchy(FC, FR, corner_lo, corner_hi, leaf_faces):
    """The faces' bounding hierarchy (the `SurfaceArrays` fields from `node_center` on), depth first
    from the root: each node halves its faces at the median centroid along its centroids' longest
    extent, down to `leaf_faces` a leaf. A node's sphere is centred on its centroids' mean and holds
    its faces whole (FC (f, 3) centroids, FR (f,) radii); its box holds their corners (corner_lo,
    corner_hi (f, 3)). Compiled: a real tooth's 40,000 faces make 16,000 nodes. Rows are written
    element by element: assigning an array or a tuple to a row compiles numba's shape-mismatch
    error path (its string formatting), seconds of every cold start."""
    n = FC.shape[0]
    most = 2 * n
    centers, radii = np.empty((most, 3)), np.empty(most)
    lo, hi = np.empty((most, 3)), np.empty((most, 3))
    left, right = np.full(most, -1, np.int64), np.full(most, -1, np.int64)
    start, count = np.empty(most, np.int64), np.empty(most, np.int64)
    order = np.arange(n)
    todo = np.empty((most, 4), np.int64)  # (start, end, parent, which child)
    todo[0, 0], todo[0, 1], todo[0, 2], todo[0, 3] = 0, n, -1, 0
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
        for axis in range(3):
            centers[k, axis] = c[axis]
        radii[k] = r * (1 + 1e-12) + 1e-12
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
            halves = idx[np.argsort(FC[idx, axis], kind="mergesort")]
            for t in range(e - s):
                order[s + t] = halves[t]
            mid = (e - s) // 2
            todo[waiting, 0], todo[waiting, 1], todo[waiting, 2], todo[waiting, 3] = s + mid, e, k, 1
            todo[waiting + 1, 0], todo[waiting + 1, 1], todo[waiting + 1, 2], todo[waiting + 1, 3] = s, s + mid, k, 0
            waiting += 2
        k += 1
    return (np.ascontiguousarray(centers[:k]), radii[:k].copy(), np.ascontiguousarray(lo[:k]), np.ascontiguousarray(hi[:k]),
            left[:k].copy(), right[:k].copy(), start[:k].copy(), count[:k].copy(), order)


@njit(cache=True, nogil=True, inline="always")
def _along_sides(p, x, y, z, abx, aby, abz, acx, acy, acz):
    """The dot products of p - (x, y, z) with a triangle's sides ab and ac."""
    px, py, pz = p[0] - x, p[1] - y, p[2] - z
    return abx * px + aby * py + abz * pz, acx * px + acy * py + acz * pz


@njit(cache=True, nogil=True, inline="always")
def closest_on_triangle(p, corners, i):
    """The closest point to p (3,) of triangle i of `corners` (n, 3, 3: a, b, c each): (feature, x,
    y, z), feature 0 the triangle's inside, 1-3 its corner a, b, c, 4-6 its edge ab, bc, ca.
    Ericson 2005, Real-Time Collision Detection, section 5.1.5: the Voronoi regions of the corners
    and edges tested in turn by the dot products d1..d6 and the barycentric va, vb, vc. On scalars:
    no array is made."""
    ax, ay, az = corners[i, 0, 0], corners[i, 0, 1], corners[i, 0, 2]
    bx, by, bz = corners[i, 1, 0], corners[i, 1, 1], corners[i, 1, 2]
    cx, cy, cz = corners[i, 2, 0], corners[i, 2, 1], corners[i, 2, 2]
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    d1, d2 = _along_sides(p, ax, ay, az, abx, aby, abz, acx, acy, acz)
    if d1 <= 0.0 and d2 <= 0.0:
        return 1, ax, ay, az
    d3, d4 = _along_sides(p, bx, by, bz, abx, aby, abz, acx, acy, acz)
    if d3 >= 0.0 and d4 <= d3:
        return 2, bx, by, bz
    d5, d6 = _along_sides(p, cx, cy, cz, abx, aby, abz, acx, acy, acz)
    if d6 >= 0.0 and d5 <= d6:  # corner c before edge ab (Ericson's order): their regions are apart
        return 3, cx, cy, cz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return 4, ax + v * abx, ay + v * aby, az + v * abz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return 6, ax + w * acx, ay + w * acy, az + w * acz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 5, bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return 0, ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w


@njit(cache=True, nogil=True)
def distance_to_face(p, s, f):
    """mm from p (3,) to face f of the mesh `s`."""
    corners = np.empty((1, 3, 3))
    for k in range(3):  # element by element: a row assignment compiles numba's error-message path
        v = s.faces[f, k]
        for axis in range(3):
            corners[0, k, axis] = s.vertices[v, axis]
    _, x, y, z = closest_on_triangle(p, corners, 0)
    return np.sqrt((p[0] - x) ** 2 + (p[1] - y) ** 2 + (p[2] - z) ** 2)


@njit(cache=True, nogil=True, inline="always")
def node_gap(p, s, k):
    """A lower bound of the distance from p to node k's faces: the larger of the gaps to its bounding
    sphere and to its box (on a curved shell the box is the tighter one off the surface)."""
    c, lo, hi = s.node_center, s.node_lo, s.node_hi
    dx = p[0] - c[k, 0]
    dy = p[1] - c[k, 1]
    dz = p[2] - c[k, 2]
    sphere = np.sqrt(dx * dx + dy * dy + dz * dz) - s.node_radius[k]
    bx = max(lo[k, 0] - p[0], 0.0, p[0] - hi[k, 0])
    by = max(lo[k, 1] - p[1], 0.0, p[1] - hi[k, 1])
    bz = max(lo[k, 2] - p[2], 0.0, p[2] - hi[k, 2])
    return max(sphere, np.sqrt(bx * bx + by * by + bz * bz))


@njit(cache=True, nogil=True)
def _feature_side(p, s, f, feature, x, y, z):
    """+1.0 where p lies outside the surface at its closest point (x, y, z) on face f's `feature`,
    -1.0 inside (on it included): the sign of (p - closest) against that feature's pseudonormal."""
    if feature == 0:
        n = s.face_normals[f]
    elif feature <= 3:
        n = s.vertex_normals[s.faces[f, feature - 1]]
    else:
        n = s.edge_normals[s.face_edges[f, feature - 4]]
    if (p[0] - x) * n[0] + (p[1] - y) * n[1] + (p[2] - z) * n[2] > 0.0:
        return 1.0
    return -1.0


@njit(cache=True, nogil=True)
def signed_distances(points, s, cap):
    """For each of the points (n, 3): its signed distance to the surface of `s` (mm, negative
    inside; +inf where no point of the surface lies within `cap` mm) and the face holding its
    closest point (-1 beyond the cap): ((n,), (n,)). Nearest node first; a node whose gap
    (`node_gap`) is no less than the best distance found is skipped. One loop over the points
    (a call a point would pass the mesh's arrays, and count their references, each time)."""
    out = np.full(points.shape[0], np.inf)
    faces = np.full(points.shape[0], -1, np.int64)
    stack, gaps = np.empty(STACK, np.int64), np.empty(STACK)
    for n in range(points.shape[0]):
        p = points[n]
        best2 = cap * cap
        best_i, best_feat = -1, 0
        bx = by = bz = 0.0
        stack[0], gaps[0] = 0, node_gap(p, s, 0)  # a point beyond the cap of the whole mesh ends here
        top = 1
        while top > 0:
            top -= 1
            k, gap = stack[top], gaps[top]
            if gap > 0.0 and gap * gap >= best2:
                continue
            if s.left[k] < 0:
                for i in range(s.start[k], s.start[k] + s.count[k]):
                    feat, x, y, z = closest_on_triangle(p, s.triangles, i)
                    d2 = (p[0] - x) ** 2 + (p[1] - y) ** 2 + (p[2] - z) ** 2
                    if d2 < best2:
                        best2, best_i, best_feat = d2, i, feat
                        bx, by, bz = x, y, z
                continue
            l, r = s.left[k], s.right[k]
            gl, gr = node_gap(p, s, l), node_gap(p, s, r)
            if gl < gr:  # nearer child popped first
                l, r, gl, gr = r, l, gr, gl
            stack[top], stack[top + 1] = l, r
            gaps[top], gaps[top + 1] = gl, gr
            top += 2
        if best_i >= 0:
            faces[n] = s.order[best_i]
            out[n] = _feature_side(p, s, faces[n], best_feat, bx, by, bz) * np.sqrt(best2)
    return out, faces


@njit(cache=True, nogil=True)
def closest_face(p, s, cap):
    """`signed_distances` of the one point p (3,): (signed distance mm, face)."""
    d, f = signed_distances(p.reshape(1, 3), s, cap)
    return d[0], f[0]


@njit(cache=True, nogil=True)
def surface_within(p, rho, s):
    """Whether any point of the surface of `s` lies closer than rho (mm) to p (3,). Stops at the
    first found: far cheaper than the closest point for a point deep inside, where every face is
    about as far."""
    stack = np.empty(STACK, np.int64)
    stack[0] = 0
    top = 1
    rho2 = rho * rho
    while top > 0:
        top -= 1
        k = stack[top]
        if node_gap(p, s, k) >= rho:
            continue
        if s.left[k] < 0:
            for i in range(s.start[k], s.start[k] + s.count[k]):
                _, x, y, z = closest_on_triangle(p, s.triangles, i)
                if (p[0] - x) ** 2 + (p[1] - y) ** 2 + (p[2] - z) ** 2 < rho2:
                    return True
            continue
        stack[top], stack[top + 1] = s.left[k], s.right[k]
        top += 2
    return False


# --------------------------------------------------------------------------------- the same in numpy

# Seconds a process spends on numpy queries before compiling the kernels pays: numba compiles this
# module's and `geometry.penetration`'s kernels in 24 s of CPU once per machine (measured on the
# demo at load 11-14: main's first run less its second), and a compiled query costs a small part of
# a numpy one, so once numpy has cost about what the compile would, compiling pays. The demo's 20
# steps spend a few seconds in numpy and never compile; a long run compiles once, for every later
# run too. Wall seconds (reading a thread's CPU clock costs more here than a query), so a loaded
# machine compiles sooner.
# The seconds count across runs too (`orthosim.storage.numpytally`): the demo spends about 1.5 s
# of numpy queries a run (quiet two-core machine, 2026-11-29), so about its 8th to 20th run
# compiles (sooner on a loaded machine), not none.
PAYS_AFTER_S = 30.0
_numpy_seconds = [0.0]
TALLY = "signed-distance-numpy-s"  # the counter of numpy seconds in the tally of earlier runs
_KERNEL_SOURCES = (__file__, str(Path(__file__).with_name("penetration.py")))
_preferred: list[bool] = []


def compiled_pays(*kernels) -> bool:
    """Whether the queries run compiled: once this process has compiled or loaded them, when the
    `kernels` they need are all in numba's cache for this source (loading them costs a
    fraction of a second), or once this process and the earlier runs of the tally
    (`orthosim.storage.numpytally`) have spent PAYS_AFTER_S on numpy queries. Both forms give
    the same numbers, so a run may switch at any point."""
    from orthosim.system.firstrun import in_numba_cache

    if _preferred or in_numba_cache(*kernels):
        return True
    return _numpy_seconds[0] + numpytally.carried(TALLY, *_KERNEL_SOURCES) > PAYS_AFTER_S


# Faces a mesh may have for its queries to run in numpy before compiling pays. The numpy forms replay
# branch and bound point by point in Python, so their cost grows with the mesh: on real teeth (about
# 40,000 faces) a real jaw's rest interpenetration took 213 s in numpy against 25 s compiled, cold
# (2026-11-29, quiet two-core machine, when each point searched every leaf in numpy). Above this
# many faces in a mesh a query compiles at once (once per machine); the parametric teeth (4,500 to
# 7,000 faces, the demo's) stay on numpy until it pays.
NUMPY_AT_MOST_FACES = 10_000


def compiled_pays_for(faces: int, *kernels) -> bool:
    """`compiled_pays`, or at once for a mesh of more than NUMPY_AT_MOST_FACES `faces`."""
    return faces > NUMPY_AT_MOST_FACES or compiled_pays(*kernels)


def _spent_numpy(started: float) -> None:
    """Count the numpy seconds since `started`, for this process and the tally of later runs."""
    seconds = time.perf_counter() - started
    _numpy_seconds[0] += seconds
    numpytally.spend(TALLY, seconds, *_KERNEL_SOURCES)


def prefer_compiled() -> None:
    """From now on this process runs the queries compiled, compiling them on first use: for the
    test suite's warm-up and the bench, which time the compiled queries as a warm machine runs them."""
    _preferred.append(True)


def closest_on_triangles_numpy(P, T):
    """`closest_on_triangle` of each point P[i] (n, 3) and triangle T[i] (n, 3, 3), in numpy: (feature
    (n,), x, y, z (n,) each). The same operations in the same order per element, so the same bits; a
    branch is taken where the compiled one takes it (the first region whose test holds)."""
    with np.errstate(all="ignore"):
        ax, ay, az = T[:, 0, 0], T[:, 0, 1], T[:, 0, 2]
        bx, by, bz = T[:, 1, 0], T[:, 1, 1], T[:, 1, 2]
        cx, cy, cz = T[:, 2, 0], T[:, 2, 1], T[:, 2, 2]
        abx, aby, abz = bx - ax, by - ay, bz - az
        acx, acy, acz = cx - ax, cy - ay, cz - az

        def along(x, y, z):
            px, py, pz = P[:, 0] - x, P[:, 1] - y, P[:, 2] - z
            return abx * px + aby * py + abz * pz, acx * px + acy * py + acz * pz

        d1, d2 = along(ax, ay, az)
        d3, d4 = along(bx, by, bz)
        d5, d6 = along(cx, cy, cz)
        vc = d1 * d4 - d3 * d2
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        tests = [(d1 <= 0.0) & (d2 <= 0.0), (d3 >= 0.0) & (d4 <= d3), (d6 >= 0.0) & (d5 <= d6),
                 (vc <= 0.0) & (d1 >= 0.0) & (d3 <= 0.0), (vb <= 0.0) & (d2 >= 0.0) & (d6 <= 0.0),
                 (va <= 0.0) & ((d4 - d3) >= 0.0) & ((d5 - d6) >= 0.0)]
        v_ab = d1 / (d1 - d3)
        w_ca = d2 / (d2 - d6)
        w_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        denom = 1.0 / (va + vb + vc)
        v, w = vb * denom, vc * denom
        feature = np.select(tests, [1, 2, 3, 4, 6, 5], 0)
        xyz = [np.select(tests, [a, b, c, a + v_ab * ab, a + w_ca * ac, b + w_bc * (c - b)], a + ab * v + ac * w)
               for a, b, c, ab, ac in ((ax, bx, cx, abx, acx), (ay, by, cy, aby, acy), (az, bz, cz, abz, acz))]
    return feature, xyz[0], xyz[1], xyz[2]


def squared_distances(P, x, y, z):
    """|P - (x, y, z)|^2 per row, summed as the kernels sum it (x, then y, then z)."""
    return (P[:, 0] - x) ** 2 + (P[:, 1] - y) ** 2 + (P[:, 2] - z) ** 2


def node_gaps_numpy(P, s, nodes):
    """`node_gap` of each point P (m, 3) to each of `nodes` (k,): (m, k) mm, the same bits."""
    c, lo, hi = s.node_center[nodes], s.node_lo[nodes], s.node_hi[nodes]
    d = [P[:, None, a] - c[None, :, a] for a in range(3)]
    sphere = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) - s.node_radius[nodes]
    b = [np.maximum(np.maximum(lo[None, :, a] - P[:, None, a], 0.0), P[:, None, a] - hi[None, :, a]) for a in range(3)]
    return np.maximum(sphere, np.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]))


def signed_distances_numpy(points, s, cap):
    """`signed_distances` before compiling, the same numbers: for each of the points (n, 3), its
    signed distance to the surface of `s` (mm, negative inside, +inf beyond `cap` mm) and the face
    holding its closest point (-1 beyond the cap). The kernel's descent replayed point by point in
    Python floats (`_descend`): it visits a few dozen nodes a point where a search of every leaf in
    numpy measured them all, and it meets equally near faces in the kernel's order by construction."""
    started = time.perf_counter()
    cap2 = float(cap) * float(cap)
    points = np.asarray(points, float).reshape(-1, 3).tolist()
    answers = [_signed_distance_plain(px, py, pz, s, cap2) for px, py, pz in points]
    out = np.array([d for d, _ in answers], float).reshape(-1)
    faces = np.array([f for _, f in answers], np.int64).reshape(-1)
    _spent_numpy(started)
    return out, faces


def build_hierarchy_numpy(FC, FR, corner_lo, corner_hi, leaf_faces):
    """`build_hierarchy` in numpy, the same arrays bit for bit. The tree's shape (each node's stretch
    of faces, its children, the kernel's depth-first numbering) depends on the number of faces
    alone; the faces' order is then settled a level at a time (sibling stretches are apart), each
    node's centre summed face by face as the kernel sums it, each split by the same stable sort."""
    start, end, level, left, right = _hierarchy_shape(FC.shape[0], leaf_faces)
    k = len(start)
    centers, radii = np.empty((k, 3)), np.empty(k)
    lo, hi = np.empty((k, 3)), np.empty((k, 3))
    order = np.arange(FC.shape[0])
    for depth in range(int(level.max()) + 1):
        nodes = np.flatnonzero(level == depth)
        s, size = start[nodes], end[nodes] - start[nodes]
        valid = np.arange(int(size.max()))[None, :] < size[:, None]  # (nodes, widest stretch)
        faces = order[np.minimum(s[:, None] + np.arange(valid.shape[1]), len(order) - 1)]
        fc = np.where(valid[..., None], FC[faces], 0.0)
        c = np.cumsum(np.concatenate([np.zeros((len(nodes), 1, 3)), fc], axis=1), axis=1)[np.arange(len(nodes)), size]
        c = c / size[:, None]
        reach = np.sqrt((fc[..., 0] - c[:, None, 0]) ** 2 + (fc[..., 1] - c[:, None, 1]) ** 2
                        + (fc[..., 2] - c[:, None, 2]) ** 2) + FR[faces]
        r = np.maximum(np.where(valid, reach, -np.inf).max(axis=1), 0.0)
        centers[nodes], radii[nodes] = c, r * (1 + 1e-12) + 1e-12
        lo[nodes] = np.where(valid[..., None], corner_lo[faces], np.inf).min(axis=1)
        hi[nodes] = np.where(valid[..., None], corner_hi[faces], -np.inf).max(axis=1)
        split = size > leaf_faces
        if np.any(split):
            spread = np.where(valid[..., None], fc, -np.inf).max(axis=1) - np.where(valid[..., None], fc, np.inf).min(axis=1)
            axis = np.argmax(spread[split], axis=1)
            rows = faces[split]
            key = np.where(valid[split], FC[rows, axis[:, None]], np.inf)
            ranked = np.take_along_axis(rows, np.argsort(key, axis=1, kind="stable"), axis=1)
            for i, node in enumerate(nodes[split]):
                order[start[node]:end[node]] = ranked[i, :end[node] - start[node]]
    return centers, radii, lo, hi, left, right, start, end - start, order


def _hierarchy_shape(n: int, leaf_faces: int):
    """The shape `build_hierarchy` gives n faces, in its numbering (depth first, left child first):
    each node's stretch [start, end) of the faces' order, its depth, its children (-1: a leaf)."""
    start, end, level, left, right = [], [], [], [], []
    todo = [(0, n, -1, 0, 0)]
    while todo:
        s, e, parent, side, depth = todo.pop()
        k = len(start)
        start.append(s)
        end.append(e)
        level.append(depth)
        left.append(-1)
        right.append(-1)
        if parent >= 0:
            (left if side == 0 else right)[parent] = k
        if e - s > leaf_faces:
            mid = (e - s) // 2
            todo.append((s + mid, e, k, 1, depth + 1))
            todo.append((s, s + mid, k, 0, depth + 1))
    return tuple(np.array(v, np.int64) for v in (start, end, level, left, right))


# One point at a time (the depth searches' branch and bound asks one point a step, and a batch's
# points each need only a few dozen of the hierarchy's nodes), numpy's call overhead outweighs its
# arithmetic: the kernel's own descent in plain Python floats (IEEE doubles, the same operations in
# the same order, so the same bits, and the same face on ties by construction).
# The descent reads a plain copy of the hierarchy (`_plain`: tuples of Python floats, made once a
# surface), not the arrays: an `ndarray.item` costs about what a node's whole gap does.


class _PlainSurface(NamedTuple):
    """The part of `SurfaceArrays` the one-point queries read, as Python lists: per node, its gap's
    ten floats (`nodes`: centre x, y, z, radius, box lo x, y, z, hi x, y, z) and its children
    (`kids`: (left, right), None for a leaf); per leaf, its rows of `triangles` (`leaf_rows`,
    filled on a leaf's first visit: (row, its 9 corner floats) each); the mesh's `vertices` and
    `faces` as lists."""

    nodes: list
    kids: list
    leaf_rows: list
    vertices: list
    faces: list


# What `_plain` copies: a moved or placed copy of a surface (`MeshSurface.moved`, the depth's
# `_replace(node_center=...)`) shares some of these arrays and not others, so all are checked.
_PLAIN_FIELDS = ("node_center", "node_radius", "node_lo", "node_hi", "left", "right", "start", "count", "triangles",
                 "vertices", "faces")
_PLAINS: dict[int, tuple] = {}  # id(node_center) -> (weak references to the _PLAIN_FIELDS arrays, their _PlainSurface)
_LAST_PLAIN: list = [(None, None)]  # (surface asked last, its _PlainSurface): a search asks one surface in a row


def _plain(s: SurfaceArrays) -> _PlainSurface:
    """The `_PlainSurface` of `s`, made on first use and kept while its arrays live (they are the
    model, never written: the copy stays exact). A different surface, or a copy of this one with
    other arrays, gets its own."""
    last = _LAST_PLAIN[0]  # read once: another thread may ask another surface meanwhile
    if last[0] is s:  # the very tuple, so the very arrays
        return last[1]
    plain = _plain_of_arrays(s)
    _LAST_PLAIN[0] = (s, plain)
    return plain


def _plain_of_arrays(s: SurfaceArrays) -> _PlainSurface:
    """`_plain`, looked up by the arrays themselves (a surface's tuple may be made anew per query)."""
    arrays = [getattr(s, name) for name in _PLAIN_FIELDS]
    entry = _PLAINS.get(id(s.node_center))
    if entry is not None and all(ref() is a for ref, a in zip(entry[0], arrays)):
        return entry[1]
    for key in [k for k, (refs, _) in _PLAINS.items() if any(ref() is None for ref in refs)]:
        _PLAINS.pop(key, None)
    nodes = list(zip(*s.node_center.T.tolist(), s.node_radius.tolist(), *s.node_lo.T.tolist(), *s.node_hi.T.tolist()))
    kids = [None if l < 0 else (l, r) for l, r in zip(s.left.tolist(), s.right.tolist())]
    plain = _PlainSurface(nodes, kids, [None] * len(nodes), s.vertices.tolist(), s.faces.tolist())
    _PLAINS[id(s.node_center)] = ([weakref.ref(a) for a in arrays], plain)
    return plain


def _leaf_rows(s: SurfaceArrays, plain: _PlainSurface, k: int) -> list:
    """Leaf k's rows of `triangles` with their corners, [(row, 9 floats: a, b, c)], in row order."""
    rows = plain.leaf_rows[k]
    if rows is None:
        first, count = s.start.item(k), s.count.item(k)
        rows = plain.leaf_rows[k] = list(enumerate(s.triangles[first:first + count].reshape(-1, 9).tolist(), first))
    return rows


def closest_on_triangle_scalar(px, py, pz, t):
    """`closest_on_triangle` of the point (px, py, pz) and the corners t (9 floats: a, b, c), in
    Python floats: (feature, x, y, z)."""
    ax, ay, az, bx, by, bz, cx, cy, cz = t
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    qx, qy, qz = px - ax, py - ay, pz - az
    d1, d2 = abx * qx + aby * qy + abz * qz, acx * qx + acy * qy + acz * qz
    if d1 <= 0.0 and d2 <= 0.0:
        return 1, ax, ay, az
    qx, qy, qz = px - bx, py - by, pz - bz
    d3, d4 = abx * qx + aby * qy + abz * qz, acx * qx + acy * qy + acz * qz
    if d3 >= 0.0 and d4 <= d3:
        return 2, bx, by, bz
    qx, qy, qz = px - cx, py - cy, pz - cz
    d5, d6 = abx * qx + aby * qy + abz * qz, acx * qx + acy * qy + acz * qz
    if d6 >= 0.0 and d5 <= d6:
        return 3, cx, cy, cz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return 4, ax + v * abx, ay + v * aby, az + v * abz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return 6, ax + w * acx, ay + w * acy, az + w * acz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 5, bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return 0, ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w


def _node_gap_plain(px, py, pz, node):
    """`node_gap` in Python floats, of a `_PlainSurface.nodes` entry. The kernel's max(a, 0.0, b) is
    written out as Python's max evaluates it (the first of the largest; `>` only), and so is the
    outer max: the same value, without a builtin call."""
    cx, cy, cz, radius, lx, ly, lz, hx, hy, hz = node
    dx, dy, dz = px - cx, py - cy, pz - cz
    sphere = math.sqrt(dx * dx + dy * dy + dz * dz) - radius
    bx = lx - px
    if 0.0 > bx:
        bx = 0.0
    if px - hx > bx:
        bx = px - hx
    by = ly - py
    if 0.0 > by:
        by = 0.0
    if py - hy > by:
        by = py - hy
    bz = lz - pz
    if 0.0 > bz:
        bz = 0.0
    if pz - hz > bz:
        bz = pz - hz
    box = math.sqrt(bx * bx + by * by + bz * bz)
    return box if box > sphere else sphere


def _descend(px, py, pz, s, best2):
    """The kernel's descent (`signed_distances`, one point) in Python floats: (squared distance, row
    of `triangles`, feature, closest point x, y, z) of the nearest face closer than sqrt(best2);
    row -1 where none is. The nearer child is taken at once and the farther one kept for later,
    unless its gap already rules it out: best2 only shrinks, so the kernel's stack would drop it
    when popped. The nodes met, and their order, are the kernel's."""
    plain = _plain(s)
    nodes, kids, leaf_rows = plain.nodes, plain.kids, plain.leaf_rows
    best_i, best_feat, bx, by, bz = -1, 0, 0.0, 0.0, 0.0
    waiting = []
    k, gap = 0, _node_gap_plain(px, py, pz, nodes[0])
    while True:
        if not (gap > 0.0 and gap * gap >= best2):
            pair = kids[k]
            if pair is not None:
                l, r = pair
                gl, gr = _node_gap_plain(px, py, pz, nodes[l]), _node_gap_plain(px, py, pz, nodes[r])
                if gl < gr:  # the nearer child first (the right one on a tie)
                    k, gap, l, gl = l, gl, r, gr
                else:
                    k, gap = r, gr
                if not (gl > 0.0 and gl * gl >= best2):
                    waiting.append((l, gl))
                continue
            rows = leaf_rows[k]
            if rows is None:
                rows = _leaf_rows(s, plain, k)
            for i, t in rows:
                feat, x, y, z = closest_on_triangle_scalar(px, py, pz, t)
                d2 = (px - x) * (px - x) + (py - y) * (py - y) + (pz - z) * (pz - z)
                if d2 < best2:
                    best2, best_i, best_feat, bx, by, bz = d2, i, feat, x, y, z
        if not waiting:
            return best2, best_i, best_feat, bx, by, bz
        k, gap = waiting.pop()


def _signed_distance_plain(px, py, pz, s, cap2):
    """`closest_face` of the point (px, py, pz) in Python floats, no farther than sqrt(cap2) mm:
    (signed distance mm, face); (+inf, -1) where no face is that near."""
    best2, best_i, best_feat, bx, by, bz = _descend(px, py, pz, s, cap2)
    if best_i < 0:
        return math.inf, -1
    f = s.order.item(best_i)
    if best_feat == 0:
        n, k = s.face_normals, f
    elif best_feat <= 3:
        n, k = s.vertex_normals, s.faces.item(f, best_feat - 1)
    else:
        n, k = s.edge_normals, s.face_edges.item(f, best_feat - 4)
    outside = (px - bx) * n.item(k, 0) + (py - by) * n.item(k, 1) + (pz - bz) * n.item(k, 2) > 0.0
    return (1.0 if outside else -1.0) * math.sqrt(best2), f


def signed_distance_scalar(p, s, cap):
    """`closest_face` of the one point p (3 floats) in Python floats: (signed distance mm, face)."""
    started = time.perf_counter()
    answer = _signed_distance_plain(float(p[0]), float(p[1]), float(p[2]), s, cap * cap)
    _spent_numpy(started)
    return answer


def distance_to_face_scalar(p, s, f) -> float:
    """`distance_to_face` in Python floats: mm from p (3 floats) to face f of `s`."""
    px, py, pz = float(p[0]), float(p[1]), float(p[2])
    plain = _plain(s)
    a, b, c = plain.faces[f]
    vertices = plain.vertices
    _, x, y, z = closest_on_triangle_scalar(px, py, pz, vertices[a] + vertices[b] + vertices[c])
    return math.sqrt((px - x) * (px - x) + (py - y) * (py - y) + (pz - z) * (pz - z))

"""The inter-arch distance map: how far every crown vertex lies from the opposing arch, exactly.

What clinicians know as an occlusal map: each crown vertex of one arch gets its signed distance
(mm) to the surface of the opposing arch's tooth meshes (not their sphere trees), negative where
the vertex lies inside an opposing tooth (interpenetration), and a class for the colour bar:
penetration (< 0), contact (< CONTACT_MM), near (up to NEAR_MM), far. The same query against a
tooth's neighbours in its own arch gives the contact areas of the paper's Figure 7.

Exactness: a distance is the minimum over triangles of the exact point-triangle distance, computed
in float64. Each tooth's triangles sit in a bounding-box tree in its local frame (built once, the
model); a query descends it nearest box first and skips every box farther than the best distance
found so far, which a box's distance bounds from below, so no closer triangle is ever skipped. The sign comes from the angle-weighted pseudonormal of the
closest feature (face, edge or vertex), which is exact for closed, consistently oriented meshes.
Distances beyond `cap_mm` are not resolved: they are reported as +inf ("far"), which is what keeps
a whole arch's map to a fraction of a second.

Written by hand (compiled with numba) because trimesh's closest-point query gathers candidates
in Python and FCL answers one object pair per call: for the 40,000 crown vertices of a dentition
both take seconds, this a fraction of one (see the report bench, `report_s`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping

import numpy as np

from orthosim.model.dentition import Dentition
from orthosim.model.fdi import Arch, arch_of

CONTACT_MM = 0.1  # closer than this (and not penetrating) counts as contact
NEAR_MM = 2.0  # up to this is "near"; beyond it "far"
CAP_MM = 5.0  # distances beyond this are not resolved (reported as +inf)

PENETRATION, CONTACT, NEAR, FAR = 0, 1, 2, 3
CLASS_NAMES = ("penetration", "contact", "near", "far")

try:  # numba is a dependency; the numpy fallback keeps the module importable without a compiler
    from numba import njit
except ImportError:  # pragma: no cover
    def njit(*args, **kwargs):
        return (lambda f: f) if not (len(args) == 1 and callable(args[0])) else args[0]


@njit(cache=True, inline="always")
def _closest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):  # pragma: no cover (compiled)
    """Closest point on triangle abc to p by Voronoi regions (the standard construction, Ericson
    2005, section 5.1.5). Returns (distance mm, region, dx, dy, dz) with d = p - closest and
    region 0 = face, 1..3 = edges ab, bc, ca, 4..6 = vertices a, b, c."""
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    region = 0
    u = 0.0  # closest = a + u*ab + v*ac
    v = 0.0
    if d1 <= 0.0 and d2 <= 0.0:
        region = 4
    else:
        bpx, bpy, bpz = px - bx, py - by, pz - bz
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        if d3 >= 0.0 and d4 <= d3:
            region = 5
            u = 1.0
        else:
            vc = d1 * d4 - d3 * d2
            if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
                region = 1
                u = d1 / (d1 - d3)
            else:
                cpx, cpy, cpz = px - cx, py - cy, pz - cz
                d5 = abx * cpx + aby * cpy + abz * cpz
                d6 = acx * cpx + acy * cpy + acz * cpz
                if d6 >= 0.0 and d5 <= d6:
                    region = 6
                    v = 1.0
                else:
                    vb = d5 * d2 - d1 * d6
                    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
                        region = 3
                        v = d2 / (d2 - d6)
                    else:
                        va = d3 * d6 - d5 * d4
                        if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
                            region = 2
                            w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                            u = 1.0 - w
                            v = w
                        else:
                            denom = 1.0 / (va + vb + vc)
                            u = vb * denom
                            v = vc * denom
    dx = px - (ax + u * abx + v * acx)
    dy = py - (ay + u * aby + v * acy)
    dz = pz - (az + u * abz + v * acz)
    return np.sqrt(dx * dx + dy * dy + dz * dz), region, dx, dy, dz


@njit(cache=True)
def _build_bvh(centroids, tri_lo, tri_hi, leaf_size):  # pragma: no cover (compiled)
    """A binary AABB tree over triangles: median split of the centroids along the widest axis.
    Returns (order, node_lo, node_hi, left, right, start, count); leaves have left == -1 and hold
    triangles order[start:start + count]."""
    m = len(centroids)
    order = np.arange(m)
    cap = 2 * m + 1
    node_lo = np.empty((cap, 3))
    node_hi = np.empty((cap, 3))
    left = np.full(cap, -1, np.int64)
    right = np.full(cap, -1, np.int64)
    start = np.zeros(cap, np.int64)
    count = np.zeros(cap, np.int64)
    n_nodes = 1
    start[0], count[0] = 0, m
    stack = [0]
    while len(stack):
        node = stack.pop()
        s, k = start[node], count[node]
        idx = order[s:s + k]
        for d in range(3):
            node_lo[node, d] = tri_lo[idx, d].min()
            node_hi[node, d] = tri_hi[idx, d].max()
        if k <= leaf_size:
            continue
        cl = centroids[idx]
        spread = np.empty(3)
        for d in range(3):
            spread[d] = cl[:, d].max() - cl[:, d].min()
        axis = np.argmax(spread)
        order[s:s + k] = idx[np.argsort(cl[:, axis])]
        half = k // 2
        l, r = n_nodes, n_nodes + 1
        n_nodes += 2
        start[l], count[l] = s, half
        start[r], count[r] = s + half, k - half
        left[node], right[node] = l, r
        stack.append(l)
        stack.append(r)
    return order, node_lo[:n_nodes], node_hi[:n_nodes], left[:n_nodes], right[:n_nodes], start[:n_nodes], count[:n_nodes]


@njit(cache=True, inline="always")
def _box_distance(px, py, pz, lo, hi, node):  # pragma: no cover (compiled)
    dx = max(lo[node, 0] - px, 0.0, px - hi[node, 0])
    dy = max(lo[node, 1] - py, 0.0, py - hi[node, 1])
    dz = max(lo[node, 2] - pz, 0.0, pz - hi[node, 2])
    return np.sqrt(dx * dx + dy * dy + dz * dz)


@njit(cache=True)
def _signed_distances(points, cap, order, lo, hi, left, right, start, count, a, b, c, face_n, edge_n, vert_n):  # pragma: no cover
    """For each point, the signed distance (mm; +inf beyond `cap`) to the closest triangle and its index.

    Nearest-first descent of the AABB tree, pruning every box farther than the best distance so
    far (initially the cap): exact, since a box's distance bounds its triangles' from below. The
    sign is that of (p - closest) against the closest feature's pseudonormal."""
    n = len(points)
    out = np.full(n, np.inf)
    best_face = np.full(n, -1, np.int64)
    stack = np.empty(128, np.int64)
    for i in range(n):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best = cap
        sign = 1.0
        found = -1
        top = 0
        if _box_distance(px, py, pz, lo, hi, 0) <= best:
            stack[0] = 0
            top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            if _box_distance(px, py, pz, lo, hi, node) > best:
                continue
            if left[node] < 0:
                for j in range(start[node], start[node] + count[node]):
                    t = order[j]
                    dist, region, dx, dy, dz = _closest_on_triangle(
                        px, py, pz, a[t, 0], a[t, 1], a[t, 2], b[t, 0], b[t, 1], b[t, 2], c[t, 0], c[t, 1], c[t, 2])
                    if dist <= best:
                        if region == 0:
                            nx, ny, nz = face_n[t, 0], face_n[t, 1], face_n[t, 2]
                        elif region <= 3:
                            nx, ny, nz = edge_n[t, region - 1, 0], edge_n[t, region - 1, 1], edge_n[t, region - 1, 2]
                        else:
                            nx, ny, nz = vert_n[t, region - 4, 0], vert_n[t, region - 4, 1], vert_n[t, region - 4, 2]
                        best = dist
                        sign = -1.0 if dx * nx + dy * ny + dz * nz < 0.0 else 1.0
                        found = t
                continue
            l, r = left[node], right[node]
            dl = _box_distance(px, py, pz, lo, hi, l)
            dr = _box_distance(px, py, pz, lo, hi, r)
            if dl > dr:  # push the farther child first so the nearer is searched first
                l, r = r, l
                dl, dr = dr, dl
            if dr <= best:
                stack[top] = r
                top += 1
            if dl <= best:
                stack[top] = l
                top += 1
        if found >= 0:
            out[i] = best * sign
            best_face[i] = found
    return out, best_face


LEAF_TRIANGLES = 8


@dataclass(frozen=True, eq=False)
class SurfaceIndex:
    """One closed mesh prepared for exact signed point distances (model: built once, local frame, mm)."""

    a: np.ndarray  # (m, 3) first corner of each triangle
    b: np.ndarray  # (m, 3)
    c: np.ndarray  # (m, 3)
    face_normals: np.ndarray  # (m, 3) unit
    edge_normals: np.ndarray  # (m, 3, 3) pseudonormal of edges ab, bc, ca
    vertex_normals: np.ndarray  # (m, 3, 3) angle-weighted pseudonormal at corners a, b, c
    bvh: tuple  # (order, node_lo, node_hi, left, right, start, count), see _build_bvh
    center: np.ndarray  # (3,) bounding sphere of the vertices
    radius_mm: float

    @classmethod
    def of(cls, mesh) -> "SurfaceIndex":
        """From a trimesh.Trimesh (closed, outward normals)."""
        V = np.asarray(mesh.vertices, float)
        F = np.asarray(mesh.faces, np.int64)
        tri = V[F]
        fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
        # angle-weighted vertex pseudonormals (Baerentzen and Aanaes 2005)
        angles = np.asarray(mesh.face_angles, float)
        vn = np.zeros_like(V)
        for corner in range(3):
            np.add.at(vn, F[:, corner], fn * angles[:, corner:corner + 1])
        vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
        # edge pseudonormals: the sum of the normals of the faces sharing the edge
        edges = np.stack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1)  # (m, 3, 2)
        key = edges.min(axis=2).reshape(-1) * len(V) + edges.max(axis=2).reshape(-1)
        uniq, inverse = np.unique(key, return_inverse=True)
        inverse = inverse.reshape(-1)
        esum = np.zeros((len(uniq), 3))
        np.add.at(esum, inverse, np.repeat(fn, 3, axis=0))
        en = esum[inverse].reshape(-1, 3, 3)
        en /= np.maximum(np.linalg.norm(en, axis=2, keepdims=True), 1e-300)
        bvh = _build_bvh(tri.mean(axis=1), tri.min(axis=1), tri.max(axis=1), LEAF_TRIANGLES)
        lo, hi = V.min(axis=0), V.max(axis=0)
        center = (lo + hi) / 2
        return cls(np.ascontiguousarray(tri[:, 0]), np.ascontiguousarray(tri[:, 1]), np.ascontiguousarray(tri[:, 2]),
                   fn, np.ascontiguousarray(en), np.ascontiguousarray(vn[F]), bvh,
                   center, float(np.linalg.norm(V - center, axis=1).max()))

    @property
    def n_faces(self) -> int:
        return len(self.a)

    def signed_distance(self, points: np.ndarray, cap_mm: float = CAP_MM) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) local-frame points (mm) -> ((n,) signed distance mm, negative inside, +inf beyond
        `cap_mm`; (n,) closest triangle index, -1 where beyond the cap)."""
        p = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
        return _signed_distances(p, float(cap_mm), *self.bvh, self.a, self.b, self.c, self.face_normals,
                                 self.edge_normals, self.vertex_normals)


@dataclass(frozen=True)
class ToothDistances:
    """One tooth's crown vertices (in `Tooth.crown_vertices` order) and their signed distances (mm)."""

    fdi: int
    distance_mm: np.ndarray  # (k,) signed, negative = inside another tooth, +inf = beyond CAP_MM
    nearest: np.ndarray  # (k,) FDI of the tooth that distance is to (0 where beyond the cap)

    @property
    def classes(self) -> np.ndarray:
        return classify(self.distance_mm)


def classify(distance_mm: np.ndarray) -> np.ndarray:
    """(n,) signed distances (mm) -> (n,) int8 classes PENETRATION, CONTACT, NEAR, FAR."""
    d = np.asarray(distance_mm, float)
    return np.select([d < 0.0, d < CONTACT_MM, d <= NEAR_MM], [PENETRATION, CONTACT, NEAR], FAR).astype(np.int8)


class DistanceMapModel:
    """The model side of distance maps: each tooth's surface index and crown vertices, built once.

        maps = DistanceMapModel(dentition)
        before = maps.inter_arch(rest_poses, absent=extracted)  # FDI -> ToothDistances
    """

    def __init__(self, dentition: Dentition):
        self.dentition = dentition
        self.surfaces = {n: SurfaceIndex.of(t.mesh) for n, t in dentition.teeth.items()}

    def distances(self, poses: Mapping[int, np.ndarray], fdi: int, others: Iterable[int],
                  cap_mm: float = CAP_MM) -> ToothDistances:
        """Signed distances (mm) of `fdi`'s crown vertices, posed, to the union of `others`' meshes, posed."""
        tooth = self.dentition.teeth[fdi]
        world = tooth.to_world(tooth.crown_vertices, poses[fdi])
        best = np.full(len(world), np.inf)
        nearest = np.zeros(len(world), np.int64)
        lo, hi = world.min(axis=0), world.max(axis=0)
        center, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2
        for other in others:
            s = self.surfaces[other]
            T = np.asarray(poses[other], float)
            if np.linalg.norm(T[:3, :3] @ s.center + T[:3, 3] - center) > radius + s.radius_mm + cap_mm:
                continue  # no crown vertex can come within the cap of this tooth
            local = (world - T[:3, 3]) @ T[:3, :3]
            d, _ = s.signed_distance(local, cap_mm)
            better = d < best
            best[better], nearest[better] = d[better], other
        return ToothDistances(fdi, best, nearest)

    def inter_arch(self, poses: Mapping[int, np.ndarray], absent: Iterable[int] = (),
                   cap_mm: float = CAP_MM) -> dict[int, ToothDistances]:
        """FDI -> distances of its crown vertices to the opposing arch (teeth in `absent` left out)."""
        absent = set(absent)
        present = [n for n in self.dentition.fdis if n not in absent]
        return {n: self.distances(poses, n, [m for m in present if arch_of(m) != arch_of(n)], cap_mm) for n in present}

    def contacts(self, poses: Mapping[int, np.ndarray], absent: Iterable[int] = (),
                 cap_mm: float = NEAR_MM) -> dict[int, ToothDistances]:
        """FDI -> distances of its crown vertices to every other present tooth: the opposing arch and
        its neighbours in its own arch (the contact areas of the paper's Figure 7)."""
        absent = set(absent)
        present = [n for n in self.dentition.fdis if n not in absent]
        return {n: self.distances(poses, n, [m for m in present if m != n], cap_mm) for n in present}


def summarize(maps: Mapping[int, ToothDistances]) -> dict:
    """Figures of one map, ready for JSON: vertices per class, the deepest penetration and the
    closest approach (mm), per arch and overall."""
    out = {}
    for label, arch in (("upper", Arch.UPPER), ("lower", Arch.LOWER), ("both", None)):
        ds = [m.distance_mm for n, m in maps.items() if arch is None or arch_of(n) is arch]
        d = np.concatenate(ds) if ds else np.zeros(0)
        cls = classify(d)
        out[label] = {
            "vertices": int(len(d)),
            **{name: int((cls == i).sum()) for i, name in enumerate(CLASS_NAMES)},
            "min_distance_mm": float(d.min()) if len(d) and np.isfinite(d.min()) else None,
        }
    return out

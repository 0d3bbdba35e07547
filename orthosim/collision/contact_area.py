"""Contact areas on the exact meshes: the triangles of one tooth that touch another, not the spheres.

A discrete sphere-tree query says which leaf spheres of two teeth overlap; a picture that paints
everything inside those spheres also paints surface that is a leaf sphere's thickness away from
the other tooth. Here the candidate triangles (those inside the overlapping leaves) are kept only
when the exact triangle-to-triangle distance to the other tooth's surface is at most the touch
tolerance, or when the triangle's centroid lies inside the other tooth (teeth pushed into each
other: the deepest part of an overlap is farther than the tolerance from the other surface yet
plainly in contact).

The triangle distance is written here (vectorised numpy, and compiled with an early stop per
triangle in `trianglepairs`, which the faces are found with) because FCL answers one closest pair
per query, not a distance per triangle. Distances in mm; poses (4, 4) local -> arch frame.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from orthosim.collision import crossings_compiled
from orthosim.collision.trianglepairs import faces_within
from orthosim.spheretree.inside import CrossingIndex

TOUCH_TOLERANCE_MM = 0.05  # as near as the model's neighbours are placed to touch (see the README)


def _segment_distances(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """(n,) distances between segments p1-q1 and p2-q2, each (n, 3) mm (clamped closest points)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    denom = a * e - b * b
    tiny = 1e-300
    s = np.where(denom > 1e-12 * np.maximum(a * e, tiny), np.clip((b * f - c * e) / np.maximum(denom, tiny), 0, 1), 0.0)
    t = (b * s + f) / np.maximum(e, tiny)
    # t outside [0, 1]: clamp it and recompute s for the clamped t
    s = np.where(t < 0, np.clip(-c / np.maximum(a, tiny), 0, 1), np.where(t > 1, np.clip((b - c) / np.maximum(a, tiny), 0, 1), s))
    t = np.clip(t, 0, 1)
    gap = (p1 + s[:, None] * d1) - (p2 + t[:, None] * d2)
    return np.sqrt(np.einsum("ij,ij->i", gap, gap))


def _edges_cross(tri: np.ndarray, other: np.ndarray) -> np.ndarray:
    """(n,) whether an edge of each triangle of `tri` passes through the paired triangle of `other`."""
    v0, e1, e2 = other[:, 0], other[:, 1] - other[:, 0], other[:, 2] - other[:, 0]
    hit = np.zeros(len(tri), bool)
    for i in range(3):
        p, d = tri[:, i], tri[:, (i + 1) % 3] - tri[:, i]
        h = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, h)
        ok = np.abs(det) > 1e-15
        inv = 1.0 / np.where(ok, det, 1.0)
        s = p - v0
        u = np.einsum("ij,ij->i", s, h) * inv
        q = np.cross(s, e1)
        v = np.einsum("ij,ij->i", d, q) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        hit |= ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= 1)
    return hit


def triangle_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact distances between paired triangles a[i], b[i] ((n, 3, 3) mm): 0 where they intersect.

    Two disjoint triangles are nearest at a vertex of one against the other or between two edges;
    intersecting ones have an edge of one through the other.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    n = len(a)
    if n == 0:
        return np.zeros(0)
    best = np.full(n, np.inf)
    for tri, other in ((a, b), (b, a)):
        for i in range(3):
            near = trimesh.triangles.closest_point(other, tri[:, i])
            best = np.minimum(best, np.linalg.norm(near - tri[:, i], axis=1))
    for i in range(3):
        for j in range(3):
            best = np.minimum(best, _segment_distances(a[:, i], a[:, (i + 1) % 3], b[:, j], b[:, (j + 1) % 3]))
    best[_edges_cross(a, b) | _edges_cross(b, a)] = 0.0
    return best


def _pairs_within(points: np.ndarray, tree: cKDTree, reach_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """(index into `points` (n, 3), index into `tree`'s points) of every pair within `reach_mm`, as arrays."""
    if not len(points):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    found = cKDTree(points).sparse_distance_matrix(tree, reach_mm, output_type="ndarray")
    return found["i"].astype(np.int64), found["j"].astype(np.int64)


class ContactSurface:
    """One tooth's mesh prepared for contact-area queries (built once per tooth, mm, local frame)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices = np.asarray(vertices, float)
        self.faces = np.asarray(faces, np.int64)
        tri = self.vertices[self.faces]
        self.triangles = np.ascontiguousarray(tri)
        self.centroids = tri.mean(axis=1)
        self.circumradius = np.linalg.norm(tri - self.centroids[:, None, :], axis=2).max(axis=1)  # about the centroid
        self.kdtree = cKDTree(self.centroids)
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(cross, axis=1)
        self.normals = np.where(length[:, None] > 0, cross / np.where(length > 0, length, 1.0)[:, None], 0.0)  # unit, or 0
        self.low, self.high = self.vertices.min(axis=0), self.vertices.max(axis=0)  # box of the mesh, mm
        self.center = self.vertices.mean(axis=0)  # a sphere (center, radius mm) holding every vertex
        self.radius = float(np.linalg.norm(self.vertices - self.center, axis=1).max())
        self._crossings: CrossingIndex | None = None

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(p, 3) points in this mesh's frame, mm -> (p,) bool: inside the closed mesh. By ray crossings
        (`CrossingIndex`, built on first use, a tenth of a second): a frame asks a few thousand points,
        too few to pay for `Solid`'s voxel grid (seconds a crown). Counted in compiled code
        (`crossings_compiled`: `CrossingIndex.contains_exact`'s answers, a tenth of its time)."""
        if self._crossings is None:
            self._crossings = CrossingIndex(self.vertices, self.faces)
        return crossings_compiled.contains(self._crossings, points)

    def faces_touching(self, candidates: np.ndarray, pose: np.ndarray, other: "ContactSurface", other_pose: np.ndarray,
                       tolerance_mm: float = TOUCH_TOLERANCE_MM) -> np.ndarray:
        """The candidate faces (indices into this mesh) within `tolerance_mm` of `other`'s surface or
        inside it, at the given poses: sorted (k,) int64."""
        candidates = np.unique(np.asarray(candidates, np.int64))
        if not len(candidates):
            return candidates
        to_other = np.linalg.inv(np.asarray(other_pose, float)) @ np.asarray(pose, float)
        tri = self.vertices[self.faces[candidates]] @ to_other[:3, :3].T + to_other[:3, 3]
        centre = tri.mean(axis=1)
        mine, theirs = self._near_pairs(candidates, centre, other, tolerance_mm)
        order = np.argsort(mine, kind="stable")
        offsets = np.zeros(len(candidates) + 1, np.int64)
        np.cumsum(np.bincount(mine, minlength=len(candidates)), out=offsets[1:])
        keep = faces_within(tri, np.ascontiguousarray(self.normals[candidates] @ to_other[:3, :3].T), offsets,
                            theirs[order], other.triangles, other.normals, float(tolerance_mm))
        rest = np.flatnonzero(~keep)
        if len(rest):
            keep[rest[other.contains(centre[rest])]] = True
        return candidates[keep]

    def _near_pairs(self, candidates: np.ndarray, centre: np.ndarray, other: "ContactSurface",
                    tolerance_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """(index into candidates, face of `other`) of every pair of triangles that may lie within
        `tolerance_mm` of each other: centroids (`centre`, in `other`'s frame) no farther apart than
        both circumradii and the tolerance, as every point of a triangle lies within its circumradius
        of its centroid. The pairs left out cannot touch, so the kept faces are those of every pair."""
        radius = self.circumradius[candidates]
        # a triangle within the tolerance of `other` has its centroid near `other`'s box (its frame)
        margin = (radius + tolerance_mm + 1e-9)[:, None]
        boxed = np.flatnonzero(np.all((centre >= other.low - margin) & (centre <= other.high + margin), axis=1))
        if not len(boxed):
            return boxed, boxed
        mine, theirs = self._pairs_near(boxed, radius, centre, other, tolerance_mm)
        return boxed[mine], theirs

    @staticmethod
    def _pairs_near(boxed: np.ndarray, radius: np.ndarray, centre: np.ndarray, other: "ContactSurface",
                    tolerance_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """`_near_pairs` for the candidates `boxed` (indices into `radius` (mm) and `centre`): (index
        into boxed, face of other)."""
        radius, centre = radius[boxed], centre[boxed]
        reach = radius.max() + other.circumradius.max() + tolerance_mm + 1e-9  # 1e-9 mm: rounding
        mine, theirs = _pairs_within(centre, other.kdtree, reach)
        gap = centre[mine] - other.centroids[theirs]
        reach = radius[mine] + other.circumradius[theirs] + tolerance_mm + 1e-9
        near = np.einsum("ij,ij->i", gap, gap) <= reach * reach
        return mine[near], theirs[near]


def faces_touching_any(surface: ContactSurface, pose: np.ndarray, candidates: np.ndarray,
                       others, tolerance_mm: float = TOUCH_TOLERANCE_MM) -> np.ndarray:
    """The candidate faces that touch any of `others` ((ContactSurface, pose) pairs): sorted indices."""
    found = [surface.faces_touching(candidates, pose, other, other_pose, tolerance_mm) for other, other_pose in others]
    return np.unique(np.concatenate(found)) if found else np.zeros(0, np.int64)


def faces_in_spheres(surface: ContactSurface, pose: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Faces (sorted indices) with all three vertices inside one of the spheres (arch frame, mm): the
    triangles an overlapping leaf sphere holds, as a tree's leaf holds whole triangles."""
    pose = np.asarray(pose, float)
    # a step lists a leaf sphere once per leaf of the other tooth it overlaps: each sphere asked once
    spheres = np.unique(np.column_stack([np.asarray(centers, float).reshape(-1, 3), np.asarray(radii, float).reshape(-1)]), axis=0)
    local = (spheres[:, :3] - pose[:3, 3]) @ pose[:3, :3]
    radii = spheres[:, 3]
    reach = radii + surface.radius + 1e-6  # a sphere that holds a face reaches the sphere holding the mesh
    gap = local - surface.center
    near = np.einsum("ij,ij->i", gap, gap) <= reach * reach
    local, radii = local[near], radii[near]
    if not len(radii):
        return np.zeros(0, np.int64)
    lists = surface.kdtree.query_ball_point(local, radii)  # a face inside holds its centroid too
    counts = np.fromiter((len(x) for x in lists), np.int64, len(lists))
    if not counts.sum():
        return np.zeros(0, np.int64)
    sphere = np.repeat(np.arange(len(radii)), counts)
    face = np.concatenate([np.asarray(x, np.int64) for x in lists if len(x)])
    far = np.linalg.norm(surface.vertices[surface.faces[face]] - local[sphere][:, None, :], axis=2).max(axis=1)
    return np.unique(face[far <= radii[sphere] + 1e-6])  # 1e-6 mm: rounding of the poses

"""The optimising sphere-tree builder: few, large, deep-set leaf spheres with little volume outside.

A leaf covers a patch of the tooth surface. Any sphere holding a patch's vertices holds the patch
(exact coverage), and among those the best one has its centre sunk inward: a bigger sphere centred
deeper leaves a thinner cap outside the surface (cap volume ~ pi rho^4 / (4 R) for a patch of
radius rho), until it bulges out elsewhere. Where the tooth is thin (roots), one sphere on the
medial axis holds both sides at once. So:

1. Leaves first: k-means of all triangles into branching**(depth-1) patches, on the centroids
   pulled toward the medial axis (x - pull * rho(x) * n(x), rho the
   radius of the largest inside ball touching x), so the two sides of a thin root fall together.
2. Fit each leaf: candidate centres along the patch's inward normal, then a pattern search in 3D;
   the radius is always the distance to the farthest patch vertex, and the score is the number of
   voxels of an outside-the-tooth band that fall in the sphere (its outside volume), plus the gap
   between the sphere and its own patch, sum of vertex area x (radius - distance): on fine meshes
   a good leaf's cap is thinner than a voxel, and the voxels alone cannot tell a thin cap from a
   thick one that happens to miss their centres.
3. Improve, a few rounds: leaves emptied earlier refill by splitting the worst leaves in two;
   leaves move to where they pay (the dearest leaves split in two, paid for by merging neighbours
   that cost little together, while a split gains more than a merge costs);
   each triangle moves to the leaf that holds it most deeply (only into a sphere that already
   holds it, so the sphere it leaves can shrink); the triangles that set a leaf's radius are
   handed to a neighbour that grows to take them when that lowers the outside volume; the
   spheres are searched again. Every radius is recomputed from its patch, so coverage stays exact.
   A thin tooth whose finished tree is still loose by this count is built again whole with a
   stronger pull (`FitOptions.thin_pulls`), and the tighter of the two trees kept.
4. Group the leaves top-down into nodes of at most `branching` children (k-means with capacity);
   each inner node is the near-minimal sphere around all vertices of its triangles, so it holds
   everything its children hold and a descent never loses a contact.

All coordinates in mm, in the mesh's frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from orthosim.spheretree.defaults import FIT_BRANCHING  # why 9: see that module
from orthosim.spheretree.enclose import enclosing_spheres, node_vertex_groups, radii_to_cover, radii_to_cover_each
from orthosim.spheretree.measure import mesh_volume
from orthosim.spheretree.outside_band import OutsideBand
from orthosim.spheretree.tree import SphereTree
from orthosim.system.firstrun import announce_compiles


@dataclass(frozen=True)
class FitOptions:
    """Knobs of the optimising builder (defaults tuned on the parametric and real teeth)."""

    medial_pulls: tuple[float, ...] = (0.7,)  # pulls tried by fit_leaves (the best first fit wins)
    # A thin tooth (median rho under thin_rho_mm) whose finished tree holds more than thin_retry_sov
    # of the tooth's volume outside, by the builder's count, is built again whole with thin_pulls
    # and the tighter tree kept (real lower incisors: 0.75 -> 0.61 on one, the others keep theirs).
    thin_pulls: tuple[float, ...] = (0.9,)
    thin_rho_mm: float = 1.2
    thin_retry_sov: float = 0.06
    medial_cap_mm: float = 4.0  # rho capped at this depth, mm
    medial_samples: int = 4000  # faces on which rho is estimated
    lloyd_iterations: int = 12
    reserve: float = 0.0  # share of the leaves first kept back, then spent on splitting the worst ones
    voxel_mm: float = 0.15  # spacing of the outside-band voxels that score spheres, mm, at most
    # Fine meshes get finer voxels: a leaf of small triangles has a small patch whose cap outside the
    # tooth is thinner than 0.15 mm, which coarse voxels see only as a few centres (on the real teeth,
    # 0.18 mm edges, 0.10 mm voxels took the summed SOV from 0.065 to 0.060 at the same build time;
    # on the parametric teeth, 1 mm edges, they bought nothing and cost 2.6 times the time).
    voxel_per_edge: float = 0.6  # spacing = this x the median edge length, within [min_voxel_mm, voxel_mm]
    min_voxel_mm: float = 0.10
    max_voxels: int = 8_000_000  # the spacing grows on huge meshes to keep the grid this small
    band_mm: float = 0.75  # thickness of the outside band that scores spheres, mm
    fine_band_mm: float = 0.3  # inner part of the band sampled at full resolution, mm
    depths: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0)  # x patch radius
    search_rounds: int = 8
    reassign_rounds: int = 3
    handoff_rounds: int = 4  # per improve round: hand radius-setting triangles to growing neighbours
    reassign_candidates: int = 24  # leaves (nearest centres) a face may move to
    relative_depth: bool = True  # reassignment compares depth / radius (True) or depth in mm
    refit_rounds: int = 8  # pattern-search rounds after each reassignment
    rebalance_share: float = 0.125  # per improve round: at most this share of the leaves merged and split
    rebalance_merge_rounds: int = 0  # pattern-search rounds when pricing a merge (more bought nothing)
    gap_weight: float = 2.0  # score += this x sum over the patch of vertex area x (radius - distance), in voxels
    seed: int = 0


def medial_radii(
    points: np.ndarray, normals: np.ndarray, surface: np.ndarray, r_max: float, iterations: int = 16
) -> np.ndarray:
    """Radius of the largest ball inside the tooth touching each surface point, mm (shrinking ball).

    `points` (p, 3) mm on the surface with outward unit `normals` (p, 3); `surface` (s, 3) mm dense
    surface points. Start with a ball of radius `r_max` mm and, while a surface point lies inside
    it, shrink it to the ball tangent at the point that passes through that surface point.
    """
    tree = cKDTree(surface)
    r = np.full(len(points), float(r_max))
    act = np.arange(len(points))  # a ball that did not shrink meets the same point next time: done
    for _ in range(iterations):
        p, n, ra = points[act], normals[act], r[act]
        d, j = tree.query(p - ra[:, None] * n)
        v = p - surface[j]
        denom = 2.0 * np.einsum("ij,ij->i", v, n)
        shrink = (d < ra * (1 - 1e-9)) & (denom > 1e-12)
        r_new = np.where(shrink, np.minimum(ra, np.einsum("ij,ij->i", v, v) / np.where(denom > 1e-12, denom, 1.0)), ra)
        moved = r_new != ra
        r[act] = r_new
        act = act[moved]
        if not len(act):
            break
    return r


announce_compiles()  # a kernel compiled here (not loaded from numba's cache) says so on stderr


@njit(cache=True, nogil=True)
def _farthest_point_sampling(points, k, start):
    """Indices of k of the (n, d) points, each the farthest from those chosen before, from `start`."""
    n, dims = points.shape
    chosen = np.empty(k, np.int64)
    mind = np.full(n, np.inf)
    chosen[0] = start
    for s in range(1, k + 1):
        p = chosen[s - 1]
        best, arg = -1.0, 0
        for i in range(n):
            d2 = 0.0
            for a in range(dims):
                t = points[i, a] - points[p, a]
                d2 += t * t
            if d2 < mind[i]:
                mind[i] = d2
            if mind[i] > best:
                best, arg = mind[i], i
        if s < k:
            chosen[s] = arg
    return chosen


def _farthest_points(points: np.ndarray, k: int, rng) -> np.ndarray:
    """Indices of k points spread out by farthest-point sampling from a random start."""
    return _farthest_point_sampling(np.ascontiguousarray(points, dtype=np.float64), k, int(rng.integers(len(points))))


def _group_means(points: np.ndarray, label: np.ndarray, k: int, weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(k, d) weighted means of the (n, d) points in each group 0..k-1 (0 for an empty group), and
    the (k,) total weights."""
    w = np.ones(len(points)) if weights is None else weights
    total = np.bincount(label, weights=w, minlength=k)
    sums = np.stack([np.bincount(label, weights=w * points[:, i], minlength=k) for i in range(points.shape[1])], 1)
    return sums / np.maximum(total, 1e-300)[:, None], total


# Centres up to this many make one leaf of scipy's k-d tree (its default leafsize), which it scans in
# index order keeping the first nearest: `_nearest_centres` answers the same without building it.
_SCANNED_CENTRES = 16


@njit(cache=True, nogil=True)
def _nearest_centres(points, centres):
    """(n,) index of the nearest of the (k, d) centres to each of the (n, d) points, by squared
    distance summed over the axes in order, the first on a tie (as a one-leaf cKDTree query)."""
    out = np.empty(len(points), np.int64)
    for i in range(len(points)):
        best, arg = np.inf, 0
        for j in range(len(centres)):
            d2 = 0.0
            for a in range(points.shape[1]):
                t = points[i, a] - centres[j, a]
                d2 += t * t
            if d2 < best:
                best, arg = d2, j
        out[i] = arg
    return out


def _nearest(points: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(n,) index of the nearest centre (k, d) to each point (n, d): a k-d tree, or for a few
    centres (the 2-means of a leaf split, hundreds of times a tooth) a compiled scan."""
    if len(centres) <= _SCANNED_CENTRES:
        return _nearest_centres(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(centres, dtype=np.float64))
    return cKDTree(centres).query(points)[1]


def _kmeans(points: np.ndarray, k: int, iterations: int, rng, weights: np.ndarray | None = None) -> np.ndarray:
    """(n, d) points into at most k clusters (Lloyd, nearest-centre assignment): (n,) labels 0..used-1."""
    k = min(k, len(points))
    centres = points[_farthest_points(points, k, rng)]
    for _ in range(iterations):
        label = _nearest(points, centres)
        means, total = _group_means(points, label, k, weights)
        centres[total > 0] = means[total > 0]
    label = _nearest(points, centres)
    return np.unique(label, return_inverse=True)[1]


@njit(cache=True, nogil=True)
def _fill_nearest_first(order, k, capacity, label):
    """Label (n,) points by (point, centre) pairs in `order` (flat indices point * k + centre, nearest
    first): each point joins the first centre it meets that has room left (`capacity` each)."""
    n = len(label)
    label[:] = -1
    room = np.full(k, capacity)
    left = n
    for flat in order:
        i, j = flat // k, flat % k
        if label[i] < 0 and room[j] > 0:
            label[i] = j
            room[j] -= 1
            left -= 1
            if not left:
                break


def _split_with_capacity(points: np.ndarray, k: int, capacity: int, rng, iterations: int = 6) -> np.ndarray:
    """(n, 3) points into at most k groups of at most `capacity` each (n <= k * capacity): (n,) labels.

    k-means whose assignment step fills the nearest centres first, pair by pair in order of
    distance, skipping full ones: groups stay compact and the tree keeps its branching factor.
    """
    n = len(points)
    k = min(k, n)
    centres = points[_farthest_points(points, k, rng)]
    label = np.zeros(n, dtype=np.int64)
    for _ in range(iterations):
        d = ((points[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2)
        _fill_nearest_first(np.argsort(d, axis=None, kind="stable"), k, capacity, label)
        means, total = _group_means(points, label, k)
        centres[total > 0] = means[total > 0]
    return label


@njit(cache=True, nogil=True)
def _radius_and_gap(points, centers):
    """(G, M, 4) weighted points (x, y, z mm, weight mm^2) and (G, C, 3) centres -> (G, C) radii to
    the farthest point, and (G, C) sums of weight x (radius - distance), mm^3."""
    g_n, c_n = points.shape[0], centers.shape[1]
    radius = np.empty((g_n, c_n))
    gap = np.empty((g_n, c_n))
    d = np.empty(points.shape[1])
    for g in range(g_n):
        # Padding (`_LeafFitter.patches`) repeats the first point with weight 0: it adds nothing.
        m_n = points.shape[1]
        while m_n > 1 and points[g, m_n - 1, 3] == 0.0 and points[g, m_n - 1, 0] == points[g, 0, 0] \
                and points[g, m_n - 1, 1] == points[g, 0, 1] and points[g, m_n - 1, 2] == points[g, 0, 2]:
            m_n -= 1
        for c in range(c_n):
            far = 0.0
            for m in range(m_n):
                dx, dy, dz = points[g, m, 0] - centers[g, c, 0], points[g, m, 1] - centers[g, c, 1], points[g, m, 2] - centers[g, c, 2]
                d[m] = np.sqrt(dx * dx + dy * dy + dz * dz)
                if d[m] > far:
                    far = d[m]
            total = 0.0
            for m in range(m_n):
                total += points[g, m, 3] * (far - d[m])
            radius[g, c] = far
            gap[g, c] = total
    return radius, gap


@njit(cache=True, nogil=True)
def _pair_patches(groups, pairs, vertices, vertex_area):
    """`_LeafFitter.merged_patches` compiled: (p, W, 4) rows of pair (a, b)'s vertices (x, y, z mm,
    area mm^2), a's then b's, padded with a's first vertex at weight 0."""
    m = groups.shape[1]
    length = np.empty(len(groups), np.int64)
    for g in range(len(groups)):
        n = 1
        while n < m and groups[g, n] != groups[g, 0]:  # a row's vertices first, then copies of its first
            n += 1
        length[g] = n
    width = 1
    for p in range(len(pairs)):
        width = max(width, length[pairs[p, 0]] + length[pairs[p, 1]])
    out = np.zeros((len(pairs), width, 4))
    for p in range(len(pairs)):
        a, b = pairs[p, 0], pairs[p, 1]
        col = 0
        for leaf in (a, b):
            for j in range(length[leaf]):
                v = groups[leaf, j]
                for k in range(3):
                    out[p, col, k] = vertices[v, k]
                out[p, col, 3] = vertex_area[v]
                col += 1
        first = groups[a, 0]
        for c in range(col, width):
            for k in range(3):
                out[p, c, k] = vertices[first, k]
    return out


def voxel_spacing(vertices: np.ndarray, faces: np.ndarray, options: FitOptions) -> float:
    """Spacing of the scoring voxels for this mesh, mm: `voxel_per_edge` x its median edge length,
    kept within [min_voxel_mm, voxel_mm]."""
    tri = vertices[faces]
    edge = float(np.median(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)))
    return float(np.clip(options.voxel_per_edge * edge, options.min_voxel_mm, options.voxel_mm))


class _LeafFitter:
    """Scores leaf spheres by the outside-band voxels they hold; fits and re-fits them."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, options: FitOptions):
        self.vertices, self.faces, self.options = vertices, faces, options
        self.band = OutsideBand(vertices, faces, voxel_mm=voxel_spacing(vertices, faces, options), max_voxels=options.max_voxels,
                                band_mm=options.band_mm, fine_mm=options.fine_band_mm)
        self.voxel = self.band.voxel
        self.count = self.band.count  # outside volume of spheres, (n, 3) and (n,) mm, in fine voxels
        tri = vertices[faces]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        self.vertex_area = np.bincount(faces.ravel(), weights=np.repeat(area / 3, 3), minlength=len(vertices))

    def patches(self, groups: np.ndarray) -> np.ndarray:
        """Padded vertex groups (L, M) -> (L, M, 4): x, y, z mm and the vertex's share of the
        surface, mm^2 (0 on padding, which repeats a row's first vertex)."""
        real = np.ones(groups.shape, dtype=bool)
        real[:, 1:] = groups[:, 1:] != groups[:, :1]
        return np.concatenate([self.vertices[groups], (self.vertex_area[groups] * real)[..., None]], axis=2)

    def merged_patches(self, groups: np.ndarray, pairs: np.ndarray) -> np.ndarray:
        """The patches of leaf pairs (p, 2) taken together, from padded vertex groups (L, M)
        (`node_vertex_groups`): (p, W, 4) as `patches`, each row a's vertices, then b's, then
        padding (a's first vertex, weight 0), W the widest pair.

        The same points and weights as the two leaves' `patches` side by side, without the
        padding between them: a repeated point changes no farthest distance nor enclosing
        sphere, and weighs nothing in the gap, so every fit of the pair is the same, while the
        compiled loops run over the real vertices only (leaves hold about a sixth of the widest).
        """
        return _pair_patches(groups, np.ascontiguousarray(pairs, dtype=np.int64), self.vertices, self.vertex_area)

    def score(self, pts: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For padded weighted patch points (L, M, 4) (`patches`) and centres (L, c, 3), mm: the score
        (outside voxels held plus `gap_weight` x the gap to the patch in voxel volumes) and radii, (L, c)."""
        r, gap = _radius_and_gap(np.ascontiguousarray(pts, dtype=np.float64), np.ascontiguousarray(centres, dtype=np.float64))
        cnt = self.count(centres.reshape(-1, 3), r.ravel()).reshape(r.shape)
        # Ties (e.g. no outside voxel at all) go to the smaller sphere.
        return cnt + self.options.gap_weight * gap / self.voxel**3 + r / (100 * r.max()), r

    def best(self, pts: np.ndarray, centres: np.ndarray, bound: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The argmin over each row of `score(pts, centres)`, its score and its outside voxels
        (`count`), (L,) each, counting only what can win; with `bound` (L,), only scores strictly
        below it count (index -1 where none is)."""
        r, gap = _radius_and_gap(np.ascontiguousarray(pts, dtype=np.float64), np.ascontiguousarray(centres, dtype=np.float64))
        return self.band.best(centres, r, self.options.gap_weight * gap / self.voxel**3, r / (100 * r.max()), bound)

    def handoff(self, leaf_of_face: np.ndarray, c: np.ndarray, r: np.ndarray, groups: np.ndarray | None = None,
                k: int = 6) -> np.ndarray:
        """Hand the triangles that set a leaf's radius to a neighbour that may grow, where that pays.

        Leaf A's radius is set by its farthest vertex; giving the A-triangles at that vertex to a
        nearby leaf B (which grows just enough to hold them) changes the outside volume by
        [B grown - B] + [A shrunk - A]; the best negative change per A is taken, at most one move
        into or out of each leaf per call, so the changes evaluated are the changes made.
        `groups`: the leaves' padded vertex groups (`node_vertex_groups`) when the caller has them.
        """
        n = len(r)
        faces, vertices = self.faces, self.vertices
        groups = node_vertex_groups(faces, leaf_of_face, n) if groups is None else groups
        pts = vertices[groups]
        far_vertex = groups[np.arange(n), np.sqrt(((pts - c[:, None, :]) ** 2).sum(axis=2)).argmax(axis=1)]
        crit = np.any(faces == far_vertex[leaf_of_face][:, None], axis=1)
        crit_count = np.bincount(leaf_of_face[crit], minlength=n)
        movable = (crit_count > 0) & (crit_count < np.bincount(leaf_of_face, minlength=n))
        if not movable.any():
            return leaf_of_face
        # A without its critical triangles: the radius it could shrink to.
        rest_pts = vertices[node_vertex_groups(faces[~crit], leaf_of_face[~crit], n)]
        r_shrunk = np.where(movable, radii_to_cover(rest_pts, c), r)
        crit_groups = node_vertex_groups(faces[crit], leaf_of_face[crit], n)  # (n, m), -1 rows: no critical face
        crit_pts = vertices[crit_groups]  # (n, m, 3)
        crit_mean, _ = _group_means(vertices[faces[crit]].mean(axis=1), leaf_of_face[crit], n)
        k = min(k + 1, n)
        _, near = cKDTree(c).query(crit_mean, k=k)
        near = near.reshape(n, -1)
        need = radii_to_cover_each(crit_pts, c[near])
        r_grown = np.maximum(r[near], need)
        base = self.count(c, r)
        gain_a = self.count(c, r_shrunk) - base  # <= 0
        mv = np.flatnonzero(movable)  # only these have anything to hand over
        # Per A, the first B minimising [B grown - B] + [A shrunk - A] + 1e-6 x B's growth, among
        # changes below 0: counting a grown B stops once it cannot win (`OutsideBand.best`).
        nb = near[mv]
        rest = np.where(nb == mv[:, None], np.inf, gain_a[mv, None] - base[nb])  # A itself is no B
        j, found, _ = self.band.best(c[nb], r_grown[mv], rest, 1e-6 * (r_grown[mv] - r[nb]), np.zeros(len(mv)))
        best_delta = np.full(n, np.inf)
        best_delta[mv] = np.where(j >= 0, found, np.inf)
        target = np.zeros(n, np.int64)
        target[mv] = nb[np.arange(len(mv)), np.maximum(j, 0)]
        busy = np.zeros(n, dtype=bool)
        moves = {}
        for a in np.argsort(best_delta, kind="stable"):
            if not best_delta[a] < 0:
                break
            b = target[a]
            if busy[a] or busy[b]:
                continue
            busy[a] = busy[b] = True
            moves[a] = b
        if not moves:
            return leaf_of_face
        dest = np.arange(n)
        dest[list(moves)] = list(moves.values())
        out = leaf_of_face.copy()
        out[crit] = dest[leaf_of_face[crit]]
        return out

    def search(self, pts: np.ndarray, c: np.ndarray, step: np.ndarray, rounds: int | None = None) -> np.ndarray:
        """Pattern search on the centres (L, 3) mm from `step` (L,) mm: move while the score drops.

        Steps go below the voxel size on purpose: among centres that hold as many outside voxels,
        the score prefers the smaller sphere, which tiny moves still find.
        """
        c = c.copy()
        best_s = self.score(pts, c[:, None, :])[0][:, 0]
        dirs = np.concatenate([np.eye(3), -np.eye(3)])
        for _ in range(self.options.search_rounds if rounds is None else rounds):
            act = np.flatnonzero(step > 1e-3 * self.voxel)
            if not len(act):
                break
            cand = c[act, None, :] + step[act, None, None] * dirs[None, :, :]
            j, sj, _ = self.best(pts[act], cand, best_s[act])
            improved = j >= 0
            moved = act[improved]
            c[moved] = cand[improved, j[improved]]
            best_s[moved] = sj[improved]
            step[act[~improved]] *= 0.5
        return c

    def normal_sums(self, leaf_of_face: np.ndarray, n_leaves: int) -> np.ndarray:
        """(n_leaves, 3) sums of the area-weighted outward normals of each leaf's faces (mm^2)."""
        tri = self.vertices[self.faces]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        return np.stack([np.bincount(leaf_of_face, weights=cross[:, i], minlength=n_leaves) for i in range(3)], axis=1)

    def fit_groups(self, pts: np.ndarray, normal: np.ndarray, search_rounds: int | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Fit spheres to padded weighted patch points (w, M, 4) (`patches`) with normal sums (w, 3): centres (w, 3),
        radii (w,), mm, from candidates along each patch's inward normal, then a pattern search; and
        their outside volumes (`count`), (w,)."""
        c0, r0 = enclosing_spheres(pts, iterations=60)
        n = normal / np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
        t = np.asarray(self.options.depths)
        cand = c0[:, None, :] - (r0[:, None] * t[None, :])[:, :, None] * n[:, None, :]
        j, _, cnt = self.best(pts, cand)
        c = cand[np.arange(len(pts)), j]
        if search_rounds == 0:
            return c, radii_to_cover(pts, c), cnt
        c = self.search(pts, c, 0.25 * r0, search_rounds)
        r = radii_to_cover(pts, c)
        return c, r, self.count(c, r)

    def fit(self, leaf_of_face: np.ndarray, n_leaves: int, which: np.ndarray | None = None,
            search_rounds: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First fit of leaves `which` (default all): centres (w, 3), radii (w,), mm, outside volumes (w,) (`fit_groups`)."""
        which = np.arange(n_leaves) if which is None else np.asarray(which)
        pts = self.patches(node_vertex_groups(self.faces, leaf_of_face, n_leaves)[which])  # (w, M, 4)
        return self.fit_groups(pts, self.normal_sums(leaf_of_face, n_leaves)[which], search_rounds)

    def reassign(self, leaf_of_face: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Give each face to the leaf, among those already holding all its vertices, where it sits deepest.

        A face moves only into a sphere that holds it, so coverage is kept, and the sphere it
        leaves may then shrink: the boundary faces that set a sphere's radius migrate away.
        """
        tri = self.vertices[self.faces]
        k = min(self.options.reassign_candidates, len(r))
        _, near = cKDTree(c).query(tri.mean(axis=1), k=k)
        near = np.concatenate([leaf_of_face[:, None], near.reshape(len(tri), -1)], axis=1)  # current first
        far = radii_to_cover_each(tri, c[near])
        rn = r[near]
        slack = rn - far  # depth of the face inside each candidate, mm
        if self.options.relative_depth:
            slack = slack / np.maximum(rn, 1e-300)
        slack[far > rn] = -np.inf
        return near[np.arange(len(tri)), slack.argmax(axis=1)]


def _face_geometry(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per face: centroid (F, 3) mm, outward unit normal (F, 3), area (F,) mm^2."""
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    return tri.mean(axis=1), cross / np.maximum(2 * area, 1e-300)[:, None], area


def medial_offsets(vertices: np.ndarray, faces: np.ndarray, options: FitOptions, rng) -> tuple[np.ndarray, np.ndarray]:
    """Per face: centroid (F, 3) mm and the step (F, 3) mm that takes it to the medial axis
    (rho(x) * n(x), rho capped at `medial_cap_mm`), so x - pull * step is pulled `pull` of the way."""
    centroid, normal, _ = _face_geometry(vertices, faces)
    # Estimated on a subsample of faces (a smooth field), spread to the rest by nearest face.
    sub = rng.choice(len(faces), size=min(len(faces), options.medial_samples), replace=False)
    rho_sub = medial_radii(centroid[sub], normal[sub], vertices, options.medial_cap_mm)
    rho = rho_sub[cKDTree(centroid[sub]).query(centroid)[1]]
    return centroid, np.minimum(rho, options.medial_cap_mm)[:, None] * normal


def initial_leaves(centroid: np.ndarray, step: np.ndarray, pull: float, n_leaves: int, options: FitOptions, rng) -> np.ndarray:
    """(F,) leaf of each face, 0..L-1 (L <= n_leaves): k-means on the centroids pulled toward the
    medial axis (`medial_offsets`)."""
    return _kmeans(centroid - pull * step, n_leaves, options.lloyd_iterations, rng)


def _compact(leaf_of_face: np.ndarray, c: np.ndarray, r: np.ndarray):
    """Drop leaves without faces and renumber the rest in order."""
    keep = np.bincount(leaf_of_face, minlength=len(r)) > 0
    return (np.cumsum(keep) - 1)[leaf_of_face], c[keep], r[keep]


def _split_worst(fitter: "_LeafFitter", leaf_of_face: np.ndarray, c: np.ndarray, r: np.ndarray, n_split: int, rng):
    """Split the n_split leaves holding the most outside volume in two (2-means on face centroids)."""
    n = len(r)
    pts = fitter.patches(node_vertex_groups(fitter.faces, leaf_of_face, n))
    score = fitter.score(pts, c[:, None, :])[0][:, 0]
    counts = np.bincount(leaf_of_face, minlength=n)
    score[counts < 2] = -np.inf
    worst = np.argsort(score)[::-1][:n_split]
    worst = worst[np.isfinite(score[worst])]
    if not len(worst):  # every leaf is a single triangle already
        return leaf_of_face, c, r
    centroid = fitter.vertices[fitter.faces].mean(axis=1)
    leaf_of_face = leaf_of_face.copy()
    for j, w in enumerate(worst):
        idx = np.flatnonzero(leaf_of_face == w)
        half = _kmeans(centroid[idx], 2, 8, rng)
        leaf_of_face[idx[half == 1]] = n + j
    changed = np.concatenate([worst, n + np.arange(len(worst))])
    c = np.concatenate([c, np.zeros((len(worst), 3))])
    r = np.concatenate([r, np.zeros(len(worst))])
    c[changed], r[changed], _ = fitter.fit(leaf_of_face, n + len(worst), changed)
    return leaf_of_face, c, r


def adjacent_leaf_pairs(faces: np.ndarray, leaf_of_face: np.ndarray, n: int) -> np.ndarray:
    """(p, 2) distinct pairs a < b of leaves (of n) whose faces share a vertex."""
    key = np.unique(faces.ravel().astype(np.int64) * n + np.repeat(leaf_of_face.astype(np.int64), 3))
    vert, lf = key // n, key % n  # sorted by vertex, then leaf
    found = [np.zeros((0, 2), np.int64)]
    for step in range(1, len(key)):
        same = vert[step:] == vert[:-step]
        if not same.any():
            break
        found.append(np.stack([lf[:-step][same], lf[step:][same]], axis=1))
    return np.unique(np.concatenate(found), axis=0)


def second_halves(points: np.ndarray, label: np.ndarray, split: np.ndarray) -> np.ndarray:
    """(F,) bool: the points (F, 3) of each group to split (`split`, (n,) bool over the labels)
    that lie beyond the group's median along its principal axis; a group of k >= 2 points keeps
    k // 2 of them, so both halves hold some."""
    n = len(split)
    sel = np.flatnonzero(split[label])
    lab, x = label[sel], points[sel]
    cnt = np.bincount(lab, minlength=n)
    mean, _ = _group_means(x, lab, n)
    d = x - mean[lab]
    cov = np.stack([np.bincount(lab, weights=d[:, i] * d[:, j], minlength=n) for i in range(3) for j in range(3)], axis=1)
    axis = np.linalg.eigh(cov.reshape(n, 3, 3))[1][:, :, 2]
    proj = np.einsum("ij,ij->i", d, axis[lab])
    order = np.lexsort((proj, lab))
    rank = np.empty(len(sel), dtype=np.int64)
    rank[order] = np.arange(len(sel)) - (np.cumsum(cnt) - cnt)[lab[order]]
    out = np.zeros(len(label), dtype=bool)
    out[sel[rank >= cnt[lab] // 2]] = True
    return out


def _rebalance(fitter: "_LeafFitter", leaf_of_face: np.ndarray, c: np.ndarray, r: np.ndarray, max_moves: int):
    """Move leaves to where they pay: merge neighbours that cost little together, split the worst.

    A split of leaf w in two (its face centroids halved across their long axis, both halves fitted) gains
    cost(w) - cost(halves); a merge of neighbours a, b costs cost(a + b) - cost(a) - cost(b). The
    best gains are paired with the cheapest merges, leaves disjoint, while a gain beats a cost:
    the number of leaves stays, the outside volume falls.
    """
    n = len(r)
    faces, vertices, options = fitter.faces, fitter.vertices, fitter.options
    counts = np.bincount(leaf_of_face, minlength=n)
    cost = fitter.count(c, r).astype(np.float64)
    order = np.argsort(-cost, kind="stable")
    cand = order[counts[order] >= 2][: 2 * max_moves]
    pairs = adjacent_leaf_pairs(faces, leaf_of_face, n)
    if not len(cand) or not len(pairs):
        return leaf_of_face, c, r
    m = len(cand)
    in_cand = np.full(n, -1)
    in_cand[cand] = np.arange(m)
    trial = leaf_of_face.copy()
    centroid = vertices[faces].mean(axis=1)
    second = second_halves(centroid, leaf_of_face, in_cand >= 0)
    trial[second] = n + in_cand[leaf_of_face[second]]
    changed = np.concatenate([cand, n + np.arange(m)])
    cs, rs, split_cost = fitter.fit(trial, n + m, changed)
    gain = cost[cand] - split_cost[:m] - split_cost[m:]
    nsum = fitter.normal_sums(leaf_of_face, n)
    merged_pts = fitter.merged_patches(node_vertex_groups(faces, leaf_of_face, n), pairs)
    cm, rm, merged_cost = fitter.fit_groups(merged_pts, nsum[pairs[:, 0]] + nsum[pairs[:, 1]],
                                            search_rounds=options.rebalance_merge_rounds)
    merge_cost = merged_cost - cost[pairs[:, 0]] - cost[pairs[:, 1]]
    busy = np.zeros(n, dtype=bool)
    splits, merges = [], []
    mi = 0
    merge_order = np.argsort(merge_cost, kind="stable")
    for si in np.argsort(-gain, kind="stable"):
        w = cand[si]
        if len(splits) >= max_moves or not gain[si] > 0:
            break
        if busy[w]:
            continue
        while mi < len(merge_order):
            a, b = pairs[merge_order[mi]]
            if not (busy[a] or busy[b] or a == w or b == w):
                break
            mi += 1
        if mi >= len(merge_order) or not gain[si] > merge_cost[merge_order[mi]]:
            break
        p = merge_order[mi]
        mi += 1
        a, b = pairs[p]
        busy[[a, b, w]] = True
        splits.append((si, b))
        merges.append(p)
    if not splits:
        return leaf_of_face, c, r
    out = leaf_of_face.copy()
    c, r = c.copy(), r.copy()
    for p in merges:
        a, b = pairs[p]
        out[leaf_of_face == b] = a
        c[a], r[a] = cm[p], rm[p]
    for si, b in splits:
        w = cand[si]
        out[trial == n + si] = b
        c[w], r[w] = cs[si], rs[si]
        c[b], r[b] = cs[m + si], rs[m + si]
    return out, c, r


def _improve(fitter: "_LeafFitter", leaf: np.ndarray, c: np.ndarray, r: np.ndarray, n_leaves: int, rng):
    """The improve rounds (module text, step 3) from a first fit: (F,) leaf of each face, centres
    (L, 3) mm, radii (L,) mm, L <= n_leaves."""
    vertices, faces, options = fitter.vertices, fitter.faces, fitter.options
    for _ in range(options.reassign_rounds):
        if len(r) < n_leaves:
            leaf, c, r = _split_worst(fitter, leaf, c, r, n_leaves - len(r), rng)
        if options.rebalance_share > 0:
            leaf, c, r = _rebalance(fitter, leaf, c, r, max(1, int(options.rebalance_share * len(r))))
        leaf = fitter.reassign(leaf, c, r)
        leaf, c, r = _compact(leaf, c, r)
        for _ in range(options.handoff_rounds):
            groups = node_vertex_groups(faces, leaf, len(r))
            r = radii_to_cover(vertices[groups], c)
            leaf = fitter.handoff(leaf, c, r, groups)
        pts = fitter.patches(node_vertex_groups(faces, leaf, len(r)))
        c = fitter.search(pts, c, 0.1 * radii_to_cover(pts, c), options.refit_rounds)
        r = radii_to_cover(pts, c)
    if len(r) < n_leaves:
        # Slots the last reassignment freed go to the worst leaves: more spheres, less outside.
        leaf, c, r = _split_worst(fitter, leaf, c, r, n_leaves - len(r), rng)
        leaf, c, r = _compact(leaf, c, r)
    return leaf, c, r


def fit_leaves(vertices: np.ndarray, faces: np.ndarray, n_leaves: int, options: FitOptions, rng):
    """At most n_leaves leaf spheres with the least outside volume: (F,) leaf of each face,
    centres (L, 3) mm, radii (L,) mm."""
    fitter = _LeafFitter(vertices, faces, options)
    reserve = int(round(n_leaves * options.reserve)) if n_leaves >= 32 else 0
    centroid, step = medial_offsets(vertices, faces, options, rng)

    def first_fit(pulls):
        # The best pull toward the medial axis depends on the tooth (thin incisors, thick molars):
        # fit each candidate pull once and keep the partition with the least outside volume.
        best = None
        for pull in pulls:
            leaf = initial_leaves(centroid, step, pull, n_leaves - reserve, options, rng)
            c, r, cnt = fitter.fit(leaf, int(leaf.max()) + 1)
            if best is None or cnt.sum() < best[0]:
                best = (cnt.sum(), leaf, c, r)
        return best[1:]

    leaf, c, r = _improve(fitter, *first_fit(options.medial_pulls), n_leaves, rng)
    if not options.thin_pulls or np.median(np.linalg.norm(step, axis=1)) >= options.thin_rho_mm:
        return leaf, c, r
    # A thin tooth (both sides of the crown and root within reach of one sphere) may fit far better
    # with a stronger pull, which the first fit does not foresee: where the finished tree is loose
    # by the builder's own count, build it again whole with the thin pulls and keep the tighter.
    total = float(fitter.count(c, r).sum())
    if total * fitter.voxel**3 <= options.thin_retry_sov * abs(mesh_volume(vertices, faces)):
        return leaf, c, r
    other = _improve(fitter, *first_fit(options.thin_pulls), n_leaves, rng)
    return other if float(fitter.count(other[1], other[2]).sum()) < total else (leaf, c, r)


def group_leaves(positions: np.ndarray, branching: int, depth: int, rng) -> list[np.ndarray]:
    """Parents of each level for leaves at `positions` (L, 3) mm, L <= branching**(depth-1).

    Returns per level k (n_k,) parent indices into level k-1 (level 0: [-1]) and, last, the
    permutation that orders the leaves by parent. Built top-down over the leaves with a capacity
    (a node of level k may hold at most branching**(depth-1-k) leaves), so every node keeps at
    most `branching` children.
    """
    n = len(positions)
    path = np.zeros((n, max(depth - 1, 0)), dtype=np.int64)
    groups = [np.arange(n)]
    for level in range(1, depth):
        capacity = branching ** (depth - 1 - level)
        nxt = []
        for g in groups:
            lab = _split_with_capacity(positions[g], branching, capacity, rng) if len(g) > 1 else np.zeros(1, np.int64)
            path[g, level - 1] = lab
            nxt.extend(g[lab == j] for j in np.unique(lab))
        groups = nxt
    key = np.zeros(n, dtype=np.int64)
    for level in range(1, depth):
        key = key * branching + path[:, level - 1]
    order = np.argsort(key, kind="stable")
    path = path[order]
    parents = [np.array([-1], dtype=np.int64)]
    prev = np.zeros(n, dtype=np.int64)  # node of level-1 holding each (ordered) leaf
    key = np.zeros(n, dtype=np.int64)
    for level in range(1, depth):
        key = key * branching + path[:, level - 1]
        used, node = np.unique(key, return_inverse=True)
        first = np.zeros(len(used), dtype=np.int64)
        first[node[::-1]] = np.arange(n)[::-1]
        parents.append(prev[first])
        prev = node.astype(np.int64)
    return parents + [order]


def build_fit_tree(
    vertices: np.ndarray, faces: np.ndarray, branching: int = FIT_BRANCHING, depth: int = 4, options: FitOptions | None = None
) -> SphereTree:
    """Optimising sphere tree of a closed mesh ((n, 3) float64 mm, (m, 3) int): see the module text."""
    options = options or FitOptions()
    rng = np.random.default_rng(options.seed)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if depth == 1:
        c, r = enclosing_spheres(vertices[None])
        return SphereTree(branching, (c,), (r,), (np.array([-1], dtype=np.int64),), np.zeros(len(faces), np.int64), "fit")
    leaf, c, r = fit_leaves(vertices, faces, branching ** (depth - 1), options, rng)
    *parents, order = group_leaves(c, branching, depth, rng)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    node_of_face = [rank[leaf]]
    centers, radii = [c[order]], [r[order]]
    for k in range(depth - 2, -1, -1):
        node_of_face.insert(0, parents[k + 1][node_of_face[0]])
        pts = vertices[node_vertex_groups(faces, node_of_face[0], len(parents[k]))]
        ck, rk = enclosing_spheres(pts)
        centers.insert(0, ck)
        radii.insert(0, rk)
    return SphereTree(
        branching=branching,
        centers=tuple(centers),
        radii=tuple(radii),
        parents=tuple(parents),
        leaf_of_face=node_of_face[-1],
        method="fit",
    )

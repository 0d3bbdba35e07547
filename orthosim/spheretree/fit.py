"""The optimising sphere-tree builder: few, large, deep-set leaf spheres with little volume outside.

A leaf covers a patch of the tooth surface. Any sphere holding a patch's vertices holds the patch
(exact coverage), and among those the best one has its centre sunk inward along the patch normal:
a bigger sphere centred deeper leaves a thinner cap outside the surface (cap volume
~ pi rho^4 / (4 R) for a patch of radius rho), until it starts to bulge out elsewhere. So:

1. Partition the surface triangles top-down: the triangles of each node are split into up to
   `branching` groups by k-means on (centroid, scaled normal), level by level, all nodes of a
   level at once. Leaves are the groups of the last level; the tree shape follows for free.
2. Fit each leaf: candidate centres along the patch's inward normal, then a pattern search in 3D;
   the radius is always the distance to the farthest patch vertex, and the score is the number of
   points of an outside-the-tooth voxel band that fall in the sphere (its outside volume).
3. Each inner node is the near-minimal sphere around all vertices of its triangles, so it holds
   everything its children hold and a descent never loses a contact.

All coordinates in mm, in the mesh's frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from .enclose import enclosing_spheres, node_vertex_groups, radii_to_cover
from .inside import CrossingIndex
from .tree import SphereTree


@dataclass(frozen=True)
class FitOptions:
    """Knobs of the optimising builder (defaults tuned on the parametric and real teeth)."""

    normal_weight: float = 0.0  # normal's weight in k-means features, in units of the patch size
    medial_pull: float = 0.6  # k-means on x - medial_pull * rho(x) * n(x): 0 surface, 1 medial centres
    medial_cap_mm: float = 4.0  # rho capped at this depth, mm
    medial_samples: int = 4000  # faces on which rho is estimated
    lloyd_iterations: int = 12
    partition: str = "bottom_up"  # or "top_down": split the triangles level by level
    area_weighted: bool = False  # k-means balances area (True) or triangle count (False)
    voxel_mm: float = 0.15  # spacing of the outside-band voxels that score spheres, mm
    max_voxels: int = 4_000_000  # the spacing grows on huge meshes to keep the grid this small
    band_mm: float = 0.75  # thickness of the outside band that scores spheres, mm
    fine_band_mm: float = 0.3  # inner part of the band sampled at full resolution, mm
    depths: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0)  # x patch radius
    search_rounds: int = 8
    reassign_rounds: int = 3
    refit_rounds: int = 8  # pattern-search rounds after each reassignment
    seed: int = 0


def _batched_kmeans(
    features: np.ndarray, node: np.ndarray, n_nodes: int, k: int, iterations: int, rng, weights: np.ndarray | None = None
) -> np.ndarray:
    """Split the points of every node into at most k clusters at once.

    `features` (F, d), `node` (F,) int, `weights` (F,) (e.g. triangle areas, so clusters balance
    area rather than triangle count): returns (F,) int label in [0, k) within each point's node.
    Initial centres by farthest-point sampling per node (spread out, deterministic given rng).
    """
    F = len(features)
    order = np.argsort(node, kind="stable")
    counts = np.bincount(node, minlength=n_nodes)
    start = np.cumsum(counts) - counts
    centres = np.zeros((n_nodes, k, features.shape[1]))
    # First centre: a random point of each node; then the point farthest from all chosen so far.
    pick = start + (rng.random(n_nodes) * np.maximum(counts, 1)).astype(np.int64)
    pick = order[np.minimum(pick, F - 1)]
    centres[:, 0] = features[pick]
    mind = ((features - centres[node, 0]) ** 2).sum(axis=1)
    for j in range(1, k):
        # Per-node argmax of mind: sort by (node, mind) and take the last of each node.
        o = np.lexsort((mind, node))
        last = o[np.cumsum(counts) - 1]
        centres[:, j] = features[last]
        mind = np.minimum(mind, ((features - centres[node, j]) ** 2).sum(axis=1))
    # Nodes with fewer than k points repeat centres; duplicates simply stay empty.
    label = np.zeros(F, dtype=np.int64)
    for _ in range(iterations):
        d = ((features[:, None, :] - centres[node]) ** 2).sum(axis=2)  # (F, k)
        label = d.argmin(axis=1)
        key = node * k + label
        w = np.ones(F) if weights is None else weights
        cnt = np.bincount(key, weights=w, minlength=n_nodes * k).reshape(n_nodes, k)
        sums = np.stack(
            [np.bincount(key, weights=w * features[:, i], minlength=n_nodes * k) for i in range(features.shape[1])], axis=1
        ).reshape(n_nodes, k, -1)
        filled = cnt > 0
        centres[filled] = sums[filled] / cnt[filled][:, None]
    return label


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
    for _ in range(iterations):
        c = points - r[:, None] * normals
        d, j = tree.query(c)
        v = points - surface[j]
        denom = 2.0 * np.einsum("ij,ij->i", v, normals)
        shrink = (d < r * (1 - 1e-9)) & (denom > 1e-12)
        if not shrink.any():
            break
        r_new = np.einsum("ij,ij->i", v, v) / np.where(denom > 1e-12, denom, 1.0)
        r = np.where(shrink, np.minimum(r, r_new), r)
    return r


def partition_faces(
    vertices: np.ndarray, faces: np.ndarray, branching: int, depth: int, options: FitOptions
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Top-down split of the triangles: per level, (F,) node of each face and (n_k,) parent of each node."""
    rng = np.random.default_rng(options.seed)
    tri = vertices[faces]
    centroid = tri.mean(axis=1)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    normal = cross / np.maximum(2 * area, 1e-300)[:, None]
    total_area = float(area.sum())
    if options.medial_pull:
        # Estimated on a subsample of faces (a smooth field), spread to the rest by nearest face.
        sub = rng.choice(len(faces), size=min(len(faces), options.medial_samples), replace=False)
        rho_sub = medial_radii(centroid[sub], normal[sub], vertices, options.medial_cap_mm)
        rho = rho_sub[cKDTree(centroid[sub]).query(centroid)[1]]
        centroid = centroid - (options.medial_pull * np.minimum(rho, options.medial_cap_mm))[:, None] * normal
    if options.partition == "bottom_up" and depth > 1:
        return _bottom_up(centroid, area, branching, depth, options, rng)
    node = np.zeros(len(faces), dtype=np.int64)
    node_of_face = [node]
    parents = [np.array([-1], dtype=np.int64)]
    n_nodes = 1
    for k in range(1, depth):
        patch = np.sqrt(total_area / branching**k)  # typical size of a node of this level, mm
        feats = np.concatenate([centroid, options.normal_weight * patch * normal], axis=1)
        label = _batched_kmeans(feats, node, n_nodes, branching, options.lloyd_iterations, rng,
                                area if options.area_weighted else None)
        # Number the non-empty (node, label) groups in order: sorted by parent by construction.
        key = node * branching + label
        used, new = np.unique(key, return_inverse=True)
        parents.append(used // branching)
        node = new.astype(np.int64)
        node_of_face.append(node)
        n_nodes = len(used)
    return node_of_face, parents


def _farthest_points(points: np.ndarray, k: int, rng) -> np.ndarray:
    """Indices of k points spread out by farthest-point sampling from a random start."""
    chosen = [int(rng.integers(len(points)))]
    mind = ((points - points[chosen[0]]) ** 2).sum(axis=1)
    for _ in range(1, k):
        chosen.append(int(mind.argmax()))
        mind = np.minimum(mind, ((points - points[chosen[-1]]) ** 2).sum(axis=1))
    return np.asarray(chosen)


def _kmeans(points: np.ndarray, k: int, iterations: int, rng, weights: np.ndarray | None = None) -> np.ndarray:
    """(n, d) points into at most k clusters (Lloyd, k-d tree assignment): (n,) labels 0..used-1."""
    k = min(k, len(points))
    centres = points[_farthest_points(points, k, rng)]
    w = np.ones(len(points)) if weights is None else weights
    for _ in range(iterations):
        label = cKDTree(centres).query(points)[1]
        cnt = np.bincount(label, weights=w, minlength=k)
        sums = np.stack([np.bincount(label, weights=w * points[:, i], minlength=k) for i in range(points.shape[1])], 1)
        filled = cnt > 0
        centres[filled] = sums[filled] / cnt[filled][:, None]
    label = cKDTree(centres).query(points)[1]
    return np.unique(label, return_inverse=True)[1]


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
        order = np.argsort(d, axis=None, kind="stable")
        label[:] = -1
        room = np.full(k, capacity)
        left = n
        for flat in order:
            i, j = divmod(int(flat), k)
            if label[i] < 0 and room[j] > 0:
                label[i] = j
                room[j] -= 1
                left -= 1
                if not left:
                    break
        for j in range(k):
            if (label == j).any():
                centres[j] = points[label == j].mean(axis=0)
    return label


def _bottom_up(centroid: np.ndarray, area: np.ndarray, branching: int, depth: int, options: FitOptions, rng):
    """Leaves first (k-means of all triangles into branching**(depth-1)), then group leaves upward.

    Leaves are then free of the borders a top-down split would impose; the groups above are built
    top-down over the leaves with a capacity, so every node keeps at most `branching` children.
    """
    leaf = _kmeans(centroid, branching ** (depth - 1), options.lloyd_iterations, rng,
                   area if options.area_weighted else None)
    n_leaves = int(leaf.max()) + 1
    cnt = np.bincount(leaf, weights=area, minlength=n_leaves)
    leaf_pos = np.stack([np.bincount(leaf, weights=area * centroid[:, i], minlength=n_leaves) for i in range(3)], 1)
    leaf_pos /= cnt[:, None]
    # path[i, k] = child index taken at level k+1 on the way from the root to leaf i.
    path = np.zeros((n_leaves, depth - 1), dtype=np.int64)
    groups = [np.arange(n_leaves)]
    for level in range(1, depth):
        capacity = branching ** (depth - 1 - level)
        nxt = []
        for g in groups:
            lab = _split_with_capacity(leaf_pos[g], branching, capacity, rng) if len(g) > capacity else np.arange(len(g))
            path[g, level - 1] = lab
            nxt.extend(g[lab == j] for j in np.unique(lab))
        groups = nxt
    key = np.zeros(n_leaves, dtype=np.int64)
    node_of_leaf, parents = [], [np.array([-1], dtype=np.int64)]
    prev_nodes = np.zeros(n_leaves, dtype=np.int64)
    node_of_leaf.append(prev_nodes)
    for level in range(1, depth):
        key = key * branching + path[:, level - 1]
        used, nodes = np.unique(key, return_inverse=True)
        first = np.zeros(len(used), dtype=np.int64)
        first[nodes] = np.arange(n_leaves)
        parents.append(prev_nodes[first])
        node_of_leaf.append(nodes.astype(np.int64))
        prev_nodes = nodes
    return [n[leaf] for n in node_of_leaf], parents


def _outside_band(vertices: np.ndarray, faces: np.ndarray, options: FitOptions) -> tuple[np.ndarray, np.ndarray, float]:
    """Voxel centres outside the tooth within `band_mm` of it, (n, 3) mm: all those within
    `fine_band_mm` (where the thin caps of good spheres lie), and every other one of each axis
    beyond (bulges, which only need to be seen, counted 8 times); and the voxel size, mm."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    lo, hi = lo - options.band_mm, hi + options.band_mm
    h = max(options.voxel_mm, float(np.prod(hi - lo) / options.max_voxels) ** (1 / 3))
    shape = tuple(int(n) for n in np.ceil((hi - lo) / h).astype(np.int64) + 1)
    # An irrational shift keeps voxel centres off the mesh's own (often round-numbered) coordinates.
    origin = lo - h * 0.318309886
    inside = CrossingIndex(vertices, faces).voxels(origin, h, shape)
    dist = ndimage.distance_transform_edt(~inside) * h
    near = ~inside & (dist <= options.fine_band_mm)
    far = ~inside & (dist > options.fine_band_mm) & (dist <= options.band_mm)
    far[1::2] = False
    far[:, 1::2] = False
    far[:, :, 1::2] = False
    return origin + h * np.argwhere(near), origin + h * np.argwhere(far), h


class _LeafFitter:
    """Scores leaf spheres by the outside-band voxels they hold; fits and re-fits them."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, options: FitOptions):
        self.vertices, self.faces, self.options = vertices, faces, options
        near, far, self.voxel = _outside_band(vertices, faces, options)
        self.near, self.far = cKDTree(near), cKDTree(far)

    def score(self, pts: np.ndarray, centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For padded patch points (L, M, 3) and centres (L, c, 3), mm: outside voxels held, radii (L, c)."""
        r = np.sqrt(((pts[:, None, :, :] - centres[:, :, None, :]) ** 2).sum(axis=3).max(axis=2))
        flat_c, flat_r = centres.reshape(-1, 3), r.ravel()
        cnt = self.near.query_ball_point(flat_c, flat_r, return_length=True).reshape(r.shape)
        cnt = cnt + 8 * self.far.query_ball_point(flat_c, flat_r, return_length=True).reshape(r.shape)
        # Ties (e.g. no outside voxel at all) go to the smaller sphere.
        return cnt + r / (100 * r.max()), r

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
            s, _ = self.score(pts[act], cand)
            j = s.argmin(axis=1)
            sj = s[np.arange(len(act)), j]
            improved = sj < best_s[act]
            moved = act[improved]
            c[moved] = cand[improved, j[improved]]
            best_s[moved] = sj[improved]
            step[act[~improved]] *= 0.5
        return c

    def fit(self, leaf_of_face: np.ndarray, n_leaves: int) -> tuple[np.ndarray, np.ndarray]:
        """First fit: centres (L, 3), radii (L,), mm, from candidates along each patch's inward normal."""
        pts = self.vertices[node_vertex_groups(self.faces, leaf_of_face, n_leaves)]  # (L, M, 3)
        c0, r0 = enclosing_spheres(pts, iterations=60)
        tri = self.vertices[self.faces]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # area-weighted normals
        n = np.stack([np.bincount(leaf_of_face, weights=cross[:, i], minlength=n_leaves) for i in range(3)], axis=1)
        n /= np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
        t = np.asarray(self.options.depths)
        cand = c0[:, None, :] - (r0[:, None] * t[None, :])[:, :, None] * n[:, None, :]
        s, _ = self.score(pts, cand)
        c = cand[np.arange(n_leaves), s.argmin(axis=1)]
        c = self.search(pts, c, 0.25 * r0)
        return c, radii_to_cover(pts, c)

    def reassign(self, leaf_of_face: np.ndarray, c: np.ndarray, r: np.ndarray, k: int = 12) -> np.ndarray:
        """Give each face to the leaf, among those already holding all its vertices, where it sits deepest.

        A face moves only into a sphere that holds it, so coverage is kept, and the sphere it
        leaves may then shrink: the boundary faces that set a sphere's radius migrate away.
        """
        tri = self.vertices[self.faces]
        k = min(k, len(r))
        _, near = cKDTree(c).query(tri.mean(axis=1), k=k)
        near = np.concatenate([leaf_of_face[:, None], near.reshape(len(tri), -1)], axis=1)  # current first
        far = np.sqrt(((tri[:, None, :, :] - c[near][:, :, None, :]) ** 2).sum(axis=3).max(axis=2))
        rn = r[near]
        slack = (rn - far) / np.maximum(rn, 1e-300)  # relative depth of the face inside each candidate
        slack[far > rn] = -np.inf
        return near[np.arange(len(tri)), slack.argmax(axis=1)]


def fit_leaves(
    vertices: np.ndarray, faces: np.ndarray, leaf_of_face: np.ndarray, n_leaves: int, options: FitOptions
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leaf spheres with the least outside volume: centres (L, 3), radii (L,), mm, and (F,) leaf of each face."""
    fitter = _LeafFitter(vertices, faces, options)
    c, r = fitter.fit(leaf_of_face, n_leaves)
    for _ in range(options.reassign_rounds):
        leaf_of_face = fitter.reassign(leaf_of_face, c, r)
        groups = node_vertex_groups(faces, leaf_of_face, n_leaves)
        pts = vertices[groups]
        # A leaf that gave away all its faces shrinks to a point; build_fit_tree drops it.
        empty = groups[:, 0] < 0
        pts[empty] = c[empty][:, None, :]
        r = radii_to_cover(pts, c)
        c = fitter.search(pts, c, 0.1 * r, options.refit_rounds)
        r = radii_to_cover(pts, c)
    return c, r, leaf_of_face


def build_fit_tree(
    vertices: np.ndarray, faces: np.ndarray, branching: int = 8, depth: int = 4, options: FitOptions | None = None
) -> SphereTree:
    """Optimising sphere tree of a closed mesh ((n, 3) float64 mm, (m, 3) int): see the module text."""
    options = options or FitOptions()
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    node_of_face, parents = partition_faces(vertices, faces, branching, depth, options)
    c, r, leaf = fit_leaves(vertices, faces, node_of_face[-1], len(parents[-1]), options)
    # Faces may have moved to another leaf: drop emptied leaves, inner nodes follow their leaves.
    keep = np.bincount(leaf, minlength=len(r)) > 0
    renumber = np.cumsum(keep) - 1
    node_of_face[-1] = renumber[leaf]
    parents[-1] = parents[-1][keep]
    c, r = c[keep], r[keep]
    for k in range(depth - 2, -1, -1):
        node_of_face[k] = parents[k + 1][node_of_face[k + 1]]
    for k in range(depth - 2, 0, -1):
        # Inner nodes left without faces go too (their children are all gone).
        keep = np.bincount(node_of_face[k], minlength=len(parents[k])) > 0
        renumber = np.cumsum(keep) - 1
        node_of_face[k] = renumber[node_of_face[k]]
        parents[k + 1] = renumber[parents[k + 1]]
        parents[k] = parents[k][keep]
    centers, radii = [c], [r]
    for k in range(depth - 2, -1, -1):
        pts = vertices[node_vertex_groups(faces, node_of_face[k], len(parents[k]))]
        c, r = enclosing_spheres(pts)
        centers.insert(0, c)
        radii.insert(0, r)
    return SphereTree(
        branching=branching,
        centers=tuple(centers),
        radii=tuple(radii),
        parents=tuple(parents),
        leaf_of_face=node_of_face[-1],
        method="fit",
    )

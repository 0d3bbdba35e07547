"""The voxels just outside a tooth, and how many of them a sphere holds: the optimising builder's score.

A leaf sphere's cost is its volume outside the tooth. The builder estimates it by counting the
centres of a regular voxel grid that lie outside the tooth, within a band around it, and inside
the sphere. The builder asks this for hundreds of thousands of candidate spheres per tooth, so
the count must be cheap: the band is stored as a weight grid (1 for a fine voxel, 8 for a coarse
one standing for its 2x2x2 block, 0 elsewhere) with running sums along z, and a sphere's count is
then one subtraction per (x, y) column it crosses, in compiled code.

Fine voxels are all those within `fine_mm` of the tooth (where the thin caps of good spheres
lie); beyond, out to `band_mm`, every other voxel of each axis is kept with weight 8 (bulges only
need to be seen). A voxel centre p counts for a sphere (c, r) when |p - c| <= r.
All coordinates in mm.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy import ndimage

from orthosim.spheretree.inside import CrossingIndex
from orthosim.system.firstrun import announce_compiles


announce_compiles()  # a kernel compiled here (not loaded from numba's cache) says so on stderr


@njit(cache=True, nogil=True, inline="always")
def _cells_within(c, half, n):
    """First and last of the grid indices 0..n-1 within `half` of `c` (voxel units; last < first
    when none)."""
    return max(int(np.ceil(c - half)), 0), min(int(np.floor(c + half)), n - 1)


@njit(cache=True, nogil=True, inline="always")
def _slice_weight(prefix, cy, cz, rx, total, stop):
    """`total` plus the weight of band voxels in one x slice (`prefix` (ny, nz + 1) running sums
    along z) inside a sphere centred at (., cy, cz) whose squared radius in that slice is rx >= 0,
    all in voxel units from the grid's first centre: one running-sum subtraction per (x, y) column
    it crosses. Returns early, with what it has, once that exceeds `stop` (-1: never)."""
    j0, j1 = _cells_within(cy, np.sqrt(rx), prefix.shape[0])
    for j in range(j0, j1 + 1):
        rz = rx - (j - cy) ** 2
        if rz >= 0.0:
            k0, k1 = _cells_within(cz, np.sqrt(rz), prefix.shape[1] - 1)
            if k1 >= k0:
                total += prefix[j, k1 + 1] - prefix[j, k0]
                if stop >= 0 and total > stop:
                    return total
    return total


@njit(cache=True, nogil=True, inline="always")
def _sphere_weight(prefix, origin, h, cx, cy, cz, r, stop):
    """Weight of band voxels inside the sphere (cx, cy, cz, r mm), counted column by column;
    counting stops, returning what it has, once the weight exceeds `stop` (-1: never). Counts only
    grow, so a count stopped there would have exceeded `stop` in full as well."""
    x, rv = (cx - origin[0]) / h, r / h
    y, z = (cy - origin[1]) / h, (cz - origin[2]) / h
    i0, i1 = _cells_within(x, rv, prefix.shape[0])
    total = 0
    for i in range(i0, i1 + 1):
        rx = rv * rv - (i - x) ** 2
        if rx >= 0.0:
            total = _slice_weight(prefix[i], y, z, rx, total, stop)
            if stop >= 0 and total > stop:
                return total
    return total


@njit(cache=True, nogil=True)
def _count_in_spheres(prefix, origin, h, centres, radii):
    """Weight of band voxels inside each sphere: (n,) int64, from (nx, ny, nz + 1) running sums."""
    out = np.zeros(len(radii), np.int64)
    for s in range(len(radii)):
        if radii[s] >= 0.0:
            out[s] = _sphere_weight(prefix, origin, h, centres[s, 0], centres[s, 1], centres[s, 2], radii[s], -1)
    return out


@njit(cache=True, nogil=True)
def _best_in_groups(prefix, origin, h, centres, radii, add1, add2, bound):
    """Per group g of candidates (G, C): the first c minimising (count + add1) + add2 among those
    strictly below bound[g], that score and its count; (-1, bound[g], -1) when none is below.

    The same choice as counting every sphere and taking the argmin, with less counting: counts only
    grow, so a candidate's count stops, column by column, once its score can no longer win. Candidates
    are tried smallest first (small spheres are cheap and usually good, and set a tight bound).
    """
    g_n, c_n = radii.shape
    best_idx = np.full(g_n, -1, np.int64)
    best = bound.copy()
    best_count = np.full(g_n, -1, np.int64)
    for g in range(g_n):
        order = np.argsort(radii[g])
        for o in range(c_n):
            s = order[o]
            r, a1, a2 = radii[g, s], add1[g, s], add2[g, s]
            if not r >= 0.0:
                continue
            score = (0.0 + a1) + a2
            if score > best[g] or (score == best[g] and s > best_idx[g]):
                continue
            # The largest count that can still win: score (total + a1) + a2 must stay below best[g]
            # (or equal it with a smaller index); one count more than that loses for sure.
            room = best[g] - a1 - a2
            stop = -1 if not room < 9e18 else max(int(np.floor(room)) + 1, 0)
            total = _sphere_weight(prefix, origin, h, centres[g, s, 0], centres[g, s, 1], centres[g, s, 2], r, stop)
            score = (float(total) + a1) + a2
            if score > best[g] or (score == best[g] and s > best_idx[g]):
                continue
            best[g] = score
            best_idx[g] = s
            best_count[g] = total
    return best_idx, best, best_count


class OutsideBand:
    """The outside band of a closed mesh ((n, 3) float64 mm, (m, 3) int) as a counting grid.

    `voxel_mm` is the finest spacing; it grows on huge meshes so the grid stays under `max_voxels`.
    An irrational shift keeps voxel centres off the mesh's own (often round-numbered) coordinates.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, *, voxel_mm: float, max_voxels: int,
                 band_mm: float, fine_mm: float):
        lo, hi = vertices.min(axis=0) - band_mm, vertices.max(axis=0) + band_mm
        h = max(voxel_mm, float(np.prod(hi - lo) / max_voxels) ** (1 / 3))
        shape = tuple(int(n) for n in np.ceil((hi - lo) / h).astype(np.int64) + 1)
        self.origin = lo - h * 0.318309886
        self.voxel = h
        inside = CrossingIndex(vertices, faces).voxels(self.origin, h, shape)
        dist = ndimage.distance_transform_edt(~inside) * h
        weight = np.where(~inside & (dist <= fine_mm), 1, 0).astype(np.int32)
        coarse = ~inside & (dist > fine_mm) & (dist <= band_mm)
        coarse[1::2] = False
        coarse[:, 1::2] = False
        coarse[:, :, 1::2] = False
        weight[coarse] = 8
        # A column's sum is at most 8 per voxel: int16 holds it on any tooth's grid (a quarter of
        # int64's memory traffic, and the grid stays in cache longer), int32 on longer columns
        kind = np.int16 if 8 * shape[2] <= np.iinfo(np.int16).max else np.int32
        self.prefix = np.zeros((shape[0], shape[1], shape[2] + 1), dtype=kind)
        np.cumsum(weight, axis=2, out=self.prefix[:, :, 1:])

    def count(self, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Outside volume of spheres, (n, 3) and (n,) mm, in fine voxels: (n,) int64."""
        centres = np.ascontiguousarray(centres, dtype=np.float64).reshape(-1, 3)
        radii = np.ascontiguousarray(radii, dtype=np.float64).ravel()
        return _count_in_spheres(self.prefix, self.origin, self.voxel, centres, radii)

    def best(self, centres: np.ndarray, radii: np.ndarray, add1: np.ndarray, add2: np.ndarray,
             bound: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per group of candidate spheres, centres (G, C, 3) and radii (G, C) mm: the index, score and
        count of the first minimiser of (count + add1) + add2 ((G, C) each) strictly below `bound`
        (G,) (default: no bound); index -1, the bound and count -1 where none is below. As `count`
        and an argmin, without counting the candidates that cannot win to the end."""
        g_n, c_n = np.shape(radii)
        bound = np.full(g_n, np.inf) if bound is None else np.ascontiguousarray(bound, dtype=np.float64)
        return _best_in_groups(self.prefix, self.origin, self.voxel,
                               np.ascontiguousarray(centres, dtype=np.float64).reshape(g_n, c_n, 3),
                               np.ascontiguousarray(radii, dtype=np.float64),
                               np.ascontiguousarray(add1, dtype=np.float64), np.ascontiguousarray(add2, dtype=np.float64),
                               bound)

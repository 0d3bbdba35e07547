"""How well a sphere tree fits its tooth: sphere outside volume (SOV) and coverage, by Monte Carlo.

The paper's approximation error is the relative SOV of the leaves: the volume inside the leaf
spheres but outside the tooth, over the tooth's volume. Its summed form adds each sphere's own
outside volume (so space where spheres overlap counts twice or more); the union form counts the
outside part of the union once. Both come from the same samples: n_i points uniform in each leaf
sphere i (n_i proportional to its volume). With m(x) the number of leaf spheres holding x and
out(x) = 1 outside the tooth,
    summed = sum_i V_i mean_i[out],   union = sum_i V_i mean_i[out / m]
(the second is the standard estimator of a union's volume from its members' volumes). Standard
errors come from the per-sphere sample variances. Coverage is the share of surface samples
(uniform by area) and of interior samples that lie in at least one leaf sphere.
Volumes in mm^3, ratios dimensionless.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from orthosim.spheretree.inside import Solid
from orthosim.spheretree.tree import SphereTree


@dataclass(frozen=True)
class FitReport:
    """The figures of one tree against its tooth (SOV relative to the tooth's volume)."""

    leaves: int
    sov_sum: float
    sov_sum_stderr: float
    sov_union: float
    sov_union_stderr: float
    surface_coverage: float  # share of `surface_samples` inside some leaf sphere
    surface_samples: int
    interior_coverage: float  # share of `interior_samples` inside some leaf sphere
    interior_samples: int
    tooth_volume_mm3: float
    sphere_samples: int


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Enclosed volume of a closed, outward-oriented mesh, mm^3 (divergence theorem)."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def uniform_in_balls(centers: np.ndarray, radii: np.ndarray, counts: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
    """counts[i] points uniform in ball i: (sum counts, 3) mm and (sum counts,) ball index."""
    owner = np.repeat(np.arange(len(radii)), counts)
    d = rng.normal(size=(len(owner), 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    rad = radii[owner] * rng.random(len(owner)) ** (1 / 3)
    return centers[owner] + d * rad[:, None], owner


def count_holding(points: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(p, 3) points and spheres, mm -> (p,) int: how many of the spheres hold each point."""
    tree = cKDTree(points)
    hits = tree.query_ball_point(centers, radii)
    flat = np.concatenate([np.asarray(h, dtype=np.int64) for h in hits]) if len(hits) else np.zeros(0, np.int64)
    return np.bincount(flat, minlength=len(points))


def surface_samples(vertices: np.ndarray, faces: np.ndarray, n: int, rng) -> np.ndarray:
    """n points uniform by area on the mesh surface, (n, 3) mm."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    f = rng.choice(len(tri), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[f]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def measure_tree(
    tree: SphereTree,
    vertices: np.ndarray,
    faces: np.ndarray,
    sphere_samples: int = 400_000,
    n_surface: int = 200_000,
    n_interior: int = 100_000,
    seed: int = 0,
    solid: Solid | None = None,
) -> FitReport:
    """SOV (summed and union, with standard errors) and coverage of the tree's leaves on the mesh."""
    rng = np.random.default_rng(seed)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    solid = solid or Solid(vertices, faces)
    volume = mesh_volume(vertices, faces)
    c, r = tree.leaf_centers, tree.leaf_radii
    ball_volume = 4.0 / 3.0 * np.pi * r**3
    counts = np.maximum(np.round(sphere_samples * ball_volume / ball_volume.sum()).astype(np.int64), 30)
    pts, owner = uniform_in_balls(c, r, counts, rng)
    out = ~solid.contains(pts)
    m = count_holding(pts, c, r)
    m = np.maximum(m, 1)  # a sample sits in its own sphere; guards float rounding at the rim

    def estimate(values: np.ndarray) -> tuple[float, float]:
        mean = np.bincount(owner, weights=values, minlength=len(r)) / counts
        sq = np.bincount(owner, weights=values**2, minlength=len(r)) / counts
        var = np.maximum(sq - mean**2, 0) / np.maximum(counts - 1, 1)
        return float((ball_volume * mean).sum()), float(np.sqrt((ball_volume**2 * var).sum()))

    s_sum, e_sum = estimate(out.astype(np.float64))
    s_union, e_union = estimate(out / m)
    surf = surface_samples(vertices, faces, n_surface, rng)
    surface_cov = float((count_holding(surf, c, r) > 0).mean())
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    interior = np.zeros((0, 3))
    while len(interior) < n_interior:
        p = rng.uniform(lo, hi, size=(n_interior, 3))
        interior = np.concatenate([interior, p[solid.contains(p)]])
    interior = interior[:n_interior]
    interior_cov = float((count_holding(interior, c, r) > 0).mean())
    return FitReport(
        leaves=tree.n_leaves,
        sov_sum=s_sum / volume,
        sov_sum_stderr=e_sum / volume,
        sov_union=s_union / volume,
        sov_union_stderr=e_union / volume,
        surface_coverage=surface_cov,
        surface_samples=n_surface,
        interior_coverage=interior_cov,
        interior_samples=n_interior,
        tooth_volume_mm3=volume,
        sphere_samples=int(counts.sum()),
    )

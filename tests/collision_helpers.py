"""Test helpers for the collision tests: a small conservative sphere-tree builder, test shapes, data paths.

`median_split_tree` stands in for the project's builder where a test wants a tree independent of
it: faces are split recursively at the median of their centroids along the longest axis, three
times per level (8 children); each sphere is centred on its faces' vertex mean with the largest
vertex distance as radius, so it holds every face below it.
"""

from __future__ import annotations


import numpy as np
import trimesh

from orthosim.exchange.shareddata import open_full_jaw_dir
from orthosim.spheretree.tree import SphereTree

REAL_MAXILLA = open_full_jaw_dir("maxilla")


def _sphere(tri: np.ndarray) -> tuple[np.ndarray, float]:
    pts = tri.reshape(-1, 3)
    c = pts.mean(axis=0)
    return c, float(np.linalg.norm(pts - c, axis=1).max()) * (1 + 1e-12) + 1e-12


def _split8(centroids: np.ndarray, faces: np.ndarray) -> list[np.ndarray]:
    groups = [faces]
    for _ in range(3):
        nxt = []
        for g in groups:
            if len(g) < 2:
                nxt.append(g)
                continue
            c = centroids[g]
            axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
            order = g[np.argsort(c[:, axis], kind="stable")]
            half = len(order) // 2
            nxt += [order[:half], order[half:]]
        groups = nxt
    return [g for g in groups if len(g)]


def median_split_tree(mesh: trimesh.Trimesh, depth: int = 4) -> SphereTree:
    tri = mesh.triangles
    centroids = tri.mean(axis=1)
    level_groups = [[np.arange(len(mesh.faces))]]
    parents = [np.array([-1])]
    for _ in range(1, depth):
        groups, par = [], []
        for i, g in enumerate(level_groups[-1]):
            kids = _split8(centroids, g)
            groups += kids
            par += [i] * len(kids)
        level_groups.append(groups)
        parents.append(np.array(par, dtype=np.int64))
    centers, radii = [], []
    for groups in level_groups:
        cs, rs = zip(*(_sphere(tri[g]) for g in groups))
        centers.append(np.array(cs))
        radii.append(np.array(rs))
    leaf_of_face = np.empty(len(mesh.faces), np.int64)
    for i, g in enumerate(level_groups[-1]):
        leaf_of_face[g] = i
    return SphereTree(8, tuple(centers), tuple(radii), tuple(parents), leaf_of_face, method="median-split(test)")


def real_tooth_meshes(numbers=(3, 4, 5, 6, 7, 8)) -> list[trimesh.Trimesh]:
    """Real upper teeth (Universal numbers), each centred on its bounding-box centre; skips if absent."""
    import pytest

    if not REAL_MAXILLA.exists():
        pytest.skip("real tooth meshes not present")
    out = []
    for n in numbers:
        m = trimesh.load(REAL_MAXILLA / f"tooth_{n}.stl")
        m.apply_translation(-m.bounds.mean(axis=0))
        out.append(m)
    return out


def thin_root_mesh(length: float = 14.0, radius: float = 0.4) -> trimesh.Trimesh:
    """A thin cylinder along local y (a thin root, mm), origin at its centre."""
    m = trimesh.creation.cylinder(radius=radius, height=length, sections=12)
    m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    return m


def crown_like_mesh(seed: int = 0, subdivisions: int = 2) -> trimesh.Trimesh:
    """A bumpy closed blob about 8 mm across (a stand-in crown), origin near its centre."""
    rng = np.random.default_rng(seed)
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=4.0)
    v = m.vertices
    bump = 1 + 0.15 * np.sin(3 * v[:, 0] + rng.uniform(0, 6)) * np.cos(2 * v[:, 1] + rng.uniform(0, 6))
    m.vertices = v * bump[:, None] * np.array([1.0, 1.3, 0.9])
    return m

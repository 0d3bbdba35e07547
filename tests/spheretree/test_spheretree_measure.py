"""The fit figures are right: SOV against cases with a known answer, and the inside test it rests on."""

from __future__ import annotations

import numpy as np
import trimesh

from orthosim.spheretree import SphereTree, measure_tree
from orthosim.spheretree.inside import CrossingIndex, Solid
from orthosim.spheretree.measure import mesh_volume


def _tree_of(centers, radii, n_faces) -> SphereTree:
    """A two-level tree: one root holding everything, the given spheres as its leaves."""
    centers, radii = np.asarray(centers, float), np.asarray(radii, float)
    root_r = float((np.linalg.norm(centers - centers.mean(0), axis=1) + radii).max())
    return SphereTree(8, (centers.mean(0)[None], centers), (np.array([root_r]), radii),
                      (np.array([-1]), np.zeros(len(radii), np.int64)), np.zeros(n_faces, np.int64), "test")


def test_sov_of_the_sphere_around_a_cube_is_the_known_ratio():
    """A cube of side 2 in its circumsphere: outside volume / cube volume = (sqrt(3) pi / 2) - 1."""
    cube = trimesh.creation.box((2.0, 2.0, 2.0))
    tree = _tree_of([[0.0, 0.0, 0.0]], [np.sqrt(3.0)], len(cube.faces))
    rep = measure_tree(tree, cube.vertices, cube.faces, sphere_samples=200_000, n_surface=100_000, n_interior=20_000)
    expected = np.sqrt(3.0) * np.pi / 2.0 - 1.0  # 1.7207
    assert abs(rep.sov_sum - expected) < 4 * rep.sov_sum_stderr + 1e-12
    assert abs(rep.sov_union - expected) < 4 * rep.sov_union_stderr + 1e-12
    assert rep.sov_sum_stderr < 0.01
    assert rep.surface_coverage == 1.0 and rep.interior_coverage == 1.0


def test_summed_sov_counts_overlaps_twice_and_the_union_once():
    cube = trimesh.creation.box((2.0, 2.0, 2.0))
    tree = _tree_of([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], [np.sqrt(3.0)] * 2, len(cube.faces))
    rep = measure_tree(tree, cube.vertices, cube.faces, sphere_samples=200_000, n_surface=100_000, n_interior=20_000)
    expected = np.sqrt(3.0) * np.pi / 2.0 - 1.0
    assert abs(rep.sov_sum - 2 * expected) < 4 * rep.sov_sum_stderr
    assert abs(rep.sov_union - expected) < 4 * rep.sov_union_stderr + 1e-9


def test_coverage_sees_an_uncovered_corner():
    """A sphere that misses the cube's corners must not report full coverage."""
    cube = trimesh.creation.box((2.0, 2.0, 2.0))
    tree = _tree_of([[0.0, 0.0, 0.0]], [1.5], len(cube.faces))  # corners are sqrt(3) = 1.73 away
    rep = measure_tree(tree, cube.vertices, cube.faces, sphere_samples=50_000, n_surface=100_000, n_interior=20_000)
    assert rep.surface_coverage < 1.0 and rep.interior_coverage < 1.0


def test_inside_test_agrees_with_the_geometry_on_rays_through_edges_and_vertices():
    """Query columns through the cube's shared triangle edges and corners still count one crossing."""
    cube = trimesh.creation.box((2.0, 2.0, 2.0))  # faces split along diagonals through (0, 0)
    g = np.linspace(-1.5, 1.5, 13)  # includes -1, 0, 1: edges and vertices of the box
    pts = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    inside = CrossingIndex(cube.vertices, cube.faces).contains_exact(pts)
    strictly = np.all(np.abs(pts) < 1.0, axis=1)
    on_or_in = np.all(np.abs(pts) <= 1.0, axis=1)
    assert inside[strictly].all()
    assert not inside[~on_or_in].any()


def test_solid_matches_the_exact_ray_test_and_the_volume():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=3.0)
    rng = np.random.default_rng(3)
    pts = rng.uniform(-3.2, 3.2, size=(60_000, 3))
    solid = Solid(mesh.vertices, mesh.faces, spacing=0.15)
    fast = solid.contains(pts)
    exact = CrossingIndex(mesh.vertices, mesh.faces).contains_exact(pts)
    assert (fast == exact).all()
    share = fast.mean() * 6.4**3
    assert abs(share - mesh_volume(mesh.vertices, mesh.faces)) < 0.03 * share
    assert abs(mesh_volume(mesh.vertices, mesh.faces) - mesh.volume) < 1e-9

"""The interpenetration depth on every point of the triangles (`orthosim.geometry.penetration`): two
teeth at the same place and edges crossing edges read a real depth, where the vertex-based measure
reads 0; never below the vertex-based value; agrees with dense sampling by an independent signed
distance (trimesh's)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import trimesh

from orthosim.geometry import meshquery
from orthosim.geometry.penetration import DEPTH_TOLERANCE_MM, edge_penetration_depth, penetration_depth

I4 = np.eye(4)


def _rotation(angle: float, axis) -> np.ndarray:
    return trimesh.transformations.rotation_matrix(angle, axis)


def _tooth() -> trimesh.Trimesh:
    """A single-rooted tooth's size: a capsule 6 mm thick, 20 mm long."""
    return trimesh.creation.capsule(height=14.0, radius=3.0, count=[16, 16])


@pytest.mark.parametrize("mesh, half_thickness", [
    (_tooth(), 3.0),
    (trimesh.creation.box((2.0, 4.0, 6.0)), 1.0),
    (trimesh.creation.icosphere(3, 2.0), 2.0),
])
def test_two_teeth_at_the_same_place_read_about_half_their_thickness(mesh, half_thickness):
    assert meshquery.penetration_depth(mesh, I4, mesh, I4) == 0.0  # every vertex on the other's surface
    depth = penetration_depth(mesh, I4, mesh.copy(), I4)
    # the largest ball inside a faceted solid is a little smaller than inside the smooth one
    assert 0.95 * half_thickness <= depth <= half_thickness + 1e-9


def test_a_nearly_coincident_copy_reads_about_half_the_thickness_too():
    tooth = _tooth()
    shifted = trimesh.transformations.translation_matrix([0.05, -0.02, 0.1]) @ _rotation(0.01, [0, 0, 1])
    depth = penetration_depth(tooth, I4, tooth, shifted)
    assert 2.8 < depth <= 3.0


def _ridges(sunk: float) -> tuple[trimesh.Trimesh, np.ndarray, np.ndarray]:
    """Two long square bars turned 45 degrees about their axes, one along x with its edge up, one
    along y with its edge down, crossing at right angles with the edges sunk `sunk` into each other."""
    bar = trimesh.creation.box((10.0, 2.0, 2.0))
    half_diagonal = np.sqrt(2.0)
    lower = _rotation(np.pi / 4, [1, 0, 0])
    lower[2, 3] = -half_diagonal
    upper = _rotation(np.pi / 2, [0, 0, 1]) @ _rotation(np.pi, [1, 0, 0]) @ _rotation(np.pi / 4, [1, 0, 0])
    upper[2, 3] = half_diagonal - sunk
    return bar, lower, upper


@pytest.mark.parametrize("sunk", [0.1, 0.3, 0.6])
def test_crossed_ridges_read_their_depth_over_root_two_where_no_vertex_is_inside(sunk):
    bar, lower, upper = _ridges(sunk)
    assert meshquery.penetration_depth(bar, lower, bar, upper) == 0.0
    depth = penetration_depth(bar, lower, bar, upper)
    truth = sunk / np.sqrt(2.0)  # each ridge point's distance to the other bar's faces at 45 degrees
    assert truth - DEPTH_TOLERANCE_MM <= depth <= truth + 1e-9
    # the ridges are edges: the measure on vertices and edges a simulation step asks reads them too
    assert truth - DEPTH_TOLERANCE_MM <= edge_penetration_depth(bar, lower, bar, upper) <= truth + 1e-9


def test_meshes_apart_or_just_touching_read_zero():
    tooth = _tooth()
    assert penetration_depth(tooth, I4, tooth, trimesh.transformations.translation_matrix([6.5, 0, 0])) == 0.0
    assert penetration_depth(tooth, I4, tooth, trimesh.transformations.translation_matrix([40.0, 0, 0])) == 0.0


def _sampled_depth(mesh_a, pose_a, mesh_b, pose_b, count: int, seed: int) -> float:
    """The deepest of `count` points sampled on each surface inside the other, by trimesh's signed
    distance (ray-cast inside test, its own closest points): an independent lower bound of the truth."""
    deepest = 0.0
    for m1, T1, m2, T2 in ((mesh_a, pose_a, mesh_b, pose_b), (mesh_b, pose_b, mesh_a, pose_a)):
        points, _ = trimesh.sample.sample_surface(m1, count, seed=seed)
        M = np.linalg.solve(T2, T1)
        points = points @ M[:3, :3].T + M[:3, 3]
        lo, hi = m2.bounds
        points = points[np.all((points >= lo) & (points <= hi), axis=1)]
        if len(points):
            deepest = max(deepest, float(trimesh.proximity.signed_distance(m2, points).max()))
    return deepest


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_agrees_with_dense_sampling_and_is_never_below_the_vertex_depth(seed):
    rng = np.random.default_rng(seed)
    tooth = trimesh.creation.icosphere(2, 3.0)  # coarse facets: vertices miss the deepest points
    pose_b = _rotation(rng.uniform(0, np.pi), rng.normal(size=3))  # facets meeting at random
    pose_b[:3, 3] = [5.6, 0.0, 0.0]  # two 3 mm spheres, centres 5.6 mm apart
    depth = penetration_depth(tooth, I4, tooth, pose_b)
    vertex = meshquery.penetration_depth(tooth, I4, tooth, pose_b)
    sampled = _sampled_depth(tooth, I4, tooth, pose_b, 20_000, seed)
    assert depth >= vertex - 1e-9
    assert depth >= sampled - DEPTH_TOLERANCE_MM - 1e-9  # never more than the tolerance below any point found
    # sampled points 20,000 to a surface of 113 mm^2 lie within about 0.1 mm of every point
    assert depth <= sampled + 0.1
    assert depth > 0.1  # the spheres overlap by about 0.4 mm less the facets' sag


@pytest.mark.parametrize("seed", [4, 5, 6])
def test_the_edge_measure_lies_between_the_vertex_measure_and_the_whole_one(seed):
    rng = np.random.default_rng(seed)
    tooth, bar = trimesh.creation.icosphere(2, 3.0), trimesh.creation.box((8.0, 1.5, 1.5))
    pose = _rotation(rng.uniform(0, np.pi), rng.normal(size=3))
    pose[:3, 3] = rng.normal(size=3) * 0.3 + [3.2, 0.0, 0.0]  # the bar's end sunk into the sphere
    vertex = meshquery.penetration_depth(tooth, I4, bar, pose)
    edges = edge_penetration_depth(tooth, I4, bar, pose)
    whole = penetration_depth(tooth, I4, bar, pose)
    assert whole > 0.05
    assert vertex - 1e-9 <= edges <= whole + 1e-9
    # the same, both meshes' roles swapped
    assert edge_penetration_depth(bar, pose, tooth, I4) == pytest.approx(edges, abs=DEPTH_TOLERANCE_MM)


def test_neither_the_drawing_side_nor_the_interpenetration_module_imports_it_or_numba_eagerly():
    code = ("import sys\n"
            "import orthosim_render.timeline, orthosim.collision.interpenetration, orthosim.geometry, orthosim.geometry.motion\n"
            "light = ('orthosim.collision', 'orthosim.collision.detectors', 'orthosim.collision.interpenetration')\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'numba'"
            " or m in ('orthosim.geometry.penetration', 'orthosim.geometry.signeddistance')"
            " or (m.startswith('orthosim.collision') and m not in light)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"

"""A run that has not compiled numba's kernels yet answers signed distances and interpenetration
depths in numpy, and gets the very numbers the kernels give (`orthosim.geometry.signeddistance`,
`orthosim.geometry.penetration`): on the paper's teeth, at random poses, every distance, every
closest face, every hierarchy array and every depth is bit for bit the compiled one. So whether a
run compiles (and when) never changes its results."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from orthosim.collision import candidate_pairs
from orthosim.geometry import penetration, signeddistance
from orthosim.geometry.signeddistance import (LEAF_FACES, build_hierarchy, build_hierarchy_numpy, mesh_surface,
                                              signed_distances, signed_distances_numpy)
from orthosim.model.parametric import parametric_dentition


@pytest.fixture(scope="module")
def paper_teeth():
    return parametric_dentition("smooth")


def _turn(rng, degrees: float) -> np.ndarray:
    """A rigid transform: a random rotation of up to `degrees` about a random axis."""
    axis = rng.normal(size=3)
    return trimesh.transformations.rotation_matrix(np.radians(rng.uniform(-degrees, degrees)), axis / np.linalg.norm(axis))


@pytest.mark.slow
def test_the_hierarchy_built_in_numpy_is_the_compiled_one(paper_teeth):
    for fdi in (11, 16, 33, 47):
        tri = np.asarray(paper_teeth.teeth[fdi].mesh.triangles, float)
        centroids = tri.mean(axis=1)
        radii = np.linalg.norm(tri - centroids[:, None, :], axis=2).max(axis=1)
        args = (centroids, radii, tri.min(axis=1), tri.max(axis=1), LEAF_FACES)
        for compiled, in_numpy in zip(build_hierarchy(*args), build_hierarchy_numpy(*args)):
            assert compiled.dtype == in_numpy.dtype
            assert np.array_equal(compiled, in_numpy)


@pytest.mark.slow
def test_signed_distances_in_numpy_are_the_compiled_ones(paper_teeth):
    """Points near the surface (vertices and face centres, jittered by up to 1 mm, so that closest
    corners and edges, shared by several faces, come up often), deep inside and far away, on the
    mesh as built and moved; with and without a cap."""
    rng = np.random.default_rng(42)
    for fdi in (13, 26, 36, 44):
        surface = mesh_surface(paper_teeth.teeth[fdi].mesh)
        V = surface.arrays.vertices
        centres = surface.arrays.triangles.mean(axis=1)
        points = np.concatenate([V, V + rng.uniform(-1, 1, V.shape), centres + rng.uniform(-0.2, 0.2, centres.shape),
                                 rng.uniform(V.min(axis=0) - 5, V.max(axis=0) + 5, (500, 3))])
        moved = surface.moved(_turn(rng, 20.0) @ trimesh.transformations.translation_matrix(rng.normal(size=3)))
        for arrays in (surface.arrays, moved):
            for cap in (np.inf, 0.5):
                d, f = signed_distances(points, arrays, cap)
                d_np, f_np = signed_distances_numpy(points, arrays, cap)
                assert np.array_equal(f, f_np)
                assert np.array_equal(d, d_np)
                assert np.array_equal(np.signbit(d), np.signbit(d_np))


def test_one_point_at_a_time_in_python_floats_is_the_compiled_query_on_every_copy_of_a_surface(paper_teeth):
    """The one-point form reads a plain copy of a surface's hierarchy, kept between queries: asked in
    turn about two teeth, a moved copy (other corners, normals and spheres) and a copy whose spheres
    alone were placed elsewhere (the depth's `_replace(node_center=...)`), each answers from its own
    arrays, as the compiled query does; a copy made anew for every query too."""
    rng = np.random.default_rng(3)
    first, second = mesh_surface(paper_teeth.teeth[21].mesh), mesh_surface(paper_teeth.teeth[36].mesh)
    moved = first.moved(_turn(rng, 20.0) @ trimesh.transformations.translation_matrix(rng.normal(size=3)))
    placed = first.arrays._replace(node_center=np.ascontiguousarray(moved.node_center))
    V = first.arrays.vertices
    points = np.concatenate([V[::25], V[::25] + rng.uniform(-1, 1, V[::25].shape)])  # vertices: faces tied
    for _ in range(2):
        for arrays in (first.arrays, second.arrays, moved, placed, first.arrays._replace()):
            d, f = signed_distances(points, arrays, np.inf)
            answers = [signeddistance.signed_distance_scalar(p, arrays, np.inf) for p in points]
            assert np.array_equal(f, [face for _, face in answers])
            assert np.array_equal(d, [distance for distance, _ in answers])
            assert np.array_equal(np.signbit(d), np.signbit([distance for distance, _ in answers]))


def _pushed_together(rng, teeth, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Rest pose of a, and b moved a random part of the way onto a and turned a few degrees."""
    pose_a, pose_b = teeth[a].rest_pose, teeth[b].rest_pose.copy()
    pose_b[:3, 3] += rng.uniform(0.0, 0.3) * (pose_a[:3, 3] - pose_b[:3, 3]) + rng.normal(scale=0.2, size=3)
    return pose_a, (pose_b @ _turn(rng, 3.0) if rng.random() < 0.5 else pose_b)


@pytest.mark.slow
def test_interpenetration_depths_in_numpy_are_the_compiled_ones(paper_teeth, monkeypatch):
    """A step's measure (vertices and edges) on neighbouring and facing teeth pushed into each other
    at random poses; the full measure (faces and the ball inside both) on a few of them."""
    rng = np.random.default_rng(7)
    teeth = paper_teeth.teeth
    pairs = candidate_pairs(paper_teeth.fdis)
    cases = [(a, b, *_pushed_together(rng, teeth, a, b)) for a, b in pairs for _ in range(2)]

    def depths(measure, compiled: bool, chosen):
        monkeypatch.setattr(penetration, "compiled_pays_for", lambda faces, *kernels: compiled)
        return [measure(teeth[a].mesh, pa, teeth[b].mesh, pb) for a, b, pa, pb in chosen]

    edge = depths(penetration.edge_penetration_depth, True, cases)
    assert sum(d > 0.05 for d in edge) >= 10  # the poses do interpenetrate, some deeply
    assert edge == depths(penetration.edge_penetration_depth, False, cases)
    some = [cases[i] for i in np.argsort(edge)[-3:]] + [cases[0]]
    assert depths(penetration.penetration_depth, True, some) == depths(penetration.penetration_depth, False, some)


def test_a_process_answers_in_numpy_until_compiling_pays(monkeypatch):
    monkeypatch.setattr(signeddistance, "_preferred", [])
    monkeypatch.setattr(signeddistance, "_numpy_seconds", [0.0])
    monkeypatch.setattr(signeddistance, "PAYS_AFTER_S", 1e-9)
    monkeypatch.setattr("orthosim.system.firstrun.in_numba_cache", lambda *kernels: False)
    monkeypatch.setattr("orthosim.storage.numpytally.carried", lambda *counter: 0.0)  # no earlier run spent any
    assert not signeddistance.compiled_pays(signed_distances)
    points = np.random.default_rng(1).normal(size=(101, 3))
    signed_distances_numpy(points, mesh_surface(trimesh.creation.icosphere(1, 1.0)).arrays, np.inf)
    assert signeddistance.compiled_pays(signed_distances)  # numpy has cost what compiling would: now compiling pays
    monkeypatch.setattr(signeddistance, "_numpy_seconds", [0.0])
    signeddistance.prefer_compiled()
    assert signeddistance.compiled_pays(signed_distances)


def test_a_large_mesh_compiles_at_once_and_the_demos_teeth_wait_until_it_pays(paper_teeth, monkeypatch):
    """The numpy forms' cost grows with the mesh (branch and bound replayed point by point in
    Python): a real tooth of about 40,000 faces compiles at once (a real jaw's rest interpenetration:
    213 s in numpy against 25 s compiled), while the parametric teeth the demo runs on stay on numpy
    until it pays."""
    monkeypatch.setattr(signeddistance, "_preferred", [])
    monkeypatch.setattr(signeddistance, "_numpy_seconds", [0.0])
    monkeypatch.setattr("orthosim.system.firstrun.in_numba_cache", lambda *kernels: False)
    monkeypatch.setattr("orthosim.storage.numpytally.carried", lambda *counter: 0.0)
    largest = max(len(t.mesh.faces) for t in paper_teeth.teeth.values())
    assert largest <= signeddistance.NUMPY_AT_MOST_FACES
    assert not signeddistance.compiled_pays_for(largest, signed_distances)
    assert signeddistance.compiled_pays_for(40_000, signed_distances)
    chosen = []
    monkeypatch.setattr(penetration, "_facing", lambda *args: chosen.append(args[-1]) or [])
    big = trimesh.creation.icosphere(subdivisions=6, radius=5.0)  # 81,920 faces
    small = trimesh.creation.icosphere(subdivisions=3, radius=5.0)  # 1,280 faces
    for measure in (penetration.penetration_depth, penetration.edge_penetration_depth):
        measure(small, np.eye(4), small, np.eye(4))
        measure(small, np.eye(4), big, np.eye(4))
    assert chosen == [False, True, False, True]  # compiled (True) only where a mesh is large

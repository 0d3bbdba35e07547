"""Signed distance from points to a closed mesh (`orthosim.geometry.signeddistance`): the exact
distance to the nearest triangle, agreeing with trimesh's closest points; negative exactly inside;
unresolved (+inf) beyond the cap; the same whether the points or the mesh are moved."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from orthosim.geometry.signeddistance import mesh_surface


def _tooth() -> trimesh.Trimesh:
    """A single-rooted tooth's size: a capsule 6 mm thick, 20 mm long."""
    return trimesh.creation.capsule(height=14.0, radius=3.0, count=[16, 16])


def test_each_face_names_its_own_three_edges():
    tooth = _tooth()
    surface = mesh_surface(tooth)
    for f in (0, 7, len(tooth.faces) - 1):
        own = {frozenset(e) for e in surface.edges[surface.face_edges[f]].tolist()}
        a, b, c = tooth.faces[f].tolist()
        assert own == {frozenset((a, b)), frozenset((b, c)), frozenset((c, a))}
    assert len(surface.edges) == len(tooth.edges_unique)


def test_a_mesh_has_an_inside_only_when_closed_and_consistently_wound():
    box = trimesh.creation.box((2.0, 4.0, 6.0))
    holed = trimesh.Trimesh(box.vertices, box.faces[1:], process=False)
    flipped = trimesh.Trimesh(box.vertices, np.vstack([box.faces[:1, ::-1], box.faces[1:]]), process=False)
    assert mesh_surface(box).closed and mesh_surface(_tooth()).closed
    assert not mesh_surface(holed).closed and not mesh_surface(flipped).closed


def test_the_inside_test_is_the_sign_of_the_closest_feature_normal():
    box = trimesh.creation.box((2.0, 4.0, 6.0))
    d, _ = mesh_surface(box).signed_distance([[0, 0, 0], [0.9, 0, 0], [1.0, 1.0, 1.0], [1.5, 0, 0], [2.0, 3.0, 4.0]])
    assert d == pytest.approx([-1.0, -0.1, 0.0, 0.5, np.sqrt(1 + 1 + 1)], abs=1e-12)


def test_distances_and_closest_faces_agree_with_trimesh_and_the_sign_with_its_inside_test():
    tooth = _tooth()
    points = np.random.default_rng(3).uniform(-6.0, 6.0, (400, 3)) * [1.0, 1.0, 2.0]
    d, faces = mesh_surface(tooth).signed_distance(points)
    closest, distance, _ = trimesh.proximity.closest_point(tooth, points)
    assert np.abs(d) == pytest.approx(distance, abs=1e-9)
    # the face named holds a closest point
    on_face = trimesh.triangles.closest_point(tooth.triangles[faces], points)
    assert np.linalg.norm(points - on_face, axis=1) == pytest.approx(distance, abs=1e-9)
    assert np.array_equal(d < 0.0, tooth.contains(points))


def test_points_beyond_the_cap_are_unresolved_and_the_rest_unchanged():
    surface = mesh_surface(_tooth())
    points = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [7.0, 0.0, 0.0], [0.0, 0.0, 40.0]])
    whole, _ = surface.signed_distance(points)
    capped, faces = surface.signed_distance(points, cap_mm=5.0)
    assert capped[:3] == pytest.approx(whole[:3], abs=0.0) and whole[:3] == pytest.approx([-3.0, 1.0, 4.0], abs=0.1)
    assert capped[3] == np.inf and faces[3] == -1 and np.all(faces[:3] >= 0)


def test_moving_the_mesh_is_moving_the_points_the_other_way():
    from orthosim.geometry.signeddistance import signed_distances

    surface = mesh_surface(_tooth())
    M = trimesh.transformations.rotation_matrix(0.7, [1.0, 2.0, 0.5])
    M[:3, 3] = [1.0, -2.0, 0.5]
    points = np.random.default_rng(5).uniform(-8.0, 8.0, (200, 3))
    here, _ = signed_distances(points, surface.moved(M), np.inf)
    local = (points - M[:3, 3]) @ M[:3, :3]
    there, _ = surface.signed_distance(local)
    assert here == pytest.approx(there, abs=1e-9)

"""Exact contact areas: the triangles that touch the other tooth, not everything inside the spheres."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from orthosim.collision.contact_area import (ContactSurface, faces_in_spheres, faces_touching_any,
                                             triangle_distances)
from orthosim.spheretree import build_sphere_tree


def _sampled_distance(a: np.ndarray, b: np.ndarray, n: int = 60) -> float:
    """Distance between two triangles from dense barycentric samples of both (an upper bound)."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    keep = u + v <= 1
    w = np.stack([1 - u[keep] - v[keep], u[keep], v[keep]], 1)
    pa, pb = w @ a, w @ b
    return float(np.min(np.linalg.norm(pa[:, None] - pb[None], axis=2)))


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_triangle_distance_is_exact_for_random_pairs_and_zero_for_crossing_ones():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(40, 3, 3))
    b = rng.normal(size=(40, 3, 3)) + rng.normal(scale=2.0, size=(40, 1, 3))
    d = triangle_distances(a, b)
    for i in range(len(a)):
        sampled = _sampled_distance(a[i], b[i])
        assert d[i] <= sampled + 1e-9  # never more than a pair of actual surface points
        if d[i] > 0:
            assert sampled - d[i] < 0.08 * (1 + sampled)  # and close to what dense sampling finds
    flat = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
    assert np.isclose(triangle_distances(flat, flat + [0.1, 0.1, 0.3])[0], 0.3)
    crossing = np.array([[[0.2, 0.2, -1], [0.3, 0.2, 1], [0.2, 0.3, 1]]], float)
    assert triangle_distances(flat, crossing)[0] == 0.0
    # two edges passing 0.25 mm apart, no vertex near the other triangle's face
    e1 = np.array([[[-1, 0, 0], [1, 0, 0], [0, 0, -2]]], float)
    e2 = np.array([[[0, -1, 0.25], [0, 1, 0.25], [0, 0, 2.25]]], float)
    assert np.isclose(triangle_distances(e1, e2)[0], 0.25)


def _ball(x: float) -> trimesh.Trimesh:
    m = trimesh.creation.icosphere(subdivisions=4, radius=3.0)
    m.apply_translation([x, 0, 0])
    return m


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_exact_contact_faces_are_the_triangles_at_the_touch_point_only():
    # two balls 0.02 mm apart: the touching triangles sit around the gap; the leaf spheres that
    # overlap hold far more surface than that
    a, b = _ball(0.0), _ball(6.02)
    sa, sb = ContactSurface(a.vertices, a.faces), ContactSurface(b.vertices, b.faces)
    eye = np.eye(4)
    touching = faces_touching_any(sa, eye, np.arange(len(a.faces)), [(sb, eye)], tolerance_mm=0.05)
    assert len(touching) > 0
    centroid_x = a.triangles_center[touching, 0]
    assert centroid_x.min() > 2.6  # all within a small cap around the touch point (x = 3)
    # every triangle of a within the tolerance of b is found (brute force over the two caps facing
    # each other: anything farther from the gap is over 0.4 mm away)
    near = np.flatnonzero(a.triangles_center[:, 0] > 2.5)
    facing = b.triangles[b.triangles_center[:, 0] < 3.5]
    brute = [f for f in near if triangle_distances(np.repeat(a.triangles[f][None], len(facing), 0), facing).min() <= 0.05]
    assert sorted(brute) == touching.tolist()
    # the sphere-based picture: triangles inside the overlapping leaves of the two trees
    ta, tb = build_sphere_tree(a, "fit", 8, 3), build_sphere_tree(b, "fit", 8, 3)
    ca, ra = ta.leaf_centers, ta.leaf_radii
    cb, rb = tb.leaf_centers, tb.leaf_radii
    overlap = np.linalg.norm(ca[:, None] - cb[None], axis=2) <= ra[:, None] + rb[None]
    ia, ib = np.nonzero(overlap)
    centers = np.concatenate([ca[ia], cb[ib]])
    radii = np.concatenate([ra[ia], rb[ib]])
    in_spheres = faces_in_spheres(sa, eye, centers, radii)
    assert set(touching) <= set(in_spheres.tolist())
    assert len(in_spheres) > 2 * len(touching)
    # and the candidates given by the spheres are enough: the exact filter keeps the same set
    assert faces_touching_any(sa, eye, in_spheres, [(sb, eye)]).tolist() == touching.tolist()


def test_triangles_pushed_inside_the_other_tooth_count_as_contact():
    a, b = _ball(0.0), _ball(5.0)  # 1 mm overlap: the deepest triangles are far from b's surface
    sa, sb = ContactSurface(a.vertices, a.faces), ContactSurface(b.vertices, b.faces)
    eye = np.eye(4)
    touching = faces_touching_any(sa, eye, np.arange(len(a.faces)), [(sb, eye)])
    deepest = int(np.argmax(a.triangles_center[:, 0]))
    assert deepest in touching
    inside = np.linalg.norm(a.triangles_center - [5.0, 0, 0], axis=1) < 3.0
    assert set(np.flatnonzero(inside)) <= set(touching.tolist())


def test_contact_faces_follow_the_poses():
    a = _ball(0.0)
    sa = ContactSurface(a.vertices, a.faces)
    moved = np.eye(4)
    moved[:3, 3] = [6.03, 0, 0]
    rot = trimesh.transformations.rotation_matrix(0.7, [0, 0, 1])
    touching = faces_touching_any(sa, rot, np.arange(len(a.faces)), [(sa, rot @ moved)])
    centres = a.triangles_center[touching]
    assert len(touching) and np.all(centres[:, 0] > 2.6)  # on the side facing +x in a's own frame

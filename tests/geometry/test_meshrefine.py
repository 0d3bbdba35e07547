"""Splitting long edges: the same closed surface, finer where its triangles were long."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from orthosim.geometry.meshrefine import split_long_edges
from orthosim.model.parametric import parametric_dentition


def _check_same_surface(before: trimesh.Trimesh, v: np.ndarray, f: np.ndarray, max_edge: float) -> trimesh.Trimesh:
    after = trimesh.Trimesh(v, f, process=False)
    assert after.is_watertight and after.is_winding_consistent
    assert after.edges_unique_length.max() <= max_edge + 1e-12
    assert after.volume == pytest.approx(before.volume, rel=1e-12)
    assert after.area == pytest.approx(before.area, rel=1e-12)
    # every new vertex lies on the old surface; old vertices keep their indices
    np.testing.assert_array_equal(v[: len(before.vertices)], before.vertices)
    _, dist, _ = trimesh.proximity.closest_point(before, v[len(before.vertices):])
    assert dist.max() < 1e-9
    return after


def test_a_long_box_is_split_to_the_limit_and_keeps_its_volume():
    box = trimesh.creation.box(extents=[12.0, 1.0, 2.0])
    v, f = split_long_edges(box.vertices, box.faces, 0.8)
    after = _check_same_surface(box, v, f, 0.8)
    assert len(after.faces) > 10 * len(box.faces)


def test_short_edges_are_left_alone():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    v, f = split_long_edges(sphere.vertices, sphere.faces, 1.0)
    np.testing.assert_array_equal(v, sphere.vertices)
    np.testing.assert_array_equal(f, sphere.faces)


def test_smooth_parametric_teeth_have_no_edge_over_a_millimetre():
    for tooth in parametric_dentition("smooth").teeth.values():
        assert tooth.mesh.edges_unique_length.max() <= 1.0 + 1e-9, tooth.fdi
        assert tooth.mesh.is_watertight, tooth.fdi


def test_a_split_tooth_is_the_same_solid():
    tooth = parametric_dentition("medium").teeth[36]  # medium teeth are not split by default
    v, f = split_long_edges(tooth.mesh.vertices, tooth.mesh.faces, 0.7)
    _check_same_surface(tooth.mesh, v, f, 0.7)

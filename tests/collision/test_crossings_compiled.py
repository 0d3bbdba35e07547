"""The compiled inside test (`orthosim.collision.crossings_compiled`) answers as the numpy crossing
count it replaces (`CrossingIndex.contains_exact`) for every point: inside and outside a closed
crown, on its vertices and edges (where the top-left rule decides), outside its buckets, above and
below it."""

from __future__ import annotations

import numpy as np
import trimesh

from orthosim.collision import crossings_compiled
from orthosim.spheretree.inside import CrossingIndex


def _crown() -> trimesh.Trimesh:
    """A closed, bumpy, consistently wound mesh with faces at many slopes (some seen edge-on from z)."""
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=4.0)
    v = sphere.vertices.copy()
    v *= 1.0 + 0.15 * np.sin(3 * v[:, [0]]) * np.cos(2 * v[:, [1]])
    v[:, 2] *= 1.6
    return trimesh.Trimesh(v, sphere.faces, process=False)


def test_every_point_is_answered_as_the_numpy_crossing_count_answers_it():
    mesh = _crown()
    assert mesh.is_watertight and mesh.is_winding_consistent
    index = CrossingIndex(mesh.vertices, mesh.faces)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    rng = np.random.default_rng(7)
    lo, hi = v.min(axis=0), v.max(axis=0)
    points = np.concatenate([
        rng.uniform(lo - 1.0, hi + 1.0, size=(20_000, 3)),  # inside, outside, beyond the buckets
        v + [0.0, 0.0, 0.01], v - [0.0, 0.0, 0.01],  # over and under each vertex: rays through shared corners
        (v[f[:, 0]] + v[f[:, 1]]) / 2 + [0.0, 0.0, 0.005],  # through shared edges
        v[f].mean(axis=1),  # on the surface itself
    ])
    want = index.contains_exact(points)
    got = crossings_compiled.contains(index, points)
    assert got.dtype == np.bool_ and got.shape == want.shape
    assert np.array_equal(got, want)
    assert 0.2 < want[:20_000].mean() < 0.8  # both sides really asked
    assert not crossings_compiled.contains(index, np.zeros((0, 3))).size

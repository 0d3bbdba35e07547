"""The first step's patches kept between runs (`orthosim.collision.patchcache`): a cut read back is
the cut made afresh, bit for bit; every input the cut reads is in its key; an entry that fails any
check gives one warning and is cut again; a folder that cannot be written costs nothing but time."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

from collision_helpers import median_split_tree
from orthosim.collision import Body, CollisionModel, ExactQueries
from orthosim.collision.patchcache import PatchCache, mesh_digest
from orthosim.geometry.pose import translation
from orthosim.storage.cacheentry import DamagedEntryWarning, write_arrays


def _pair():
    """Two spheres 0.2 mm apart along x, fine enough that a patch keeps a part of each."""
    a = trimesh.creation.icosphere(subdivisions=3, radius=3.0)
    b = trimesh.creation.icosphere(subdivisions=3, radius=2.0)
    model = CollisionModel([Body(1, a, median_split_tree(a), np.eye(4)), Body(2, b, median_split_tree(b), np.eye(4))])
    return model, {1: np.eye(4), 2: translation([5.2, 0.1, -0.05])}


def _answers(queries, poses):
    return queries.distance((1, 2), poses), queries.intersects((1, 2), poses), queries._patches[(0, 1)]


def test_a_cut_read_back_is_the_cut_made_afresh(tmp_path):
    model, poses = _pair()
    fresh = ExactQueries(model)
    want = _answers(fresh, poses)
    for _ in range(2):  # the first keeps its cut, the second reads it
        q = ExactQueries(model)
        q.patch_cache = PatchCache(tmp_path)
        got = _answers(q, poses)
        assert got[:2] == want[:2]
        assert np.array_equal(got[2].faces_i, want[2].faces_i) and np.array_equal(got[2].faces_j, want[2].faces_j)
        assert 0 < len(got[2].faces_i) < len(model.bodies[0].mesh.faces)  # a part of the tooth: a real cut
    assert len(list(tmp_path.glob("*.npz"))) == 1
    assert not q._trees  # the second never built a k-d tree


def test_the_key_holds_the_meshes_the_poses_to_the_last_bit_and_the_reach(tmp_path):
    cache = PatchCache(tmp_path)
    M, N = np.eye(4)[:3], np.eye(4)[:3]
    verts, faces = np.eye(3), np.array([[0, 1, 2]])
    base = cache.key(mesh_digest(verts, faces), "b", M, N, 0.5)
    nudged = M.copy()
    nudged[0, 3] = np.nextafter(0.0, 1.0)
    moved_vertex = verts.copy()
    moved_vertex[1, 1] = np.nextafter(0.0, 1.0)
    others = {cache.key(mesh_digest(moved_vertex, faces), "b", M, N, 0.5), cache.key(mesh_digest(verts, faces), "c", M, N, 0.5),
              cache.key(mesh_digest(verts, faces), "b", nudged, N, 0.5), cache.key(mesh_digest(verts, faces), "b", M, nudged, 0.5),
              cache.key(mesh_digest(verts, faces), "b", M, N, 0.25)}
    assert base not in others and len(others) == 5


@pytest.mark.parametrize("stored, problem", [
    ({"faces_i": np.array([0, 5, 10**6]), "faces_j": np.array([1])}, "names faces its mesh does not have"),
    ({"faces_i": np.array([3, 3]), "faces_j": np.array([1])}, "or one twice"),
    ({"faces_i": np.array([[1, 2]]), "faces_j": np.array([1])}, "not a list of face indices"),
    ({"faces_j": np.array([1])}, "not a list of face indices"),
])
def test_an_entry_that_fails_a_check_is_warned_of_once_and_cut_again(tmp_path, stored, problem):
    model, poses = _pair()
    want = _answers(ExactQueries(model), poses)
    q = ExactQueries(model)
    q.patch_cache = PatchCache(tmp_path)
    _answers(q, poses)
    (path,) = tmp_path.glob("*.npz")
    write_arrays(path, "patches", path.stem, stored)  # checksummed, but not a cut of these meshes
    q = ExactQueries(model)
    q.patch_cache = PatchCache(tmp_path)
    with pytest.warns(DamagedEntryWarning, match=problem) as caught:
        got = _answers(q, poses)
    assert len(caught) == 1 and got[:2] == want[:2] and np.array_equal(got[2].faces_i, want[2].faces_i)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # written again: the next run reads it without a word
        q = ExactQueries(model)
        q.patch_cache = PatchCache(tmp_path)
        assert _answers(q, poses)[:2] == want[:2]


def test_a_folder_that_cannot_be_written_costs_only_the_cut(tmp_path):
    model, poses = _pair()
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    q = ExactQueries(model)
    q.patch_cache = PatchCache(blocked / "patches")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _answers(q, poses)[:2] == _answers(ExactQueries(model), poses)[:2]

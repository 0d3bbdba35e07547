"""Trees travel: Bradshaw's .sph format both ways, and the on-disk cache returns the very same tree."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from orthosim.errors import SphereTreeError
from orthosim.spheretree import SphereTree, build_sphere_tree, cached_sphere_tree, cached_sphere_trees, read_sph, write_sph
from orthosim.spheretree.cache import cache_key, load_tree, store_entry


def _mesh() -> trimesh.Trimesh:
    return trimesh.creation.capsule(height=8.0, radius=2.5, count=[20, 20])


def _same(a, b) -> None:
    assert a.branching == b.branching and a.depth == b.depth
    for k in range(a.depth):
        np.testing.assert_array_equal(a.centers[k], b.centers[k])
        np.testing.assert_array_equal(a.radii[k], b.radii[k])
        np.testing.assert_array_equal(a.parents[k], b.parents[k])


@pytest.mark.parametrize("method,depth", [("fit", 4), ("octree", 5)])
def test_sph_round_trip_is_exact_and_stays_conservative(tmp_path, method, depth):
    mesh = _mesh()
    tree = build_sphere_tree(mesh, method=method, depth=depth)
    path = tmp_path / "11.sph"
    write_sph(tree, path)
    lines = path.read_text().splitlines()
    B = tree.branching  # the default: 9 for fit, 8 for octree
    assert lines[0].split() == [str(depth), str(B)]
    assert len(lines) == 1 + sum(B**k for k in range(depth))  # every slot of the complete tree
    back = read_sph(path, mesh.vertices, mesh.faces)
    _same(tree, back)
    assert (back.leaf_of_face >= 0).all()
    back.validate(mesh.vertices, mesh.faces)
    assert len(read_sph(path).leaf_of_face) == 0  # without a mesh, no faces to assign


def test_bradshaw_file_with_absent_and_childless_nodes(tmp_path):
    """Slots with radius <= 0 are absent; a node without children is carried to the leaf level."""
    B = 2
    rows = ["3 2",
            "0 0 0 3 0",  # root
            "-1 0 0 2 0", "1 0 0 2 0",  # level 1: both present
            "-1.5 0 0 1 0", "-0.5 0 0 1 0",  # children of node 1 (slot 1 -> slots 3, 4)
            "0 0 0 0 0", "0 0 0 -1 0"]  # node 2 has no children
    path = tmp_path / "b.sph"
    path.write_text("\n".join(rows) + "\n")
    tree = read_sph(path)
    assert [len(r) for r in tree.radii] == [1, 2, 3]
    np.testing.assert_array_equal(tree.parents[2], [0, 0, 1])
    np.testing.assert_allclose(tree.leaf_centers[2], [1, 0, 0])  # node 2, carried down
    assert tree.branching == B


@pytest.mark.parametrize("text,field", [
    ("", "line 1"),
    ("four 8\n", "line 1"),
    ("2 2\n0 0 0 1 0\n0 0 0 1 0\n", None),  # truncated: needs 3 sphere lines
    ("2 2\n0 0 0 1 0\n0 0 x 1 0\n0 0 0 1 0\n", "line 3"),
    ("2 2\n0 0 0 0 0\n0 0 0 1 0\n0 0 0 1 0\n", "line 2"),  # root missing
])
def test_malformed_sph_files_are_refused_with_the_line(tmp_path, text, field):
    path = tmp_path / "bad.sph"
    path.write_text(text)
    with pytest.raises(SphereTreeError) as err:
        read_sph(path)
    assert str(path) in str(err.value)
    if field:
        assert field in str(err.value)


def test_cache_returns_the_identical_tree(tmp_path):
    mesh = _mesh()
    first = cached_sphere_tree(mesh, cache_dir=tmp_path)
    files = list(tmp_path.glob("*.npz"))
    assert len(files) == 1
    second = cached_sphere_tree(mesh, cache_dir=tmp_path)
    _same(first, second)
    np.testing.assert_array_equal(first.leaf_of_face, second.leaf_of_face)
    assert second.method == "fit"
    # The second call really reads the file: a tree planted under the key (with its checksum) is what
    # comes back. (planted in the stored orientation: a capsule's entry may hold its mirror image's tree)
    stored = load_tree(files[0])
    planted = SphereTree(stored.branching, stored.centers, tuple(r * 2 for r in stored.radii), stored.parents,
                         stored.leaf_of_face, "planted")
    store_entry(planted, files[0])
    third = cached_sphere_tree(mesh, cache_dir=tmp_path)
    assert third.method == "planted"
    np.testing.assert_array_equal(third.leaf_radii, 2 * first.leaf_radii)


def test_cache_key_follows_mesh_and_request(tmp_path):
    mesh = _mesh()
    v, f = mesh.vertices, mesh.faces
    base = cache_key(v, f, "fit", 8, 4)
    assert base == cache_key(v.copy(), f.copy(), "fit", 8, 4)
    assert base != cache_key(v, f, "fit", 8, 3)
    assert base != cache_key(v, f, "octree", 8, 4)
    moved = v.copy()
    moved[0, 0] += 1e-9
    assert base != cache_key(moved, f, "fit", 8, 4)


def test_cache_key_follows_the_builder_source(monkeypatch):
    """An edited builder must never be served a tree its older self stored."""
    from orthosim.spheretree import cache

    mesh = _mesh()
    base = cache_key(mesh.vertices, mesh.faces, "fit", 8, 4)
    monkeypatch.setattr(cache, "builder_source_digest", lambda: "0" * 64)
    assert cache_key(mesh.vertices, mesh.faces, "fit", 8, 4) != base


def test_every_module_the_tree_builders_import_is_part_of_the_cache_key():
    """Every spheretree module a keyed builder module imports (at any depth) is keyed too, and the
    digest reads the files' current text."""
    import ast

    from orthosim.spheretree import cache

    package = Path(cache.__file__).resolve().parent
    keyed = set(cache._BUILDER_MODULES)
    missing = set()
    for name in keyed:
        for node in ast.walk(ast.parse((package / f"{name}.py").read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module and node.module not in keyed:
                missing.add(f"{name} imports {node.module}")
    assert not missing, sorted(missing)
    assert {"build", "fit", "octree"} <= keyed


def test_damaged_cache_entry_is_rebuilt(tmp_path):
    mesh = _mesh()
    tree = cached_sphere_tree(mesh, cache_dir=tmp_path)
    (path,) = tmp_path.glob("*.npz")
    path.write_bytes(b"not a zip file")
    again = cached_sphere_tree(mesh, cache_dir=tmp_path)
    _same(tree, again)
    assert path.stat().st_size > 100


def test_a_tooth_and_its_mirror_image_share_one_cache_entry(tmp_path):
    """Left and right teeth are mirror images: one build serves both, and both trees hold their tooth."""
    mesh = trimesh.creation.capsule(height=8.0, radius=2.5, count=[20, 20])
    v = mesh.vertices + [1.5, 0.3, 0.0]  # off-centre, so the mirror is a different mesh
    f = mesh.faces
    right = cached_sphere_tree((v, f), cache_dir=tmp_path)
    left = cached_sphere_tree((v * [-1, 1, 1], f[:, ::-1]), cache_dir=tmp_path)
    assert len(list(tmp_path.glob("*.npz"))) == 1
    right.validate(v, f)
    left.validate(v * [-1, 1, 1], f[:, ::-1])
    np.testing.assert_array_equal(left.leaf_centers, right.leaf_centers * [-1, 1, 1])
    np.testing.assert_array_equal(left.leaf_radii, right.leaf_radii)


def test_which_of_a_mirror_pair_is_built_does_not_follow_the_builder_source(monkeypatch):
    from orthosim.spheretree import cache

    # an edit of the builder rebuilds the trees, but for the same side of each pair: a tree's mirror
    # is not the tree its mirror image would get, so a swap would change every picture of that pair
    mesh = trimesh.creation.capsule(height=8.0, radius=2.5, count=[20, 20])
    pairs = [((mesh.vertices + [dx, 0.3, 0.0]), mesh.faces) for dx in (-2.0, -1.0, 0.5, 1.5, 2.5)]
    sides = []
    for digest in ("0" * 64, "f" * 64):
        monkeypatch.setattr(cache, "builder_source_digest", lambda d=digest: d)
        sides.append([(cache._entry((v, f), "fit", 8, 4, Path(".")).flip,
                       cache._entry((v * [-1, 1, 1], f[:, ::-1]), "fit", 8, 4, Path(".")).flip) for v, f in pairs])
    assert sides[0] == sides[1]
    assert all(a != b for a, b in sides[0])  # one of each pair is stored, the other is its mirror
    assert len({flip for flip, _ in sides[0]}) == 2  # and the side follows the mesh, not a fixed rule


def test_many_trees_at_once_build_in_parallel_each_distinct_mesh_once(tmp_path):
    """A dentition's trees: parallel builds give the very trees one process gives, in the given order,
    a mirror pair is built once, and the progress callback counts every mesh once."""
    base = trimesh.creation.capsule(height=8.0, radius=2.5, count=[16, 16])
    v, f = base.vertices + [1.5, 0.3, 0.0], base.faces
    other = trimesh.creation.box(extents=[3.0, 5.0, 4.0]).subdivide().subdivide()
    meshes = [(v, f), (other.vertices, other.faces), (v * [-1, 1, 1], f[:, ::-1]), (v, f)]
    done = []
    trees = cached_sphere_trees(meshes, cache_dir=tmp_path / "parallel", workers=2, progress=done.append)
    assert sum(done) == len(meshes)
    assert len(list((tmp_path / "parallel").glob("*.npz"))) == 2  # the capsule, its mirror and its copy share one
    serial = cached_sphere_trees(meshes, cache_dir=tmp_path / "serial", workers=1)
    for a, b, (mv, mf) in zip(trees, serial, meshes):
        _same(a, b)
        a.validate(np.asarray(mv, float), np.asarray(mf))
    _same(trees[0], trees[3])
    np.testing.assert_array_equal(trees[2].leaf_centers, trees[0].leaf_centers * [-1, 1, 1])
    # a second call loads everything: nothing is built, the trees are the same
    again = cached_sphere_trees(meshes, cache_dir=tmp_path / "parallel", workers=2)
    for a, b in zip(trees, again):
        _same(a, b)


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_tree_build_timings_build_each_mirror_pair_once():
    from orthosim.model.parametric import parametric_dentition
    from orthosim_bench.spheretree import tree_build_timings

    rec = tree_build_timings(parametric_dentition("coarse"), baseline=False)
    assert rec["teeth"] == 28 and rec["distinct_meshes"] == 14  # left and right teeth are mirror images
    assert rec["leaves_mean"] > 1 and rec["build_s"] > 0 and rec["load_s"] > 0
    assert rec["meets_target"] == (rec["build_s"] < rec["target_s"])

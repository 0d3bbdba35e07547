"""Sphere trees hold their tooth: every surface point inside the leaves, every level inside its parent.

These are the claims the collision detectors stand on: a descent that prunes a node never loses a
contact below it, and an overlapping leaf pair is where the teeth touch.
"""

from __future__ import annotations


import numpy as np
import pytest
import trimesh

from orthosim.errors import SphereTreeError
from orthosim.spheretree import build_sphere_tree
from orthosim.exchange.shareddata import open_full_jaw_dir
from orthosim.spheretree.measure import count_holding, surface_samples

REAL_MOLAR = open_full_jaw_dir("maxilla") / "tooth_3.stl"


def parametric_tooth(fdi: int = 36, resolution: str = "medium") -> trimesh.Trimesh:
    from orthosim.model.anatomy import dimensions
    from orthosim.model.fdi import arch_of, tooth_type
    from orthosim.model.toothshape import build_tooth_shape

    return build_tooth_shape(dimensions(fdi), arch_of(fdi), tooth_type(fdi), resolution).mesh


def assert_conservative(tree, mesh: trimesh.Trimesh, n_surface: int = 100_000) -> None:
    """Random surface points lie in the union of the leaves, and each level holds its parent's part."""
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    rng = np.random.default_rng(7)
    pts = surface_samples(v, f, n_surface, rng)
    held = count_holding(pts, tree.leaf_centers, tree.leaf_radii)
    assert (held > 0).all(), f"{int((held == 0).sum())} of {n_surface} surface samples outside every leaf"
    # Exact per face: each triangle inside its leaf and inside every ancestor of that leaf.
    tree.validate(v, f)
    # And per level: the triangles a child holds are inside its parent too, level by level.
    tri = v[f]
    node = tree.leaf_of_face
    for k in range(tree.depth - 1, 0, -1):
        parent = tree.parents[k][node]
        d_child = np.linalg.norm(tri - tree.centers[k][node][:, None], axis=2).max(axis=1)
        d_parent = np.linalg.norm(tri - tree.centers[k - 1][parent][:, None], axis=2).max(axis=1)
        assert (d_child <= tree.radii[k][node] + 1e-9).all()
        assert (d_parent <= tree.radii[k - 1][parent] + 1e-9).all()
        node = parent


@pytest.mark.parametrize("method,depth", [("fit", 4), ("octree", 5)])
def test_parametric_molar_is_covered_by_its_leaves(method, depth):
    mesh = parametric_tooth(36)
    tree = build_sphere_tree(mesh, method=method, branching=8, depth=depth)
    assert tree.depth == depth and tree.n_leaves <= 8 ** (depth - 1)
    assert_conservative(tree, mesh)


def test_fit_tree_has_the_papers_shape():
    """Branching 8, depth 4: a root, up to 8, 64 and 512 spheres, each node at most 8 children."""
    mesh = parametric_tooth(11)
    tree = build_sphere_tree(mesh, method="fit", branching=8, depth=4)
    sizes = [len(r) for r in tree.radii]
    assert sizes[0] == 1 and sizes[1] <= 8 and sizes[2] <= 64 and 300 <= sizes[3] <= 512
    for k in range(1, 4):
        assert np.bincount(tree.parents[k]).max() <= 8
        assert (np.diff(tree.parents[k]) >= 0).all()


def test_default_fit_tree_is_nine_ary_with_up_to_729_leaves_and_the_octree_keeps_eight():
    """Asked for nothing, the optimising builder splits each node in 9 (smaller leaves, fewer false
    contacts); the octree still splits in 8, so `--method octree` alone is a valid request."""
    mesh = parametric_tooth(11)
    tree = build_sphere_tree(mesh)
    sizes = [len(r) for r in tree.radii]
    assert tree.branching == 9 and tree.depth == 4
    assert sizes[0] == 1 and sizes[1] <= 9 and sizes[2] <= 81 and 600 <= sizes[3] <= 729
    assert max(np.bincount(p).max() for p in tree.parents[1:]) <= 9
    assert_conservative(tree, mesh)
    assert build_sphere_tree(mesh, method="octree", depth=3).branching == 8


def test_octree_spheres_are_equal_per_level_on_a_fine_mesh():
    """On a mesh much finer than the cells, every sphere of a level is the cell's circumsphere."""
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=5.0)
    tree = build_sphere_tree(mesh, method="octree", depth=4)
    side = mesh.extents.max()
    for k in range(4):
        assert np.allclose(tree.radii[k], 0.5 * np.sqrt(3) * side / 2**k, rtol=1e-6)
    assert_conservative(tree, mesh)


def test_other_branching_factors_keep_coverage():
    mesh = trimesh.creation.capsule(height=10.0, radius=3.0, count=[24, 24])
    tree = build_sphere_tree(mesh, method="fit", branching=4, depth=5)
    assert np.bincount(tree.parents[-1]).max() <= 4
    assert_conservative(tree, mesh, n_surface=100_000)


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.real_data
def test_real_molar_is_covered_by_its_leaves():
    mesh = trimesh.load(REAL_MOLAR)
    tree = build_sphere_tree(mesh, method="fit")
    assert_conservative(tree, mesh, n_surface=200_000)


@pytest.mark.real_data
@pytest.mark.slow
def test_real_molar_tree_holds_little_outside_volume():
    """The point of the optimising builder: leaves hug the tooth. Summed SOV on the real upper molar
    was 0.067 before rebalancing and the gap term, about 0.058 with them (one standard error 0.002)."""
    from orthosim.spheretree.measure import measure_tree

    mesh = trimesh.load(REAL_MOLAR)
    v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    rep = measure_tree(build_sphere_tree((v, f), method="fit"), v, f, sphere_samples=400_000, n_surface=100_000)
    assert rep.surface_coverage == 1.0
    assert rep.sov_sum < 0.064, f"summed SOV {rep.sov_sum:.4f} +/- {rep.sov_sum_stderr:.4f}"


def test_bad_requests_name_the_option():
    mesh = trimesh.creation.box((2, 2, 2))
    with pytest.raises(SphereTreeError, match="branch"):
        build_sphere_tree(mesh, method="octree", branching=4)
    with pytest.raises(SphereTreeError, match="method"):
        build_sphere_tree(mesh, method="medial")
    with pytest.raises(SphereTreeError, match="depth"):
        build_sphere_tree(mesh, method="fit", depth=0)


@pytest.mark.parametrize("method", ["fit", "octree"])
def test_meshes_with_fewer_triangles_than_leaves_keep_the_branching(method):
    """A 12-triangle box asked for depth 4: every triangle its own leaf, still at most 8 children."""
    mesh = trimesh.creation.box((2.0, 3.0, 4.0))
    tree = build_sphere_tree(mesh, method=method, depth=4)
    assert tree.depth == 4
    tree.validate(mesh.vertices, mesh.faces)
    assert_conservative(tree, mesh)


def test_outside_band_counts_exactly_the_weighted_voxels_inside_each_sphere():
    """The optimising builder's score: the compiled running-sum count equals a brute-force count."""
    from scipy.spatial import cKDTree

    from orthosim.spheretree.outside_band import OutsideBand

    mesh = trimesh.creation.capsule(height=6.0, radius=2.0, count=[24, 24])
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces, np.int64)
    band = OutsideBand(v, f, voxel_mm=0.15, max_voxels=4_000_000, band_mm=0.75, fine_mm=0.3)
    weight = np.diff(band.prefix, axis=2)
    assert set(np.unique(weight)) == {0, 1, 8}
    cells = np.argwhere(weight > 0)
    centres_of_cells = band.origin + band.voxel * cells
    # no band voxel inside the tooth, none farther than the band
    assert not mesh.contains(centres_of_cells[::50]).any()
    assert trimesh.proximity.signed_distance(mesh, centres_of_cells[::50]).min() >= -0.75 - band.voxel
    kd, w = cKDTree(centres_of_cells), weight[weight > 0]
    rng = np.random.default_rng(3)
    c = v[rng.integers(len(v), size=400)] + rng.normal(scale=0.6, size=(400, 3))
    r = rng.uniform(0.1, 3.0, 400)
    expected = [w[kd.query_ball_point(ci, ri)].sum() for ci, ri in zip(c, r)]
    np.testing.assert_array_equal(band.count(c, r), expected)


def test_best_candidate_is_the_argmin_of_the_full_count_with_and_without_a_bound():
    """`OutsideBand.best` stops counting the candidates that cannot win: it must still pick the first
    minimiser of (count + add1) + add2, with its score and count, and honour a strict bound."""
    from orthosim.spheretree.outside_band import OutsideBand

    mesh = trimesh.creation.capsule(height=6.0, radius=2.0, count=[24, 24])
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces, np.int64)
    band = OutsideBand(v, f, voxel_mm=0.15, max_voxels=4_000_000, band_mm=0.75, fine_mm=0.3)
    rng = np.random.default_rng(5)
    g, k = 300, 7
    c = v[rng.integers(len(v), size=g)][:, None, :] + rng.normal(scale=0.8, size=(g, k, 3))
    r = rng.uniform(0.2, 3.0, (g, k))
    add1 = rng.uniform(0, 200, (g, k))
    add2 = rng.uniform(0, 1, (g, k))
    add1[:20] = 0.0  # ties: equal scores must go to the first candidate, as argmin does
    add2[:20] = 0.0
    r[:20] = 0.05  # spheres too small to hold any voxel
    cnt = band.count(c.reshape(-1, 3), r.ravel()).reshape(g, k)
    score = (cnt + add1) + add2
    idx, best, count = band.best(c, r, add1, add2)
    np.testing.assert_array_equal(idx, score.argmin(axis=1))
    np.testing.assert_array_equal(best, score.min(axis=1))
    np.testing.assert_array_equal(count, cnt[np.arange(g), idx])
    bound = np.median(score, axis=1)
    bound[:5] = score[:5].min(axis=1)  # strictly below: nothing qualifies
    idx, best, count = band.best(c, r, add1, add2, bound)
    below = score < bound[:, None]
    expect = np.where(below.any(axis=1), np.where(below, score, np.inf).argmin(axis=1), -1)
    np.testing.assert_array_equal(idx, expect)
    assert (idx[:5] == -1).all() and (count[:5] == -1).all()
    np.testing.assert_array_equal(best, np.where(expect >= 0, score.min(axis=1), bound))


def test_fine_meshes_are_scored_on_finer_voxels_and_coarse_ones_keep_the_default():
    from orthosim.spheretree.fit import FitOptions, voxel_spacing

    opts = FitOptions()
    fine = trimesh.creation.icosphere(subdivisions=6, radius=5.0)  # edges about 0.08 mm
    coarse = trimesh.creation.icosphere(subdivisions=3, radius=5.0)  # edges about 0.6 mm
    assert voxel_spacing(fine.vertices, fine.faces, opts) == opts.min_voxel_mm
    assert voxel_spacing(coarse.vertices, coarse.faces, opts) == opts.voxel_mm
    mid = trimesh.creation.icosphere(subdivisions=5, radius=5.0)  # edges about 0.16 mm
    edge = np.median(mid.edges_unique_length)
    assert np.isclose(voxel_spacing(mid.vertices, mid.faces, opts), opts.voxel_per_edge * edge, rtol=0.05)


def test_second_halves_split_each_chosen_group_across_its_long_axis():
    """Leaves picked for a split lose about half their faces, those beyond the median of the long axis."""
    from orthosim.spheretree.fit import second_halves

    rng = np.random.default_rng(1)
    pts = np.concatenate([rng.uniform([0, 0, 0], [10, 1, 1], (101, 3)), rng.uniform([0, 0, 0], [1, 1, 6], (40, 3)),
                          rng.uniform(0, 1, (1, 3)), rng.uniform(0, 1, (2, 3))])
    label = np.repeat([0, 1, 2, 3], [101, 40, 1, 2])
    second = second_halves(pts, label, np.array([True, False, False, True]))
    assert second[label == 0].sum() == 51 and not second[label == 1].any() and second[label == 3].sum() == 1
    x = pts[label == 0, 0]
    assert x[second[label == 0]].min() >= x[~second[label == 0]].max() or x[second[label == 0]].max() <= x[~second[label == 0]].min()


def test_adjacent_leaf_pairs_are_the_leaves_sharing_a_vertex():
    from orthosim.spheretree.fit import adjacent_leaf_pairs

    mesh = trimesh.creation.box((1.0, 1.0, 1.0))
    f = np.asarray(mesh.faces, np.int64)
    normal_axis = np.abs(np.asarray(mesh.face_normals)).argmax(axis=1)
    leaf = normal_axis * 2 + (np.asarray(mesh.face_normals).sum(axis=1) > 0)  # one leaf per box side
    pairs = {tuple(p) for p in adjacent_leaf_pairs(f, leaf, 6)}
    # every side meets the four sides across an edge, never its opposite one
    assert all((2 * a, 2 * a + 1) not in pairs for a in range(3))
    assert len(pairs) == 12 and all(a < b for a, b in pairs)


def test_rebalancing_trades_cheap_merges_for_dear_splits_and_keeps_coverage():
    """Merging and splitting moves leaves to where they pay: the same number of leaves, less outside
    volume by the builder's own count, every face still inside its leaf."""
    from orthosim.spheretree.enclose import node_vertex_groups, radii_to_cover
    from orthosim.spheretree.fit import FitOptions, _LeafFitter, _rebalance, initial_leaves, medial_offsets

    mesh = parametric_tooth(36)
    v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    opts = FitOptions()
    rng = np.random.default_rng(0)
    fitter = _LeafFitter(v, f, opts)
    centroid, step = medial_offsets(v, f, opts, rng)
    leaf = initial_leaves(centroid, step, 0.6, 64, opts, rng)
    n = int(leaf.max()) + 1
    c, r, _ = fitter.fit(leaf, n)
    leaf2, c2, r2 = _rebalance(fitter, leaf, c, r, 8)
    assert len(r2) == n and len(np.unique(leaf2)) == n
    assert not np.array_equal(leaf2, leaf), "nothing moved on a tooth with flat sides and cusps"
    assert fitter.count(c2, r2).sum() < fitter.count(c, r).sum()
    pts = v[node_vertex_groups(f, leaf2, n)]
    assert (radii_to_cover(pts, c2) <= r2 + 1e-9).all()


def test_a_loose_thin_tooth_is_built_again_with_a_stronger_pull_and_keeps_the_tighter_tree():
    """Where the tooth is thin and the finished tree loose (forced here by the thresholds), the
    builder builds it again with the thin pulls and keeps whichever holds less outside volume;
    elsewhere the tree is exactly the one-pull build."""
    from orthosim.spheretree.enclose import node_vertex_groups, radii_to_cover
    from orthosim.spheretree.fit import FitOptions, _LeafFitter, fit_leaves

    mesh = parametric_tooth(31)
    v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    fitter = _LeafFitter(v, f, FitOptions())

    def build(**kw):
        leaf, c, r = fit_leaves(v, f, 64, FitOptions(**kw), np.random.default_rng(0))
        assert (radii_to_cover(v[node_vertex_groups(f, leaf, len(r))], c) <= r + 1e-9).all()
        return leaf, c, r, int(fitter.count(c, r).sum())

    plain = build(thin_pulls=())
    for kw in ({"thin_rho_mm": 0.0, "thin_retry_sov": 0.0}, {"thin_rho_mm": 100.0, "thin_retry_sov": 1.0}):
        for a, b in zip(plain, build(**kw)):  # not thin, or tight enough: the one-pull tree
            np.testing.assert_array_equal(a, b)
    retried = build(thin_rho_mm=100.0, thin_retry_sov=0.0)
    strong = build(medial_pulls=(0.9,), thin_pulls=())
    assert strong[3] < plain[3], "on this incisor the stronger pull must win, for the test to see the choice"
    assert retried[3] < plain[3]  # the second build was made and kept


@pytest.mark.real_data
@pytest.mark.slow
def test_thin_real_lower_incisor_tree_holds_little_outside_volume():
    """Universal 23 (FDI 32), the thinnest real tooth: 0.082 with the one pull of 0.7, about 0.064
    built again with the stronger pull (the issue: no real tooth above 0.07)."""
    from orthosim.spheretree.measure import measure_tree

    mesh = trimesh.load(open_full_jaw_dir("mandible") / "tooth_23.stl")
    v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    rep = measure_tree(build_sphere_tree((v, f), method="fit"), v, f, sphere_samples=400_000, n_surface=100_000)
    assert rep.surface_coverage == 1.0
    assert rep.sov_sum < 0.07, f"summed SOV {rep.sov_sum:.4f} +/- {rep.sov_sum_stderr:.4f}"


def test_node_vertex_groups_list_each_nodes_distinct_vertices_in_order_padded_with_the_first():
    """The compiled gather every leaf and node fit starts from: per node, the sorted distinct
    vertices of its faces, padded by repeating the first (a repeated point changes no enclosing
    sphere), a row of -1 for a node without faces; a node number out of range is refused."""
    from orthosim.spheretree.enclose import node_vertex_groups

    rng = np.random.default_rng(8)
    for _ in range(50):
        n_nodes = int(rng.integers(1, 30))
        faces = rng.integers(0, 200, (int(rng.integers(1, 400)), 3))
        node = rng.integers(0, n_nodes, len(faces))
        out = node_vertex_groups(faces, node, n_nodes)
        width = max(1, max(len(np.unique(faces[node == k])) for k in range(n_nodes)))
        assert out.shape == (n_nodes, width)
        for k in range(n_nodes):
            expect = np.unique(faces[node == k])
            if not len(expect):
                assert (out[k] == -1).all()
                continue
            np.testing.assert_array_equal(out[k, :len(expect)], expect)
            assert (out[k, len(expect):] == expect[0]).all()
    with pytest.raises(ValueError, match="node_of_face"):
        node_vertex_groups(np.array([[0, 1, 2]]), np.array([2]), 2)

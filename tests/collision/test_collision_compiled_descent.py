"""The compiled (numba) sphere-tree descent returns exactly what the numpy descent returns: the same
(pair, leaf a, leaf b), in the same order, for the discrete and the continuous detectors."""

import numpy as np
import pytest

pytest.importorskip("numba")

from collision_helpers import crown_like_mesh, median_split_tree  # noqa: E402
from orthosim.collision import Body, CollisionModel  # noqa: E402
from orthosim.collision import descent  # noqa: E402
from orthosim_bench.collision import perturbed_poses  # noqa: E402
from orthosim.collision.continuous import swept_leaves  # noqa: E402
from orthosim.collision.detect import default_pairs  # noqa: E402
from orthosim.collision.discrete import overlapping_leaves  # noqa: E402


def both(fn, *args):
    """fn(*args) with the numpy descent and with the compiled one."""
    assert descent.compiled_descent() is not None and descent.compiled_descent(False) is None
    return fn(*args, compiled=False), fn(*args, compiled=True)


def assert_same(ref, got):
    assert len(ref) == len(got)
    for r, g in zip(ref, got):
        np.testing.assert_array_equal(np.asarray(r), np.asarray(g))


def check_step(model, P0, P1, pair_idx):
    """Discrete at both ends (all leaf pairs, first only) and continuous over the step; returns the
    number of overlapping leaf pairs at the end, so tests can make sure they test something."""
    for P in (P0, P1):
        for first_only in (False, True):
            ref, got = both(overlapping_leaves, model, P, pair_idx, first_only)
            assert_same(ref, got)
    for first_only in (False, True):
        assert_same(*both(swept_leaves, model, P0, P1, pair_idx, first_only))
    return len(both(overlapping_leaves, model, P1, pair_idx)[1][0])


def mixed_depth_builder():
    """Trees of depth 3 and 4 in turn, so that leaf pairs are found in several rounds of the descent
    (the compiled walk must then reorder its results as the numpy descent finds them)."""
    calls = iter(range(10**6))
    return lambda mesh: median_split_tree(mesh, depth=3 + next(calls) % 2)


@pytest.fixture(scope="module")
def smooth():
    from orthosim.model.parametric import parametric_dentition

    d = parametric_dentition("smooth")
    return d, CollisionModel.from_dentition(d)


@pytest.fixture(scope="module", params=["median-split", "mixed-depth"])
def coarse(request):
    from orthosim.model.parametric import parametric_dentition

    d = parametric_dentition("coarse")
    builder = median_split_tree if request.param == "median-split" else mixed_depth_builder()
    model = CollisionModel.from_dentition(d, tree_builder=builder)
    assert len({b.tree.depth for b in model.bodies}) == (1 if request.param == "median-split" else 2)
    return d, model


def whole_arch(dentition, model, seed):
    rest = dentition.rest_poses()
    pair_idx = model.pair_indices(default_pairs(model))
    P0 = model.pose_array(rest)
    moved = model.pose_array(perturbed_poses(rest, seed=seed))
    moved_far = model.pose_array(perturbed_poses(rest, step_mm=0.4, step_deg=2.0, seed=seed + 1))
    return pair_idx, P0, moved, moved_far


@pytest.mark.parametrize("seed", [0, 1])
def test_compiled_descent_matches_numpy_on_the_smooth_arch_at_rest_and_moving(smooth, seed):
    d, model = smooth
    pair_idx, P0, moved, far = whole_arch(d, model, seed)
    assert check_step(model, P0, moved, pair_idx) > 0
    assert check_step(model, moved, far, pair_idx) > 0


@pytest.mark.parametrize("seed", [0, 1])
def test_compiled_descent_matches_numpy_on_the_coarse_arch_at_rest_and_moving(coarse, seed):
    d, model = coarse
    pair_idx, P0, moved, far = whole_arch(d, model, seed)
    assert check_step(model, P0, moved, pair_idx) > 0
    assert check_step(model, moved, far, pair_idx) > 0


def test_compiled_descent_matches_numpy_on_random_relative_poses_of_two_teeth():
    from scipy.spatial.transform import Rotation

    a, b = crown_like_mesh(0), crown_like_mesh(1, subdivisions=3)
    model = CollisionModel([Body(1, a, median_split_tree(a), np.eye(4)), Body(2, b, median_split_tree(b, depth=3), np.eye(4))])
    pair_idx = np.array([[0, 1], [1, 0]])
    rng = np.random.default_rng(7)
    touching = 0
    for _ in range(40):
        P0 = np.stack([np.eye(4)] * 2)
        P0[1, :3, :3] = Rotation.random(random_state=rng).as_matrix()
        P0[1, :3, 3] = rng.normal(size=3) / np.sqrt(3) * rng.uniform(4.0, 10.0)
        P1 = P0.copy()
        P1[1, :3, :3] = Rotation.from_rotvec(rng.normal(size=3) * 0.2).as_matrix() @ P0[1, :3, :3]
        P1[1, :3, 3] += rng.normal(size=3)
        touching += check_step(model, P0, P1, pair_idx) > 0
    assert 5 < touching < 40  # both touching and apart poses were tested


def test_a_body_pair_listed_twice_gets_its_leaf_pairs_twice(smooth):
    d, model = smooth
    pair_idx = model.pair_indices(default_pairs(model))
    twice = np.concatenate([pair_idx[:5], pair_idx[:5]])
    P = model.pose_array(d.rest_poses())
    assert check_step(model, P, P, twice) > 0

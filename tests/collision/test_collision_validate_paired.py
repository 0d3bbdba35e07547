"""Tree builders compared on the very same near-contact poses (`paired_false_positives`)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from collision_helpers import median_split_tree
from orthosim.collision.validate import ToothSet, paired_false_positives


def _set():
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=4, radius=3.0)
    egg = trimesh.creation.icosphere(subdivisions=4, radius=2.0)
    egg.apply_scale((1.0, 1.6, 1.0))
    return ToothSet("round", (ball, egg), ((0, 1),))


def _inflated(mesh, by=0.3):
    tree = median_split_tree(mesh)
    return dataclasses.replace(tree, radii=tuple(r + by for r in tree.radii))


def test_the_same_trees_twice_agree_pose_for_pose_and_looser_trees_only_add_false_contacts():
    res = paired_false_positives([_set()], {"base": median_split_tree, "same": median_split_tree, "looser": _inflated},
                                 n_poses=100, seeds=(0, 1), band=(0.2, 0.5))
    pooled, flips = res["pooled"], res["flips_against_baseline"]
    assert pooled["base"]["in_band"] > 40 and pooled["base"]["false_negatives"] == 0
    assert pooled["same"] == pooled["base"] and flips["same"] == {"fp_to_tn": 0, "tn_to_fp": 0}
    # every sphere of the looser trees holds the base one: a base false positive stays one
    assert flips["looser"]["fp_to_tn"] == 0 and flips["looser"]["tn_to_fp"] > 0
    assert pooled["looser"]["false_positives"] == pooled["base"]["false_positives"] + flips["looser"]["tn_to_fp"]
    per_seed = sum(res["seeds"][s]["builders"]["base"]["in_band"] for s in ("0", "1"))
    assert per_seed == pooled["base"]["in_band"]
    assert np.isclose(pooled["base"]["rate"], pooled["base"]["false_positives"] / pooled["base"]["in_band"])


@pytest.mark.real_data
@pytest.mark.slow
def test_default_trees_draw_few_false_contacts_between_real_teeth_a_tenth_of_a_millimetre_apart():
    """Issue 18's line, on real teeth and a seed the trees were not chosen on: of the poses where two
    neighbours are 0.1-0.25 mm apart, the discrete detector with the default trees calls at most
    15 % touching (8-ary trees of 512 leaves called about 17 %), and it misses no contact."""
    from collision_helpers import real_tooth_meshes
    from orthosim.collision.validate import discrete_study
    from orthosim.spheretree import cached_sphere_tree

    meshes = real_tooth_meshes((10, 11, 12, 13, 14, 15))
    report = discrete_study([ToothSet("real", tuple(meshes), tuple((k, k + 1) for k in range(5)))], n_poses=1500,
                            tree_builder=cached_sphere_tree, seed=21)
    res = report["sets"]["real"]
    band = res["false_positive_rate_by_band"]["0.1-0.25mm"]
    assert res["false_negatives"] == 0 and res["exact_intersecting"] > 100
    assert band["poses"] >= 150  # enough poses in the band for a rate worth asserting
    assert band["rate"] <= 0.15, f"{band['rate']:.1%} of {band['poses']} separated poses called touching"

"""Tree builders compared on the very same near-contact poses (`paired_false_positives`)."""

from __future__ import annotations

import dataclasses

import numpy as np

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

"""Compile orthosim's numba kernels once, in one process, before the suite's workers start.

numba caches a compiled kernel beside its source (`__pycache__`), so only the first process on a
fresh clone compiles it; but the suite's first minutes start many processes at once (two pytest
workers, each running `orthosim` in child processes), and every one of them that needs a kernel
before its cache file exists compiles it again, at 2-6 s of CPU a kernel. `tests/conftest.py` runs
this script first (`python tests/numba_warmup.py`), so that they all load the kernels instead.
Where the caches are warm already it takes about two seconds.

It runs what the suite runs, at the smallest size that reaches every kernel: a few steps of the
paper's case 1 with each detector, the compiled sphere-tree descent and sweep asked for by name
(the detectors themselves compile them only once that pays), the exact
penetration depths), the distance map (signed distances), two teeth pushed into each other
(penetration and edge depth) and a sphere tree of a small ball (the tree builders).
"""

from __future__ import annotations

import numpy as np
import trimesh

from orthosim.analysis.distancemap import DistanceMapModel
from orthosim.collision.continuous import swept_leaves
from orthosim.collision.detect import default_pairs
from orthosim.collision.discrete import overlapping_leaves
from orthosim.exchange.case import DEFAULT_CASE, load_case
from orthosim.geometry.penetration import edge_penetration_depth, penetration_depth
from orthosim.geometry.signeddistance import prefer_compiled
from orthosim.movement.simulation import MovementModel, simulate
from orthosim.spheretree import build_sphere_tree


def warm_up() -> None:
    prefer_compiled()  # the depth and distance queries stay in numpy until compiling pays: compile them here
    model = MovementModel.build(load_case(DEFAULT_CASE))
    for detector in ("continuous", "exact", "discrete", "circles"):
        for _ in simulate(model, detector, steps=3):
            pass
    dent = model.dentition
    rest = dent.rest_poses()
    # the detectors compile their descent only once it pays (orthosim.collision.descent): compile it here
    collision = model.collision
    poses, pairs = collision.pose_array(rest), collision.pair_indices(default_pairs(collision))
    overlapping_leaves(collision, poses, pairs, compiled=True)
    swept_leaves(collision, poses, poses, pairs, compiled=True)
    DistanceMapModel(dent).inter_arch(rest)
    a, b = dent.fdis[0], dent.fdis[1]  # neighbours in the arch: b moved halfway onto a
    into = rest[b].copy()
    into[:3, 3] = 0.5 * (rest[a][:3, 3] + rest[b][:3, 3])
    penetration_depth(dent.teeth[a].mesh, rest[a], dent.teeth[b].mesh, into)
    edge_penetration_depth(dent.teeth[a].mesh, rest[a], dent.teeth[b].mesh, into)
    for method in ("fit", "octree"):
        build_sphere_tree(trimesh.creation.icosphere(subdivisions=3, radius=4.0), method=method, depth=3)


if __name__ == "__main__":
    np.seterr(all="ignore")
    warm_up()

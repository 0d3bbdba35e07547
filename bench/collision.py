"""Timings of every detector on one whole-arch step, against python-fcl over the same pairs.

`collision_timings` is what `orthosim bench` reports as `collision_us_per_step` and
`candidate_pairs`: median wall-clock microseconds of one call that tests every candidate pair of a
step, through the public entry point `detect_step` (pose dict in, `StepResult` out), and for FCL a
plain loop that places both prebuilt BVH objects and calls `fcl.collide` per pair.
"""

from __future__ import annotations

import time
from typing import Callable, Mapping, Sequence

import fcl
import numpy as np

from orthosim.geometry import meshquery
from orthosim.collision.contract import CollisionRequest
from orthosim.collision.detect import default_pairs, detect_step
from orthosim.collision.model import CollisionModel
from orthosim.collision.queries import ExactQueries


def round_robin_us(fns: dict[str, Callable[[], object]], repeats: int) -> dict[str, np.ndarray]:
    """(repeats,) microseconds of each callable, measured round-robin (one call of each in turn)
    so that load from other processes on a shared machine falls on all of them alike."""
    for fn in fns.values():
        fn()  # warm-up (first use builds FCL objects, caches)
    times = {k: [] for k in fns}
    for _ in range(repeats):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t0)
    return {k: np.array(v) * 1e6 for k, v in times.items()}


def perturbed_poses(poses: Mapping[int, np.ndarray], step_mm: float = 0.1, step_deg: float = 0.2, seed: int = 0) -> dict[int, np.ndarray]:
    """Every pose moved by a random translation of `step_mm` mm and a turn of `step_deg` degrees about
    its local origin: a realistic simulation step."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    out = {}
    for k, T in poses.items():
        d = rng.normal(size=3)
        axis = rng.normal(size=3)
        U = np.array(T, float, copy=True)
        U[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.radians(step_deg)).as_matrix() @ U[:3, :3]
        U[:3, 3] += d / np.linalg.norm(d) * step_mm
        out[k] = U
    return out


class _FclStep:
    """python-fcl over the same pairs as the detectors: both prebuilt BVH objects placed, then
    `fcl.collide`, per pair; calling it returns how many pairs intersect."""

    def __init__(self, model: CollisionModel, pair_idx, poses, poses_end):
        queries = ExactQueries(model)

        def objects(poses_):
            P = model.pose_array(poses_)
            return [(queries.object(a), queries.object(b), P[a], P[b]) for a, b in pair_idx]

        self.at_end, self.at_start = objects(poses_end), objects(poses)

    def __call__(self, all_contacts: bool, objs=None) -> int:
        req = fcl.CollisionRequest(num_max_contacts=10**7, enable_contact=True) if all_contacts else fcl.CollisionRequest()
        hits = 0
        for oa, ob, Ta, Tb in (self.at_end if objs is None else objs):
            meshquery.set_pose(oa, Ta)
            meshquery.set_pose(ob, Tb)
            res = fcl.CollisionResult()
            fcl.collide(oa, ob, req, res)
            hits += res.is_collision
        return hits


def collision_timings(dentition, poses: Mapping[int, np.ndarray] | None = None, pairs: Sequence[tuple[int, int]] | None = None,
                      repeats: int = 50, model: CollisionModel | None = None, tree_builder=None,
                      poses_end: Mapping[int, np.ndarray] | None = None) -> dict:
    """{"collision_us_per_step": {circles, discrete, continuous, fcl_boolean, fcl_all_contacts},
    "candidate_pairs": int, "collision_step": {...details}} for one whole-arch step.

    The step goes from `poses` (FDI -> (4, 4), rest poses by default) to `poses_end` (default
    `perturbed_poses(poses)`: every tooth moved 0.1 mm and turned 0.2 degrees). The discrete
    detectors and FCL test the step's end poses, as a simulator using them would; the continuous
    detector sweeps the whole step. `collision_step.at_start_poses_us` also gives the discrete
    detector and FCL at the start poses (the parametric model at rest: crowns just touching).
    """
    if model is None:
        model = CollisionModel.from_dentition(dentition, tree_builder=tree_builder)
    poses = dict(poses) if poses is not None else dentition.rest_poses()
    step_given = poses_end is not None
    poses_end = poses_end if step_given else perturbed_poses(poses)
    pairs = list(pairs) if pairs is not None else default_pairs(model)
    all_pairs = CollisionRequest(all_leaf_pairs=True)
    pair_idx = model.pair_indices(pairs)

    fcl_step = _FclStep(model, pair_idx, poses, poses_end)
    at_start = fcl_step.at_start
    samples = round_robin_us({
        "circles": lambda: detect_step(model, poses_end, pairs=pairs, detector="circles"),
        "discrete": lambda: detect_step(model, poses_end, pairs=pairs, detector="discrete", request=all_pairs),
        "continuous": lambda: detect_step(model, poses, poses_end, pairs=pairs, detector="continuous", request=all_pairs),
        "fcl_boolean": lambda: fcl_step(False),
        "fcl_all_contacts": lambda: fcl_step(True),
        "discrete_at_start": lambda: detect_step(model, poses, pairs=pairs, detector="discrete", request=all_pairs),
        "fcl_boolean_at_start": lambda: fcl_step(False, at_start),
    }, repeats)
    timed = {k: float(np.median(v)) for k, v in samples.items()}
    keys = ("circles", "discrete", "continuous", "fcl_boolean", "fcl_all_contacts")
    us = {k: timed[k] for k in keys}
    fastest = {k: float(samples[k].min()) for k in keys}
    disc = detect_step(model, poses_end, pairs=pairs, detector="discrete", request=all_pairs)
    cont = detect_step(model, poses, poses_end, pairs=pairs, detector="continuous", request=all_pairs)
    return {
        "collision_us_per_step": us,
        "candidate_pairs": len(pairs),
        "collision_step": {
            "teeth": len(model.bodies),
            "tree_depth": model.depth,
            "leaves_per_tooth_mean": float(np.mean([b.tree.n_leaves for b in model.bodies])),
            "discrete_touching_pairs": int(disc.touching.sum()),
            "discrete_overlapping_leaf_pairs": int(len(disc.leaf_pairs)),
            "continuous_touching_pairs": int(cont.touching.sum()),
            "fcl_intersecting_pairs": int(fcl_step(False)),
            "at_start_poses_us": {"discrete": timed["discrete_at_start"], "fcl_boolean": timed["fcl_boolean_at_start"],
                                  "fcl_intersecting_pairs": int(fcl_step(False, at_start))},
            "continuous_step": "every tooth moved 0.1 mm and turned 0.2 degrees (perturbed_poses)" if not step_given else "given",
            "ratios": {
                "discrete_over_fcl_boolean": us["discrete"] / us["fcl_boolean"],
                "continuous_over_discrete": us["continuous"] / us["discrete"],
                "discrete_over_fcl_all_contacts": us["discrete"] / us["fcl_all_contacts"],
            },
            "repeats": repeats,
            # on a shared machine a longer call is likelier to be preempted, which skews medians;
            # the fastest of the repeats shows the undisturbed cost
            "us_per_step_min": fastest,
            "ratios_of_min": {
                "discrete_over_fcl_boolean": fastest["discrete"] / fastest["fcl_boolean"],
                "continuous_over_discrete": fastest["continuous"] / fastest["discrete"],
            },
        },
    }

"""How long a dentition's sphere trees take: built from nothing, on every core and on one, and loaded.

`tree_build_timings(dentition)` builds the trees of every tooth into a throw-away cache folder
twice, once over all cores (what a first run on a machine does) and once in one process (the
baseline, measured in the same run so the ratio stands on a loaded machine), then loads them
all from that cache (what every later run does). `orthosim bench` records the result beside
its 10 s target for the 28 smooth teeth of the default model.
"""

from __future__ import annotations

import os
import tempfile
import time

from orthosim.spheretree.build import DEPTH, default_branching
from orthosim.spheretree.cache import cached_sphere_trees

TARGET_S = 10.0  # all 28 smooth teeth of the default model, built together on this 2-core machine


def tree_build_timings(dentition, method: str = "fit", branching: int | None = None, depth: int = DEPTH,
                       baseline: bool = True) -> dict:
    """Seconds to build (all cores; one process as baseline) and to load the trees of `dentition`."""
    branching = default_branching(method, branching)
    meshes = [dentition.teeth[n].mesh for n in dentition.fdis]
    record: dict = {"teeth": len(meshes), "triangles_total": int(sum(len(m.faces) for m in meshes)),
                    "method": method, "branching": branching, "depth": depth,
                    "workers": os.cpu_count() or 1, "target_s": TARGET_S}
    with tempfile.TemporaryDirectory(prefix="orthosim-bench-trees-") as folder:
        t0 = time.perf_counter()
        trees = cached_sphere_trees(meshes, method, branching, depth, folder, shipped=False)  # built, never the shipped
        record["build_s"] = time.perf_counter() - t0
        record["distinct_meshes"] = len(os.listdir(folder))  # mirror pairs share one entry
        t0 = time.perf_counter()
        cached_sphere_trees(meshes, method, branching, depth, folder)
        record["load_s"] = time.perf_counter() - t0
    record["leaves_mean"] = sum(t.n_leaves for t in trees) / len(trees)
    record["meets_target"] = record["build_s"] < TARGET_S
    if baseline:
        with tempfile.TemporaryDirectory(prefix="orthosim-bench-trees-") as folder:
            t0 = time.perf_counter()
            cached_sphere_trees(meshes, method, branching, depth, folder, workers=1, shipped=False)
            record["build_s_one_process"] = time.perf_counter() - t0
        record["speedup_all_cores_vs_one"] = record["build_s_one_process"] / record["build_s"]
    return record

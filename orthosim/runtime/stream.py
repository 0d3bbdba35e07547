"""The simulation side of a run as one stream: model, trees, then a record per step, then the report.

`simulation_stream` is what every run strategy (`orthosim.runtime.strategies`) iterates, in this
process or in a child: `PhaseDone` items as the model and trees are ready, one `StepRecord` per
step (steps.jsonl and distances_per_step.csv stream into the run folder as they come), and the
`RunResult` last. Its arguments pickle, so a child process can run it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator


@dataclass(frozen=True)
class PhaseDone:
    """A phase of the simulation side ended (sent by the child among its step records)."""

    name: str
    seconds: float
    detail: str = ""


@dataclass(frozen=True)
class RunResult:
    """The simulation side's last item: the run's report, ready to write."""

    metrics: dict
    distances_csv: str
    model_files: dict  # for run.json: the model's description and source files


def simulation_stream(case, detector: str, out_dir: str | Path, dentition=None, shared: bool = False) -> Iterator:
    """The simulation side of a run: PhaseDone("model"), PhaseDone("trees"), one StepRecord per step,
    then the RunResult. Picklable arguments: it runs in the child process when the run draws.
    The per-step detail (steps.jsonl, distances_per_step.csv) streams into out_dir as it comes.
    shared: `dentition` is drawn meanwhile by another thread of this process (its meshes' caches
    are then left alone)."""
    from orthosim.runtime.background import release_freed_heap
    from orthosim.storage.numpytally import keep as keep_numpy_tally
    from orthosim.collision import CollisionModel, ExactQueries
    from orthosim.collision.patchcache import PatchCache
    from orthosim.analysis.metrics import occlusion_summary
    from orthosim.movement.report import DISTANCES_PER_STEP_FILE, STEPS_FILE, RunReport
    from orthosim.movement.simulation import MovementModel, simulate

    t0 = time.perf_counter()
    cached = dentition is None and case.dentition_is_cached()
    dent = dentition if dentition is not None else case.build_dentition()
    t1 = time.perf_counter()
    collision = CollisionModel.from_dentition(dent)
    # a tooth's whole-mesh BVH is built when a step first needs it (most steps ask patches only:
    # case 1 needs 8 of its 24 teeth's), not for every tooth up front: ~55 MB less in a drawn run
    queries = ExactQueries(collision)
    # every run of these teeth starts from the same poses, whatever its plan: the first step's
    # patches are kept between runs (`orthosim.collision.patchcache`); later steps' are not
    queries.patch_cache = PatchCache()
    t2 = time.perf_counter()
    model = MovementModel.build(case, dent, collision=collision)
    if not shared:
        dent.drop_mesh_caches()  # the meshes' derived arrays the build asked for (~30 MB on 28 teeth)
    release_freed_heap()  # what building the model freed, before a run of any length
    t3 = time.perf_counter()
    how = "from the cache" if cached else ("given" if dentition is not None else "built")
    yield PhaseDone("model", (t1 - t0) + (t3 - t2), f"{dent.description}, {how}")
    yield PhaseDone("trees", t2 - t1, f"{len(collision.bodies)} sphere trees")
    out_dir = Path(out_dir)
    report = RunReport(model, detector, steps_file=out_dir / STEPS_FILE, distances_file=out_dir / DISTANCES_PER_STEP_FILE)
    for record in report.collect(simulate(model, detector, queries=queries)):
        queries.patch_cache = None
        yield record
    report.finish_streams(out_dir)
    keep_numpy_tally()  # what it spent in numpy, for later runs (a forked child ends with os._exit: no atexit)
    metrics = report.metrics()
    metrics["model"] = {"kind": case.model.kind, **model_summary(dent)}  # every model says what it is (the schema asks)
    metrics["occlusion"] = occlusion_summary(dent)  # the initial model's
    metrics["occlusion_final"] = occlusion_summary(dent, {n: report.last.poses[n] for n in dent.fdis})
    yield RunResult(metrics, report.distances_csv(), model_files(dent))


_PATH_KEYS = ("source", "files", "axes_file")  # model info that names files on this machine: run.json's


def model_summary(dent) -> dict:
    """What metrics.json says of the model: its kind and build figures, without machine paths."""
    return {"teeth": len(dent.teeth), **{k: v for k, v in dent.info.items() if k not in _PATH_KEYS}}


def model_files(dent) -> dict:
    """What run.json says of the model: its description and the files it was read from."""
    return {"description": dent.description, **{k: v for k, v in dent.info.items() if k in _PATH_KEYS}}



"""Where a run's simulation runs: in this process, in a forked child, or in a spawned child.

Each strategy is a small object whose `start` gives the two things a drawn run needs: the
dentition this process draws, and the stream of the simulation's records (`StepRecord`s, then the
`RunResult`; `orthosim.runtime.run.simulation_stream`). `orthosim run`, the bench and the image
regression helpers all pick one with `choose_strategy` and draw from what it gives, so they time
and draw the same thing.

- `InProcess`: the simulation runs in this process, between frames (one core; `--single-core`).
- `ForkedChild`: the imports both sides use and the teeth are loaded here, then a forked child
  (a copy of this process, sharing those pages) simulates while this process draws.
- `SpawnedChild`: a fresh interpreter simulates (where fork is unsafe: threads already running).
"""

from __future__ import annotations

import time
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import Iterator, Protocol

# what both sides of a drawn run use (the teeth: numpy and orthosim's own modules; the teeth are
# LazyMeshes, so no trimesh), imported before the fork so that the two processes share it; the step's
# own (the collision package, FCL, scipy's k-d tree, numba) only the simulation child imports, and the
# renderer only this process, once the first step has reached it
SHARED_MODULES = ("orthosim.runtime.run", "orthosim.runtime.stream", "orthosim.model.dentition", "orthosim.analysis.metrics", "orthosim.movement.records")
SIMULATION_MODULES = ("orthosim.runtime.stream", "orthosim.collision.detect", "orthosim.collision.queries",
                      "orthosim.movement.simulation")


@dataclass
class SimulationSource:
    """What a strategy gives: the dentition to draw, the simulation's record stream, and where it runs."""

    dentition: object  # orthosim.model.dentition.Dentition
    records: Iterator
    where: str


class RunStrategy(Protocol):
    def start(self, case, detector: str, out_dir, log, stack: ExitStack) -> SimulationSource: ...


def _import_modules(names) -> None:
    """Import `names` now (before a fork: the child shares them)."""
    import importlib

    for name in names:
        importlib.import_module(name)


class InProcess:
    """The simulation steps in this process, as the drawing asks for records."""

    def start(self, case, detector, out_dir, log, stack) -> SimulationSource:
        from orthosim.runtime.stream import simulation_stream

        dent = case.build_dentition()
        return SimulationSource(dent, simulation_stream(case, detector, out_dir, dentition=dent, shared=True),
                                "in this process")


class SpawnedChild:
    """A fresh interpreter simulates; the teeth are built here first only when the cache cannot
    hand them to the child (then they are passed along)."""

    def __init__(self, dentition=None):
        self.dentition = dentition  # already built here (a fork that turned unsafe), or None

    def start(self, case, detector, out_dir, log, stack) -> SimulationSource:
        from orthosim.runtime.background import ChildProcessIterator
        from orthosim.runtime.stream import simulation_stream

        dent = self.dentition
        child = stack.enter_context(ChildProcessIterator(ignore_warnings=True, preload=SIMULATION_MODULES))
        if dent is None and not case.dentition_is_cached():  # built once, here, and cached for the child
            t = time.perf_counter()
            dent = case.build_dentition()
            log.phase("model", time.perf_counter() - t, f"{dent.description}, built and cached")
        given = dent if dent is not None and not case.dentition_is_cached() else None  # unwritable cache
        child.submit(simulation_stream, case, detector, out_dir, dentition=given)
        return SimulationSource(dent or case.build_dentition(), child, "beside the drawing")


class ForkedChild:
    """The shared imports and the teeth loaded once here, then a forked child simulates."""

    def start(self, case, detector, out_dir, log, stack) -> SimulationSource:
        from orthosim.runtime.background import ChildProcessIterator, fork_is_safe
        from orthosim.runtime.stream import simulation_stream

        # the child starts as a copy of this process, with the imports both sides use done and the
        # teeth loaded once; the step's own imports (numba, the collision package) come after the
        # fork in the child only, the renderer (and its OpenGL context) in this process only
        t = time.perf_counter()
        _import_modules(SHARED_MODULES)
        log.phase("imports", time.perf_counter() - t, "numpy and the run's modules: once, for both processes")
        t = time.perf_counter()
        cached = case.dentition_is_cached()
        dent = case.build_dentition()
        dent.drop_mesh_caches()  # a build's leftovers: each process derives only what it uses
        log.phase("model", time.perf_counter() - t, f"{dent.description}, {'from the cache' if cached else 'built and cached'}")
        if not fork_is_safe():  # a thread started during the build: spawn instead, handing the teeth over
            return SpawnedChild(dent).start(case, detector, out_dir, log, stack)
        child = stack.enter_context(ChildProcessIterator(ignore_warnings=True, start_method="fork"))
        child.submit(simulation_stream, case, detector, out_dir, dentition=dent)
        return SimulationSource(dent, child, "beside the drawing")


def choose_strategy(in_process: bool, dentition=None) -> RunStrategy:
    """In this process when asked (`--single-core`, tests), else a forked child where fork is safe
    (no thread running yet), else a spawned one. `dentition`: the teeth, when this process has
    loaded them already (a spawned child is handed them where the cache cannot serve it)."""
    if in_process:
        return InProcess()
    from orthosim.runtime.background import fork_is_safe

    return ForkedChild() if fork_is_safe() else SpawnedChild(dentition)


class _Unlogged:
    """A run log that keeps nothing (`orthosim.runtime.run.RunLog`'s `phase`), for runs nobody reads the phases of."""

    def phase(self, name: str, seconds: float, detail: str = "") -> None:
        pass


@contextmanager
def step_records(case, detector: str, steps: int | None = None, *, in_process: bool = False, dentition=None):
    """The simulation side of `orthosim run` for the case's first `steps` steps (None: all), as one
    `SimulationSource` whose `records` are the `StepRecord`s alone: the strategy `choose_strategy`
    picks, its run-folder files streamed into a temporary folder as a run's are. For those that
    draw a run without being one (the bench, the image regression helpers), so that they draw what
    `orthosim run` would. dentition: the teeth, when this process holds them already."""
    import dataclasses
    import tempfile

    from orthosim.movement.records import StepRecord

    if steps is not None:
        case = dataclasses.replace(case, duration_days=max(1, int(steps)) * case.step_days)
    with tempfile.TemporaryDirectory(prefix="orthosim-records-") as out, ExitStack() as stack:
        source = choose_strategy(in_process, dentition).start(case, detector, out, _Unlogged(), stack)
        yield SimulationSource(source.dentition, (r for r in source.records if isinstance(r, StepRecord)), source.where)

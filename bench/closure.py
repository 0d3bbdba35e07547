"""What the bite's closure costs: a real-jaw step with the mandible closing after it, and without.

`orthosim bench --closure` adds this record: the case is run for a few steps with `[occlusion]
closure = "hinge"` and again with "none" (the occlusal slide allowance instead), both on the
continuous detector in this one process, and each closing step's time is split into the closure
(`movement.closure.settle_bite`) and the rest of the step. The issue's target: the closure costs at
most as much as the rest of the step.
"""

from __future__ import annotations

import dataclasses
import statistics
import time
from pathlib import Path


def _timed_steps(case, steps: int) -> dict:
    """Per-step seconds of `steps` steps of `case`, and of its closures (0 without)."""
    from orthosim.movement import closure as closure_module
    from orthosim.movement.simulation import MovementModel, initial_state, step

    model = MovementModel.build(case)
    state, _ = initial_state(model, "continuous")
    spent: list[float] = []
    settle = closure_module.settle_bite

    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return settle(*args, **kwargs)
        finally:
            spent.append(time.perf_counter() - t0)

    step_s, closure_s = [], []
    closure_module.settle_bite = timed  # step() looks it up in the module at each call
    try:
        for _ in range(steps):
            spent.clear()
            t0 = time.perf_counter()
            state, _ = step(model, state)
            step_s.append(time.perf_counter() - t0)
            closure_s.append(sum(spent))
    finally:
        closure_module.settle_bite = settle
    return {"step_s": step_s, "closure_s": closure_s, "rest_of_step_s": [a - b for a, b in zip(step_s, closure_s)]}


def closure_timings(case_path: str | Path, steps: int = 6) -> dict:
    """The closure's bench record for one (real-jaw) case: seconds per step with and without the
    closure, the closure's share, and the two ratios (medians over the steps)."""
    from orthosim.exchange.case import load_case

    case = load_case(case_path)
    runs = {}
    for mode in ("hinge", "none"):
        runs[mode] = _timed_steps(dataclasses.replace(case, occlusion=dataclasses.replace(case.occlusion, closure=mode)), steps)
    med = {mode: {k: statistics.median(v) for k, v in r.items()} for mode, r in runs.items()}
    return {
        "case": str(case_path),
        "steps": steps,
        "detector": "continuous",
        "with_closure": runs["hinge"],
        "without_closure": runs["none"],
        "median_s": med,
        "closure_over_rest_of_step": med["hinge"]["closure_s"] / max(med["hinge"]["rest_of_step_s"], 1e-9),
        "step_with_over_without_closure": med["hinge"]["step_s"] / max(med["none"]["step_s"], 1e-9),
        "target": "closure_over_rest_of_step <= 1",
    }

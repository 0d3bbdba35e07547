"""`orthosim stage`, the core half: read a case, plan its staging, list the contacts to highlight.

The command itself lives in `orthosim/cli/stage.py` (it also draws, through `orthosim_render.staging`); this
module does everything that does not draw, so a script can stage a case without OpenGL:

    run = plan_case("cases/staging_lower_incisor_crowding.toml", StageLimits.parse("tip=1.5"))
    write_outputs(run.plan, "out/crowding", run.case.path)
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orthosim.errors import CaseError
from orthosim.staging.limits import StageLimits
from orthosim.staging.plan import StagingPlan, plan_staging


@dataclass(frozen=True, eq=False)
class StagingRun:
    case: object  # orthosim.exchange.case.Case
    dentition: object  # orthosim.model.dentition.Dentition (every tooth of the model)
    model: object  # orthosim.collision.CollisionModel of the staged teeth
    plan: StagingPlan


def plan_case(case_path: str | Path, limits: StageLimits = StageLimits(), model=None) -> StagingRun:
    """Load and validate the case, build its teeth and collision model, plan the staging."""
    from orthosim.exchange.case import load_case
    from orthosim.collision import CollisionModel
    from orthosim.model.dentition import Dentition

    case = load_case(case_path)
    if case.staging is None or case.staging.target is None:
        raise CaseError(case.path, "target", "missing: nothing to stage",
                        "add a [target] section (per-tooth movements, e.g. [target.41] buccal_mm = 0.5, or folder = \"...\")")
    dent = case.build_dentition()
    start, target = case.staging.poses(dent)
    absent = frozenset(case.extractions)
    if model is None:
        staged = Dentition({n: dent.teeth[n] for n in dent.fdis if n not in absent}, dent.description, dent.info)
        model = CollisionModel.from_dentition(staged)
    plan = plan_staging(dent, start, target, limits, model=model, absent=absent, source=case.path)
    return StagingRun(case, dent, model, plan)


def ipr_contact_points(run: StagingRun, stage: int) -> tuple[np.ndarray, tuple[tuple[int, int], ...]]:
    """((m, 3) mm arch-frame points, pairs): where the full (unreduced) meshes of each IPR pair
    intersect at `stage`: the enamel the reduction removes, what the animation highlights."""
    from orthosim.collision import CollisionRequest, detect_step

    pairs = [(r.a, r.b) for r in run.plan.ipr]
    if not pairs:
        return np.zeros((0, 3)), ()
    res = detect_step(run.model, run.plan.poses(stage), pairs=pairs, detector="exact",
                      request=CollisionRequest(all_leaf_pairs=True))
    touching = tuple(tuple(int(x) for x in pairs[i]) for i in np.flatnonzero(res.touching))
    return res.centers_a, touching

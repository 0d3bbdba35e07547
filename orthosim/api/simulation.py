"""A case's model built once and simulated in memory: what `orthosim.build`, `orthosim.simulate` and
`orthosim.contacts` do.

    case = orthosim.load_case("cases/case1_first_premolar_extraction.toml")
    model = orthosim.build(case)                    # MovementModel: teeth, sphere trees, mechanics
    for record in orthosim.simulate(model, steps=5):  # StepRecord: step 0 (rest), then 1..5
        found = orthosim.contacts(model, record.poses)

The same model and step that `orthosim run` uses (`orthosim.movement`); nothing is written to disk
but the caches (built teeth and sphere trees, `~/.cache/orthosim` or $ORTHOSIM_CACHE), so a second
`build` of the same case loads them instead of building them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator, Mapping

import numpy as np

from orthosim.collision import Contacts, ExactQueries
from orthosim.collision.detect import contacts as detect_contacts
from orthosim.exchange.case import Case, load_case
from orthosim.movement.model import MovementModel
from orthosim.movement.records import StepRecord
from orthosim.movement.response import touch_request
from orthosim.movement.simulation import simulate as simulate_model


def build(case: Case | str | Path) -> MovementModel:
    """The case's model, built once and never changed: its teeth (`Dentition`, mm), each tooth's
    sphere tree and exact mesh (`CollisionModel`), each tooth's mechanics (centre of resistance,
    rate law) and the settings. `case`: a `Case` or a case file's path (validated: `OrthosimError`
    on bad input). Teeth and sphere trees are cached on disk: the second build loads them."""
    if not isinstance(case, Case):
        case = load_case(case)
    return MovementModel.build(case)


def simulate(model: MovementModel, steps: int | None = None, detector: str | None = None) -> Iterator[StepRecord]:
    """The simulation of `model`, one `StepRecord` per step as it is made: step 0 (the rest poses),
    then steps 1..`steps` of the case's step_days each (None: the case's duration).

    Each record: `step`, `time_days` (days), `poses` ({FDI: (4, 4) float64, tooth frame -> arch
    frame, mm}), `touching` (FDI pairs in contact), `contact_centers` ((n, 3) mm),
    `contact_radii` ((n,) mm), `collisions`, `max_penetration_mm` (mm). `detector`: one of
    "circles", "discrete", "continuous", "exact" (None: the case's)."""
    return simulate_model(model, detector, steps)


def contacts(model: MovementModel, poses: Mapping[int, np.ndarray], detector: str | None = None) -> Contacts:
    """The contacts of the model's teeth at `poses` ({FDI: (4, 4) tooth frame -> arch frame, mm};
    e.g. a `StepRecord`'s), as `detector` (None: the case's) sees them, between the pairs a step
    tests (arch neighbours and facing teeth, extracted teeth left out).

    Returns `Contacts`: `touching` (FDI pairs), `centers` ((n, 3) mm) and `radii` ((n,) mm) of what
    is drawn as contact, `penetration` ({pair: mm} of the pairs whose exact meshes interpenetrate)
    and `distance` ({pair: mm} where the exact distance decided contact)."""
    return detect_contacts(model.collision, poses, touch_request(model), ExactQueries(model.collision), model.pairs,
                           detector or model.case.detector)

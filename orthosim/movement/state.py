"""The state of a run between steps (`StepState`): poses, touching pairs, the rest state's
interpenetration, the run's detector and exact queries (MuJoCo's mjData). Frozen: a step returns a
new one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Mapping

import numpy as np

from orthosim.collision import ExactQueries
from orthosim.collision.detectors import Detector

if TYPE_CHECKING:
    from orthosim.movement.model import MovementModel


@dataclass(frozen=True, eq=False)
class StepState:
    """What a run carries from one step to the next (the model never changes).

    step / day: the step just made (0: the initial state) and its day.
    poses: FDI -> (4, 4) local -> arch frame, mm. touching: pairs in contact at `poses`.
    rest_depths: pair -> mm the exact meshes interpenetrate in the initial state (a scan may leave
        some; the run's interpenetration is measured against it).
    detector: the run's detector. queries: the run's exact queries and their memos (`ExactQueries`).
    bite: pairs of facing teeth in contact in the initial state (the bite as the model stands): they
        may slide by `occlusal_slide_mm`; contacts the run makes get the touch tolerance.
    centers: FDI -> (3,) crown centres at `poses` (`Dentition.crown_centers`; found when None).
    mandible_deg: with a closure, the hinge angle the lower teeth's poses stand at.
    """

    step: int
    day: float
    poses: Mapping[int, np.ndarray]
    touching: tuple[tuple[int, int], ...]
    rest_depths: Mapping[tuple[int, int], float]
    detector: Detector  # the run's (`orthosim.collision.detectors`): its capabilities steer the step
    queries: ExactQueries
    bite: frozenset[tuple[int, int]] = frozenset()
    centers: Mapping[int, np.ndarray] | None = None
    mandible_deg: float = 0.0  # the mandible's hinge angle from rest (degrees, positive open; `closure`)

    def slide_allowance(self, model: "MovementModel", pair: tuple[int, int]) -> float:
        """mm a facing pair may sink below the rest state while its cusps slide along each other."""
        s = model.settings
        return s.occlusal_slide_mm if pair in self.bite else min(s.occlusal_slide_mm, s.touch_tolerance_mm)

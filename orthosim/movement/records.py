"""What one simulation step hands on: `StepRecord` (and its `CollisionEvent`s), the items that cross
from the simulation process to the drawing one, pickled.

Their own module, free of the simulation's imports (the collision package, FCL, numba), so that the
process that unpickles them to draw frames does not load those; `orthosim.movement.simulation`
makes them and re-exports them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from orthosim.analysis.metrics import PairDistance
    from orthosim.movement.propagation import ForceBalance


@dataclass(frozen=True, eq=False)
class CollisionEvent:
    """Two teeth met in a step: at `time` (fraction of the step; 1.0 for discrete detectors, which
    only see the end), with the impact response of the paper."""

    pair: tuple[int, int]
    time: float
    impact: dict


@dataclass(frozen=True, eq=False)
class BiteRecord:
    """The bite after a step's closure (`orthosim.movement.closure`): the mandible's hinge angle from
    rest (degrees, positive open), how far the bite stands open at the incisors and at the first
    molars (mm, along the occlusal normal; negative: closed further than at rest), the facing pairs
    in contact at closure, and those the closure could not resolve (their movers were stopped)."""

    angle_deg: float
    opening_incisors_mm: float
    opening_molars_mm: float
    contacts: tuple[tuple[int, int], ...]
    unresolved: tuple[tuple[int, int], ...] = ()

    def summary(self) -> dict:
        return {"angle_deg": self.angle_deg, "opening_incisors_mm": self.opening_incisors_mm,
                "opening_molars_mm": self.opening_molars_mm, "contacts": [list(p) for p in self.contacts],
                "contact_count": len(self.contacts), "unresolved": [list(p) for p in self.unresolved]}


@dataclass(frozen=True, eq=False)
class StepRecord:
    """The state after one step (step 0: the initial state, before any movement).

    poses: FDI -> (4, 4) local -> arch frame, mm (extracted teeth keep their rest pose, not drawn).
    moving: teeth that moved in the step. touching: pairs in contact at the step's end.
    contact_centers (n, 3) mm / contact_radii (n,) mm: overlapping leaf spheres of touching pairs.
    collisions: events of the step. forces: the step's force balance (cN).

    max_penetration_mm: deepest interpenetration the run has added to any candidate pair, on the
        exact meshes (mm; depth now less depth in the initial model, which may have some).

    distances: the paper's tooth-to-tooth distances (mm) per adjacent pair.
    raw_penetration_mm: deepest interpenetration of any candidate pair as it stands (mm).
    penetrating: ((a, b), mm) for every candidate pair interpenetrating as it stands, deepest first.
    bite: the bite after the step's closure; None when the run closes no bite (or at step 0).
    """

    step: int
    time_days: float
    poses: dict[int, np.ndarray]
    moving: frozenset[int]
    touching: tuple[tuple[int, int], ...]
    contact_centers: np.ndarray
    contact_radii: np.ndarray
    collisions: tuple[CollisionEvent, ...]
    forces: ForceBalance | None
    max_penetration_mm: float
    distances: tuple[PairDistance, ...]
    raw_penetration_mm: float = 0.0
    penetrating: tuple[tuple[tuple[int, int], float], ...] = ()
    bite: BiteRecord | None = None

    @property
    def total_distance_mm(self) -> float:
        return float(sum(d.distance_mm for d in self.distances))

"""Whether one stage's motion brings any two teeth into contact: the planner's collision check.

A stage moves every tooth from its pose at the previous stage to its pose at this one with the
motion the continuous detector assumes (`orthosim.geometry.motion`). Every pair of teeth that may
meet is tested, crowns and roots, same arch and opposing arch, through the collision contract:
  1. broad phase: `collision.detect.swept_sphere_pairs`, each tooth's root sphere grown by its
     sweep, so any two teeth can be paired, not only arch neighbours;
  2. `collision.detect_step` with the continuous detector: the sphere trees' conservative first
     time of contact, or proof that the pair stays apart, then refined on the exact meshes
     (python-fcl) to the first time they INTERSECT (`CollisionRequest.contact = INTERSECTING`):
     conservative advancement, each stride the FCL distance over the bound on relative speed,
     never shorter than `tolerance_mm` of closing.
A pair is in contact when FCL finds the meshes intersecting at some time of the stage; a contact
shallower than `tolerance_mm` could slip between two strides, which is the check's resolution.

Where interproximal reduction is planned, the checker is given the reduced teeth
(`reduced_model`: each cut tooth's mesh replaced by its cut one, `staging.reduction`, its sphere
tree kept: the full tooth's tree still bounds the cut tooth, so the broad phase stays conservative).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from orthosim.collision.contract import INTERSECTING, CollisionRequest
from orthosim.collision.detect import detect_step, swept_sphere_pairs
from orthosim.collision.detectors import CONTINUOUS
from orthosim.collision.model import CollisionModel
from orthosim.collision.queries import ExactQueries

TOLERANCE_MM = 0.002  # resolution of the exact check (see the module docstring)
BROAD_PHASE_MARGIN_MM = 0.01  # added to every swept sphere


@dataclass(frozen=True)
class Contact:
    """Teeth `a` and `b` (FDI) touch at `time` (fraction 0..1 of the stage's motion)."""

    a: int
    b: int
    time: float


class StageChecker:
    """Contact checks of stage motions over one collision model (the teeth that take part, reduced
    where IPR is planned: `reduced_model`)."""

    def __init__(self, model: CollisionModel, tolerance_mm: float = TOLERANCE_MM):
        self.model = model
        self.request = CollisionRequest(all_leaf_pairs=False, refine_time_of_contact=True, contact=INTERSECTING,
                                        contact_tolerance_mm=tolerance_mm, drawn_leaves=False)
        self.queries = ExactQueries(model, memo_size=8192)

    @property
    def fcl_queries(self) -> int:
        """FCL queries asked so far (distances and intersection tests; remembered answers not counted)."""
        return self.queries.fcl_calls

    def contacts(self, poses0: Mapping[int, np.ndarray], poses1: Mapping[int, np.ndarray],
                 pairs: Sequence[tuple[int, int]] | None = None) -> list[Contact]:
        """Every pair of teeth in contact during the motion poses0 -> poses1 (FDI -> (4, 4));
        `pairs` (FDI) restricts the test. poses0 == poses1 tests one set of poses (every pair
        intersecting there)."""
        if pairs is None:
            P0, P1 = self.model.pose_array(poses0), self.model.pose_array(poses1)
            pairs = swept_sphere_pairs(self.model, P0, P1, BROAD_PHASE_MARGIN_MM, moving_only=not np.array_equal(P0, P1))
        found = self._ask(poses0, poses1, list(pairs)) if len(pairs) else []
        return sorted(found, key=lambda c: (c.time, c.a, c.b))

    def _ask(self, poses0, poses1, pairs) -> list[Contact]:
        res = detect_step(self.model, poses0, poses1, pairs, CONTINUOUS, self.request, self.queries)
        return [Contact(min(a, b), max(a, b), float(t))
                for (a, b), t in zip(res.pairs.tolist(), res.time_of_first_contact.tolist()) if not np.isnan(t)]


def reduced_model(model: CollisionModel, meshes: Mapping[int, object]) -> CollisionModel:
    """`model` with each body's mesh replaced by meshes[its FDI] (tooth frame, mm) where that is
    another mesh (a reduced tooth), its sphere tree and rest pose kept."""
    from dataclasses import replace

    bodies = [b if meshes.get(b.key, b.mesh) is b.mesh else replace(b, mesh=meshes[b.key]) for b in model.bodies]
    return model if all(x is y for x, y in zip(bodies, model.bodies)) else CollisionModel(bodies)

"""Interproximal reduction (IPR): enamel removed between two neighbours that do not fit at the target.

How much: the exact penetration of the two target meshes along their contact direction (the unit
vector from one crown centre to the other at the target): the least distance one tooth must be
moved away from the other along it for FCL to find the meshes apart, found by bisection to
`RESOLUTION_MM`.

How it is modelled (honestly, a simplification): the reduction is taken as done before the first
stage, as a slab of that thickness removed at the contact, half from each tooth. The meshes are
not cut. Instead, whenever that pair (and only that pair) is checked for contact, its two teeth
are moved apart by half the reduction each along the contact direction, plus `CLEARANCE_MM`
between them; every other pair sees the full teeth. This is exact for the two contacting
surfaces when the contact direction is the direction of approach, and ignores that real
stripping reshapes the surface (it removes enamel only near the contact, and the staged teeth
may meet at a slightly different point of it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthosim.collision.queries import ExactQueries
from orthosim.errors import OrthosimError

RESOLUTION_MM = 1e-3  # bisection resolution of the reduction
CLEARANCE_MM = 0.01  # extra room left between the reduced surfaces, above the contact check's resolution
MAX_IPR_MM = 5.0  # a tooth pair overlapping more than this at the target is a wrong target, not crowding
USUAL_MAX_PER_CONTACT_MM = 0.5  # clinical guideline: about 0.25 mm of enamel per surface


class StagingError(OrthosimError):
    """A set-up that cannot be staged (teeth that cannot reach the target without contact)."""


@dataclass(frozen=True, eq=False)
class InterproximalReduction:
    a: int  # FDI, the first tooth of the contact (lower FDI)
    b: int  # FDI
    amount_mm: float  # enamel to remove at the contact, both surfaces together
    direction: np.ndarray  # (3,) unit, arch frame: from a's crown centre to b's at the target

    def shifts(self) -> tuple[np.ndarray, np.ndarray]:
        """(3,) mm arch-frame offsets of a and of b for this pair's contact checks."""
        h = 0.5 * (self.amount_mm + CLEARANCE_MM)
        return -h * self.direction, h * self.direction


def penetration_along(queries: ExactQueries, i: int, pose_a: np.ndarray, j: int, pose_b: np.ndarray,
                      direction: np.ndarray) -> float:
    """mm: least translation of body j (at pose_b) along `direction` (unit, arch frame) after which
    the meshes of bodies i and j of `queries` no longer intersect (0 when they do not), by
    bisection to RESOLUTION_MM."""
    def apart(d: float) -> bool:
        T = np.array(pose_b, float)
        T[:3, 3] += d * direction
        return not queries.body_intersects(i, pose_a, j, T)

    if apart(0.0):
        return 0.0
    lo, hi = 0.0, 0.05
    while not apart(hi):
        lo, hi = hi, 2 * hi
        if hi > 2 * MAX_IPR_MM:
            return float("inf")
    while hi - lo > RESOLUTION_MM:
        mid = 0.5 * (lo + hi)
        if apart(mid):
            hi = mid
        else:
            lo = mid
    return hi


def reduction_for(model, dentition, a: int, b: int, pose_a: np.ndarray, pose_b: np.ndarray, source=None,
                  queries: ExactQueries | None = None) -> InterproximalReduction:
    """The IPR that lets neighbours a and b (FDI) stand at the given target poses (queries: the
    caller's `ExactQueries` of `model`; one is made when None)."""
    ca = dentition.teeth[a].to_world(dentition.teeth[a].crown_center, pose_a)
    cb = dentition.teeth[b].to_world(dentition.teeth[b].crown_center, pose_b)
    u = (cb - ca) / np.linalg.norm(cb - ca)
    queries = queries or ExactQueries(model)
    amount = penetration_along(queries, model.index[a], pose_a, model.index[b], pose_b, u)
    if amount > MAX_IPR_MM:
        raise StagingError(source, f"target of teeth {a} and {b}",
                           f"the two teeth overlap by more than {MAX_IPR_MM:g} mm at the target: no reduction can make room",
                           "check the target movements of these teeth (units, signs)")
    return InterproximalReduction(a, b, float(amount), u)

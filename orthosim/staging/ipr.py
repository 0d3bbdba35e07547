"""Interproximal reduction (IPR): enamel removed between two neighbours that do not fit at the target.

How much, and how it is modelled: as labs strip, a plane cut on each tooth's contact side
(`staging.reduction`: the enamel beyond a plane perpendicular to the contact direction, the unit
vector from one crown centre to the other at the target, half the reduction deep on each tooth).
The reduction is the least such pair of equal cuts after which FCL finds the two target meshes
apart, found by bisection to `RESOLUTION_MM`, plus `CLEARANCE_MM` of room between the cut faces,
rounded up to 1e-4 mm (the figure stages.json and certificate.json record, so every reader cuts
the same teeth). It is done before stage 1: from there on the planner, the certificate, the
verifier and the exported stage models all see the reduced teeth, for every pair they check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from orthosim.collision.queries import ExactQueries
from orthosim.errors import OrthosimError
from orthosim.staging.reduction import contact_cuts, cut_tooth

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


def reduction_for(dentition, a: int, b: int, pose_a: np.ndarray, pose_b: np.ndarray, source=None) -> InterproximalReduction:
    """The IPR that lets neighbours a and b (FDI) stand at the given target poses ((4, 4), mm):
    the least equal pair of cuts (`reduction.contact_cuts`) that leaves the meshes apart."""
    ta, tb = dentition.teeth[a], dentition.teeth[b]
    ca, cb = ta.to_world(ta.crown_center, pose_a), tb.to_world(tb.crown_center, pose_b)
    u = (cb - ca) / np.linalg.norm(cb - ca)

    def apart(half_mm: float) -> bool:
        cut_a, cut_b = contact_cuts(a, b, 2.0 * half_mm, u, pose_a, pose_b)
        q = ExactQueries.of_meshes({a: cut_tooth(ta.mesh, [cut_a]), b: cut_tooth(tb.mesh, [cut_b])}, patch_reach_mm=0.0)
        return not q.body_intersects(q.model.index[a], pose_a, q.model.index[b], pose_b)

    if apart(0.0):
        return InterproximalReduction(a, b, 0.0, u)
    lo, hi = 0.0, 0.05
    while not apart(hi):
        if 2.0 * hi > MAX_IPR_MM:
            raise StagingError(source, f"target of teeth {a} and {b}",
                               f"the two teeth overlap by more than {MAX_IPR_MM:g} mm at the target: no reduction can make room",
                               "check the target movements of these teeth (units, signs)")
        lo, hi = hi, 2.0 * hi
    while hi - lo > 0.5 * RESOLUTION_MM:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if apart(mid) else (mid, hi)
    amount = math.ceil((2.0 * hi + CLEARANCE_MM) * 1e4) / 1e4
    return InterproximalReduction(a, b, amount, u)

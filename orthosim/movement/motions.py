"""Phase 2 of a step: each tooth's motion over the step under its free force (its mechanics, the
wire, the rate law: `orthosim.mechanics.biomechanics.tooth_motion`, or with the ligament's stiffness
`orthosim.mechanics.ligamentmotion.ligament_motion`); with a rectangular wire a
blocked tooth follows a neighbour that gives way (teeth in contact move together).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from orthosim.mechanics.biomechanics import Motion, tooth_motion
from orthosim.mechanics.ligamentmotion import ligament_motion
from orthosim.mechanics.vec import length
from orthosim.movement.directions import contact_normal
from orthosim.movement.forces import Forces
from orthosim.movement.model import MovementModel
from orthosim.movement.state import StepState


def motions(model: MovementModel, state: StepState, f: Forces, centers: Mapping[int, np.ndarray]) -> dict[int, Motion]:
    """Phase 2: each tooth's motion over the step under its free force; blocked teeth follow a
    neighbour that gives way."""
    s = model.settings
    dt = float(model.case.step_days)
    poses, balance = state.poses, f.balance
    wire = model.case.wire.type
    out: dict[int, Motion] = {}
    for n in model.present:
        free = balance.free.get(n)
        own = f.loads.get(n, ())
        couple = sum((a.couple_cNmm for a in own), np.zeros(3))
        if (free is None or not free.any()) and not couple.any():
            continue
        if free is None:
            free = np.zeros(3)
        if own and any(a.force_cN.any() for a in own):
            w = np.array([length(a.force_cN) for a in own])
            point = sum(wi * a.point_mm for wi, a in zip(w, own)) / max(w.sum(), 1e-12)
        else:
            point = centers[n]
        translation_only = wire == "rectangular" and (not own or any(a.bodily for a in own))
        mech = model.mechanics[n]
        move = tooth_motion if mech.support is None else ligament_motion
        m = move(mech, poses[n], free, point, couple, wire, translation_only, s.rate)
        if not m.is_still:
            out[n] = m
    if wire != "rectangular":
        return out
    # a tooth blocked by a neighbour that moves away follows it, as far as its own push would take it
    settled: dict[tuple[int, int], tuple] = {}  # (i, j) -> the motions (of j, of i) it last left unchanged
    for _ in range(len(model.present)):
        changed = False
        for i, blockers in balance.blocked_by.items():
            for j in blockers:
                if j not in out:
                    continue
                seen = settled.get((i, j))
                if seen is not None and seen[0] is out[j] and seen[1] is out.get(i):
                    continue  # the same motions (frozen) as when this pair last changed nothing
                n_ij = contact_normal(model, (i, j), centers)
                p = 0.5 * (centers[i] + centers[j])
                away = float(out[j].displacement(p, dt)[0] @ n_ij) / dt
                mi = out.get(i, Motion.still(centers[i]))
                cur = float(mi.displacement(p, dt)[0] @ n_ij) / dt
                push = float(balance.total[i] @ n_ij)
                want = float(s.rate.rate(length(balance.total[i]), model.mechanics[i].resisting_area_mm2)) * push / max(
                    length(balance.total[i]), 1e-12)
                target = min(away, want)
                if target > cur + 1e-12:
                    out[i] = Motion(mi.pivot, mi.velocity + (target - cur) * n_ij, mi.omega)
                    changed = True
                else:
                    settled[(i, j)] = (out[j], out.get(i))
        if not changed:
            break
    return out

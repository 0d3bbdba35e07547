"""Phase 1 of a step: the case's loads on each tooth at the step's start poses (`AppliedLoad`), and
the forces touching teeth pass on (`orthosim.movement.propagation`); the reactions an anchor unit
takes ([[anchorage]], `orthosim.exchange.ligamentfields`). Arch frame; cN, cN*mm, mm.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from orthosim.exchange.case import Load
from orthosim.exchange.ligamentfields import Anchorage, same_side
from orthosim.mechanics.vec import length
from orthosim.movement.directions import arch_direction, contact_normal, horizontal, onward_directions
from orthosim.movement.model import MovementModel
from orthosim.movement.propagation import ForceBalance, propagate
from orthosim.movement.state import StepState


@dataclass(frozen=True, eq=False)
class AppliedLoad:
    """One load of the case on one tooth at given poses, arch frame.

    force_cN (3,), applied at point_mm (3,), plus a couple couple_cNmm (3,). bodily: the load asks
    for translation (a rectangular wire then moves the tooth without tipping)."""

    force_cN: np.ndarray
    point_mm: np.ndarray
    couple_cNmm: np.ndarray
    bodily: bool


def applied_load(model: MovementModel, poses: Mapping[int, np.ndarray], load: Load, fdi: int,
                 centers: Mapping[int, np.ndarray] | None = None) -> AppliedLoad:
    """One load on one tooth at `poses` (centers: the crown centres at `poses`,
    `Dentition.crown_centers`, when the caller has them)."""
    tooth = model.dentition.teeth[fdi]
    mech = model.mechanics[fdi]
    R, p = poses[fdi][:3, :3], poses[fdi][:3, 3]
    d = load.direction
    if load.movement == "extrusion":
        d = "occlusal"
    elif load.movement == "intrusion":
        d = "apical"
    if isinstance(d, str):
        if d in ("mesial", "distal"):
            u = arch_direction(model, poses, fdi, d, centers)
        elif d in ("labial", "lingual"):
            t = arch_direction(model, poses, fdi, "mesial", centers)
            u = horizontal(np.cross(t, [0.0, 1.0, 0.0]))
            if u @ (R @ tooth.labial) < 0:
                u = -u
            if d == "lingual":
                u = -u
        else:
            u = R @ tooth.long_axis * (1.0 if d == "occlusal" else -1.0)
    else:
        u = np.asarray(d, float) / length(d)
    pt = load.point
    local = {"bracket": mech.bracket, "crown_center": mech.crown_center,
             "center_of_resistance": mech.center_of_resistance}.get(pt) if isinstance(pt, str) else np.asarray(pt, float)
    axis = {"mesiodistal": tooth.mesial, "labiolingual": tooth.labial, "long_axis": tooth.long_axis}[load.moment_axis]
    bodily = load.movement in ("translation", "extrusion", "intrusion") or (load.movement == "auto" and load.moment_cNmm == 0.0)
    return AppliedLoad(load.force_cN * u, R @ local + p, load.moment_cNmm * (R @ axis), bodily)


@dataclass(frozen=True, eq=False)
class Forces:
    """The forces phase: the loads on each tooth at the step's start and the force balance."""

    loads: dict[int, list[AppliedLoad]]
    balance: ForceBalance


def forces(model: MovementModel, state: StepState, centers: Mapping[int, np.ndarray]) -> Forces:
    """Phase 1: the case's loads at the step's start poses, and the forces touching teeth pass on."""
    s = model.settings
    P = state.poses
    loads: dict[int, list[AppliedLoad]] = {}
    for load in model.case.loads:
        for n in load.teeth:
            if n in model.mechanics:
                loads.setdefault(n, []).append(applied_load(model, P, load, n, centers))
    for anchor in getattr(model.case, "anchorage", ()):
        if anchor.kind == "teeth":
            _anchor_reactions(model, P, anchor, loads)
    applied = {n: sum((a.force_cN for a in v), np.zeros(3)) for n, v in loads.items()}
    normals = [(a, b, contact_normal(model, (a, b), centers)) for a, b in state.touching]
    balance = propagate(applied, normals, s.force_share,
                        lambda n, f: n in model.mechanics and s.rate.moves(f, model.mechanics[n].resisting_area_mm2),
                        onward_directions(model, P, state.touching, centers))
    return Forces(loads, balance)


def _anchor_reactions(model: MovementModel, poses: Mapping[int, np.ndarray], anchor: Anchorage,
                      loads: dict[int, list[AppliedLoad]]) -> None:
    """Adds to `loads` the reactions of the loads on the anchorage's active teeth: each active tooth's
    resultant force (cN), reversed, shared by the anchor unit's teeth of its side at their brackets
    by their stiffness along it (the ligament's translational stiffness; the resisting root surface
    for a tooth moved by a rule), bodily (the wire ties the unit)."""
    for n in anchor.active:
        own = loads.get(n)
        if not own:
            continue
        reaction = -sum((a.force_cN for a in own), np.zeros(3))
        f = length(reaction)
        unit = [t for t in same_side(n, anchor.teeth) if t in model.mechanics]
        if f == 0.0 or not unit:
            continue
        u = reaction / f
        weights = np.array([_stiffness_along(model.mechanics[t], poses[t], u) for t in unit])
        for t, w in zip(unit, weights / weights.sum()):
            R, p = poses[t][:3, :3], poses[t][:3, 3]
            loads.setdefault(t, []).append(AppliedLoad(reaction * w, R @ model.mechanics[t].bracket + p, np.zeros(3), True))


def _stiffness_along(mech, pose: np.ndarray, u: np.ndarray) -> float:
    """How stiffly a tooth resists a translation along the arch-frame unit vector u (N/mm with the
    ligament; its resisting root surface, mm^2, for a tooth moved by a rule: only ratios count)."""
    if mech.support is None:
        return mech.resisting_area_mm2
    ul = pose[:3, :3].T @ u
    return float(ul @ mech.support.stiffness[:3, :3] @ ul)

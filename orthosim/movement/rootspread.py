"""How far a run's answer hangs on roots nobody saw: the range of each moving tooth's movement over
the plausible roots of the teeth whose roots were estimated (`orthosim.model.rootsynthesis`).

An estimated root's length is the crown height times the tooth type's average root/crown ratio
(Wheeler). Real ratios spread about the average: Hoelttae P, Nystroem M, Evaelahti M, Alaluusua S.
2004. Root-crown ratios of permanent teeth in a healthy Finnish population assessed from panoramic
radiographs. Eur J Orthod 26(5):491-497 (abstract read: the biological variance exceeded the
measurement error for every tooth; its Table 2's type means run from 1.78 to 2.46, as quoted by a
secondary page, the table itself not read), about +/-16 % about their middle across types. Within a
type the spread is at least that wide; we take the ratio's ends at 0.75 and 1.25 of the average
(`ROOT_CROWN_SPREAD`), beyond the across-type span, as the plausible roots.

The ends are simulated: the case is run again with every estimated root stretched along the long
axis about the CEJ to the short and to the long end (its mechanics: stiffness, centre of resistance,
embedded surface and so its rate; the collision geometry stays the estimated root's, which only
roots touching roots would feel). A tooth's `moved_mm_range` is the least and the most its crown
centre moved over the three runs (mm).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from orthosim.mechanics.biomechanics import build_mechanics
from orthosim.model.tooth import Tooth
from orthosim.movement.model import MovementModel
from orthosim.movement.simulation import simulate

ROOT_CROWN_SPREAD = (0.75, 1.25)  # ends of the root/crown ratio, as multiples of the type's average (module text)


def stretched_root(tooth: Tooth, factor: float) -> Tooth:
    """The tooth with its root (the mesh apical of the CEJ, local y < 0) stretched along the long axis
    by `factor` about the CEJ; the crown as it is. Lengths mm, tooth frame."""
    v = tooth.mesh.vertices.copy()
    below = v[:, 1] < 0.0
    v[below, 1] *= factor
    import trimesh  # here: a run's report imports this module, and its first step needs no trimesh

    mesh = trimesh.Trimesh(v, tooth.mesh.faces, process=False)
    return replace(tooth, mesh=mesh, apex=np.asarray(tooth.apex, float) * np.array([1.0, factor, 1.0]),
                   landmarks=dict(tooth.landmarks))


def estimated(model: MovementModel) -> list[int]:
    """The present teeth whose roots were estimated for a crown."""
    return [n for n in model.present if model.dentition.teeth[n].root_kind == "estimated"]


def spread_model(model: MovementModel, factor: float) -> MovementModel:
    """`model` with the mechanics of every estimated root stretched by `factor` (module text)."""
    s = model.settings
    levels = dict(s.bone_level_mm)
    mech = dict(model.mechanics)
    for n in estimated(model):
        mech[n] = build_mechanics(stretched_root(model.dentition.teeth[n], factor), s.resistance_rule,
                                  s.resistance_fraction, s.rate, s.ligament, levels.get(n))
    return replace(model, mechanics=mech)


def crown_moves(model: MovementModel, first, last) -> tuple[dict[int, float], dict[int, float]]:
    """(FDI -> mm its crown centre moved from the record `first` to `last`, arch frame, as metrics.json's
    `moved_mm`; FDI -> mm it moved within its own jaw: a lower tooth's with the mandible's hinge turn
    taken out when the run closes the bite)."""
    undo = None
    if model.closure is not None and last.bite is not None:
        undo = model.closure.axis.transform(-last.bite.angle_deg)
    moved, own = {}, {}
    for n in model.dentition.fdis:
        t = model.dentition.teeth[n]
        start = t.to_world(t.crown_center, first.poses[n])
        moved[n] = float(np.linalg.norm(t.to_world(t.crown_center, last.poses[n]) - start))
        lower = undo is not None and n // 10 in (3, 4)
        own[n] = float(np.linalg.norm(t.to_world(t.crown_center, undo @ last.poses[n]) - start)) if lower else moved[n]
    return moved, own


def moved_ranges(model: MovementModel, detector: str, steps: int, first, last) -> dict[int, tuple[float, float]]:
    """FDI -> (least, most) mm (`moved_mm`) of each tooth that moves within its jaw by more than
    0.01 mm in any of the runs: the run given (its records `first` and `last`) and the two ends of
    the root spread, each simulated for `steps` steps with `detector`; {} when no root was estimated.
    (Teeth the mandible's hinge only carries are not moving teeth.)"""
    if not estimated(model):
        return {}
    runs = [crown_moves(model, first, last)]
    for factor in ROOT_CROWN_SPREAD:
        records = simulate(spread_model(model, factor), detector, steps)
        start = end = next(records)
        for end in records:
            pass
        runs.append(crown_moves(model, start, end))
    out = {}
    for n in model.present:
        if max(own[n] for _, own in runs) > 0.01:
            values = [moved[n] for moved, _ in runs]
            out[n] = (min(values), max(values))
    return out

"""Directions along the arch and across a contact at given poses: the paper's director vector (toward
the next present tooth along the arch), contact normals, and the direction a pushed tooth passes a
force on. Arch frame, unit (3,) vectors.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from orthosim.mechanics.vec import length
from orthosim.model import fdi as F
from orthosim.movement.model import MovementModel


def arch_step(fdi: int, direction: str) -> int:
    """+1 / -1: which way along `arch_order` (right to left) is `direction` for this tooth."""
    mesial = 1 if F.quadrant(fdi) in (1, 4) else -1
    return mesial if direction == "mesial" else -mesial


def horizontal(v: np.ndarray) -> np.ndarray:
    h = np.array([v[0], 0.0, v[2]])
    n = length(h)
    return h / n if n > 0 else h


def _present_in_arch(model: MovementModel, fdi: int) -> list[int]:
    """Present teeth of fdi's arch, right distal end to left distal end."""
    arch = F.arch_of(fdi)
    order = model.arch_orders.get(arch)
    if order is None:
        order = [t for t in F.arch_order(arch, set(model.dentition.teeth)) if t not in model.extracted]
    return order


def arch_direction(model: MovementModel, poses: Mapping[int, np.ndarray], fdi: int, direction: str,
                   centers: Mapping[int, np.ndarray] | None = None) -> np.ndarray:
    """(3,) unit arch-frame vector 'mesial' or 'distal' for a tooth at `poses`: toward the crown centre
    of the next present tooth that way along the arch (the paper's director vector), or along the
    tooth's own mesiodistal axis at the end of the arch. centers: the crown centres at `poses`
    (`Dentition.crown_centers`) when the caller has them."""
    order = _present_in_arch(model, fdi)
    i = order.index(fdi)
    j = i + arch_step(fdi, direction)
    tooth = model.dentition.teeth[fdi]
    R = poses[fdi][:3, :3]
    if 0 <= j < len(order):
        if centers is None:
            centers = model.dentition.crown_centers(poses)
        return horizontal(centers[order[j]] - centers[fdi])
    sign = 1.0 if direction == "mesial" else -1.0
    return horizontal(sign * (R @ tooth.mesial))


def contact_normal(model: MovementModel, pair: tuple[int, int], centers: Mapping[int, np.ndarray]) -> np.ndarray:
    """Unit vector from pair[0] toward pair[1]: horizontal between crown centres for neighbours,
    vertical for facing (occlusal) pairs."""
    a, b = pair
    if pair in model.facing or (b, a) in model.facing:
        return np.array([0.0, np.sign(centers[b][1] - centers[a][1]) or 1.0, 0.0])
    return horizontal(centers[b] - centers[a])


def onward_directions(model: MovementModel, poses, touching, centers) -> dict[tuple[int, int], np.ndarray]:
    """(pusher, pushed) -> direction of the force the pushed tooth receives: along the arch, toward
    its own next tooth away from the pusher (the paper's director vector); occlusal pairs: none
    (the contact normal, vertical, is used)."""
    out = {}
    found: dict[tuple[int, str], np.ndarray] = {}  # (tooth, way) -> its arch direction (a tooth in two contacts)
    for a, b in touching:
        if (a, b) in model.facing or (b, a) in model.facing or F.arch_of(a) != F.arch_of(b):
            continue
        ia, ib = model.arch_place[a], model.arch_place[b]
        for i, j, step_ in ((a, b, (ib > ia) - (ib < ia)), (b, a, (ia > ib) - (ia < ib))):
            way = "mesial" if step_ == arch_step(j, "mesial") else "distal"
            d = found.get((j, way))
            if d is None:
                d = found[(j, way)] = arch_direction(model, poses, j, way, centers)
            out[(i, j)] = d
    return out

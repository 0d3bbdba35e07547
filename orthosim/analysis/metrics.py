"""Figures of a model or a run that users compare across cases and detectors.

The paper's tooth-to-tooth distance: for each pair of adjacent teeth in an arch, the distance in
the occlusal (x-z) plane between the geometric centres of their crowns,
d = sqrt((x1 - x2)^2 + (z1 - z2)^2), in mm; the sum over an arch measures how closely the teeth
fit (smaller is better), and a gap over 1 mm between neighbours cannot be neglected in practice.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthosim.model.dentition import Dentition
from orthosim.model.occlusion import molar_relation, overbite, overjet

Poses = dict[int, np.ndarray]


@dataclass(frozen=True)
class PairDistance:
    pair: tuple[int, int]  # FDI numbers, right to left along the arch
    distance_mm: float


def tooth_to_tooth_distances(dent: Dentition, poses: Poses | None = None, absent: set[int] = frozenset(),
                             centers: dict[int, np.ndarray] | None = None) -> list[PairDistance]:
    """The paper's distance for every adjacent pair of present teeth (extraction spaces bridged).
    centers: the crown centres at `poses` (`Dentition.crown_centers`) when the caller has them."""
    if centers is None:
        centers = dent.crown_centers(poses)
    pairs = dent.adjacent_pairs(absent)
    if not pairs:
        return []
    gap = np.array([centers[a] for a, _ in pairs]) - np.array([centers[b] for _, b in pairs])
    return [PairDistance(pair, d) for pair, d in zip(pairs, np.hypot(gap[:, 0], gap[:, 2]).tolist())]


def occlusion_summary(dent: Dentition, poses: Poses | None = None) -> dict | None:
    """Overjet, overbite and molar relation (mm) of a (posed) dentition, ready for JSON; None when
    the model lacks the four central incisors these figures are measured on."""
    if not {11, 21, 31, 41} <= set(dent.teeth):
        return None
    return {"overjet_mm": overjet(dent, poses), "overbite_mm": overbite(dent, poses),
            "molar_relation_mm": molar_relation(dent, poses)}

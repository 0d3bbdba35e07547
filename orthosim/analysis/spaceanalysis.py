"""Space analysis per arch: the space the teeth have along the arch against the space they need.

Clinicians compare the space available along an arch with the sum of the mesiodistal widths of
its teeth: a surplus is spacing (gaps, an extraction space not yet closed), a deficit crowding.
Measured here on the posed meshes for any pose, in the occlusal (x-z) plane, in mm:
  - required: the sum of the present teeth's mesiodistal crown widths (`occlusion.mesiodistal_width`);
  - available: the arch length from the distal surface of the last tooth on one side to that of
    the last tooth on the other, along the polyline through the crown centres (centre-to-centre
    distances plus half the widths of the two end teeth);
  - discrepancy = available - required: the sum of the gaps between neighbours, where each
    neighbour pair's gap is its centre distance minus half of each width (an extraction space
    counts in full until it closes).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping

import numpy as np

from orthosim.model.dentition import Dentition
from orthosim.model.fdi import Arch
from orthosim.model.occlusion import mesiodistal_width

GAP_THRESHOLD_MM = 1.0  # a gap over 1 mm between neighbours cannot be neglected in practice (the paper)


@dataclass(frozen=True)
class PairGap:
    pair: tuple[int, int]  # FDI numbers, right to left along the arch
    center_distance_mm: float  # the paper's tooth-to-tooth distance (x-z plane)
    gap_mm: float  # centre distance minus half of each tooth's mesiodistal width


@dataclass(frozen=True)
class ArchSpace:
    arch: str  # "upper" | "lower"
    teeth: tuple[int, ...]
    required_mm: float
    available_mm: float
    gaps: tuple[PairGap, ...]

    @property
    def discrepancy_mm(self) -> float:
        """Positive: spacing; negative: crowding."""
        return self.available_mm - self.required_mm

    def as_dict(self) -> dict:
        return {"arch": self.arch, "teeth": list(self.teeth), "required_mm": self.required_mm,
                "available_mm": self.available_mm, "discrepancy_mm": self.discrepancy_mm,
                "gaps_over_threshold": [list(g.pair) for g in self.gaps if g.gap_mm > GAP_THRESHOLD_MM],
                "gaps": [{"pair": list(g.pair), "center_distance_mm": g.center_distance_mm, "gap_mm": g.gap_mm}
                         for g in self.gaps]}


def widths_mm(dent: Dentition) -> dict[int, float]:
    """FDI -> mesiodistal crown width (mm); a model property, the same in every pose."""
    return {n: mesiodistal_width(dent, n) for n in dent.fdis}


def arch_space(dent: Dentition, poses: Mapping[int, np.ndarray] | None = None, absent: Iterable[int] = (),
               widths: Mapping[int, float] | None = None) -> dict[str, ArchSpace]:
    """{"upper": ArchSpace, "lower": ArchSpace} of the posed dentition, teeth in `absent` left out."""
    absent = set(absent)
    widths = widths or widths_mm(dent)
    poses = dent.rest_poses() if poses is None else poses
    centers = {n: t.to_world(t.crown_center, poses[n]) for n, t in dent.teeth.items() if n not in absent}
    out = {}
    for arch in (Arch.UPPER, Arch.LOWER):
        teeth = [n for n in dent.arch(arch) if n not in absent]
        gaps = []
        for a, b in zip(teeth[:-1], teeth[1:]):
            d = float(np.hypot(*(centers[a] - centers[b])[[0, 2]]))
            gaps.append(PairGap((a, b), d, d - (widths[a] + widths[b]) / 2))
        required = float(sum(widths[n] for n in teeth))
        available = (sum(g.center_distance_mm for g in gaps) + (widths[teeth[0]] + widths[teeth[-1]]) / 2) if teeth else 0.0
        out[arch.value] = ArchSpace(arch.value, tuple(teeth), required, float(available), tuple(gaps))
    return out

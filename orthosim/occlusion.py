"""Occlusal measurements on a posed dentition: overjet, overbite, Angle molar relation, Bolton ratios.

All are measured on the meshes, in the arch frame, in millimetres (ratios in per cent), so they
check the model rather than restate the numbers it was built from.
  - overbite: vertical overlap of the central incisors: the highest point of the lower central's
    crown minus the lowest point of the upper central's crown, averaged over both sides;
  - overjet: horizontal distance, along the upper central's labial direction, from the lower
    central's labial surface (the part overlapped by the upper incisor) to the upper incisal edge;
  - molar relation: how far the mesiobuccal cusp tip of the upper first molar lies mesial (+) or
    distal (-) of the buccal groove of the lower first molar, along the lower molar's mesial
    direction in the occlusal plane; 0 is Angle class I, about +half a cusp (2-3 mm) class II;
  - Bolton: lower over upper sum of mesiodistal crown widths, overall (first molar to first molar,
    12 teeth) and anterior (canine to canine, 6 teeth), widths measured along each tooth's mesial
    axis on its mesh.
"""

from __future__ import annotations

import numpy as np

from .dentition import Dentition

Poses = dict[int, np.ndarray]


def _crown_world(dent: Dentition, fdi: int, poses: Poses | None) -> np.ndarray:
    t = dent.teeth[fdi]
    return t.to_world(t.crown_vertices, None if poses is None else poses[fdi])


def _horizontal_direction(dent: Dentition, fdi: int, local_dir: np.ndarray, poses: Poses | None) -> np.ndarray:
    t = dent.teeth[fdi]
    T = t.rest_pose if poses is None else poses[fdi]
    d = T[:3, :3] @ local_dir
    d[1] = 0.0
    return d / np.linalg.norm(d)


def _incisor_pairs(dent: Dentition) -> list[tuple[int, int]]:
    return [(u, l) for u, l in ((11, 41), (21, 31)) if u in dent.teeth and l in dent.teeth]


def overbite(dent: Dentition, poses: Poses | None = None) -> float:
    """mm, mean vertical overlap of upper over lower central incisors."""
    values = [_crown_world(dent, l, poses)[:, 1].max() - _crown_world(dent, u, poses)[:, 1].min()
              for u, l in _incisor_pairs(dent)]
    return float(np.mean(values))


def overjet(dent: Dentition, poses: Poses | None = None) -> float:
    """mm, mean horizontal distance from the lower incisors' labial faces to the upper incisal edges."""
    values = []
    for u, l in _incisor_pairs(dent):
        upper = _crown_world(dent, u, poses)
        lower = _crown_world(dent, l, poses)
        labial = _horizontal_direction(dent, u, dent.teeth[u].labial, poses)
        edge = upper[np.argmin(upper[:, 1])]
        overlapped = lower[lower[:, 1] >= edge[1]]
        if len(overlapped) == 0:  # open bite: compare with the lower incisal edge itself
            overlapped = lower[np.argmax(lower[:, 1])][None]
        values.append(edge @ labial - (overlapped @ labial).max())
    return float(np.mean(values))


def molar_relation(dent: Dentition, poses: Poses | None = None) -> float:
    """mm, mesiobuccal cusp of the upper first molar relative to the lower buccal groove (0 = class I)."""
    values = []
    for u, l in ((16, 46), (26, 36)):
        if u not in dent.teeth or l not in dent.teeth:
            continue
        tu, tl = dent.teeth[u], dent.teeth[l]
        if "mb_cusp" not in tu.landmarks or "buccal_groove" not in tl.landmarks:
            continue
        cusp = tu.to_world(tu.landmarks["mb_cusp"], None if poses is None else poses[u])
        groove = tl.to_world(tl.landmarks["buccal_groove"], None if poses is None else poses[l])
        mesial = _horizontal_direction(dent, l, tl.mesial, poses)
        values.append((cusp - groove) @ mesial)
    return float(np.mean(values)) if values else float("nan")


def mesiodistal_width(dent: Dentition, fdi: int) -> float:
    """mm, the crown's extent along its own mesial axis (contact point to contact point)."""
    t = dent.teeth[fdi]
    along = t.crown_vertices @ t.mesial
    return float(along.max() - along.min())


def bolton_ratios(dent: Dentition) -> dict[str, float]:
    """Per cent: {'overall': 12-tooth ratio, 'anterior': 6-tooth ratio}, lower over upper widths."""
    def total(quads, positions):
        return sum(mesiodistal_width(dent, 10 * q + p) for q in quads for p in positions)

    return {
        "overall": 100 * total((3, 4), range(1, 7)) / total((1, 2), range(1, 7)),
        "anterior": 100 * total((3, 4), range(1, 4)) / total((1, 2), range(1, 4)),
    }

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
Real (scanned) molars carry no landmarks; theirs are found on the crown (`molar_landmark`): the
mesiobuccal cusp tip is the most occlusal crown vertex mesial and buccal of the crown's middle;
the buccal groove is the lowest point of the buccal cusp ridge between the mesiobuccal cusp and
the next buccal cusp distal of it. Occlusal contacts per pair are in `orthosim.analysis.occlusalcontacts`.
"""

from __future__ import annotations

import numpy as np

from orthosim.model.dentition import Dentition

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
        cusp = tu.to_world(molar_landmark(tu, "mb_cusp"), None if poses is None else poses[u])
        groove = tl.to_world(molar_landmark(tl, "buccal_groove"), None if poses is None else poses[l])
        mesial = _horizontal_direction(dent, l, tl.mesial, poses)
        values.append((cusp - groove) @ mesial)
    return float(np.mean(values)) if values else float("nan")


def molar_landmark(tooth, name: str) -> np.ndarray:
    """(3,) mm, local: the tooth's landmark `name` ("mb_cusp" or "buccal_groove"), from its model
    when it has one, else found on its crown (see the module docstring)."""
    if name in tooth.landmarks:
        return tooth.landmarks[name]
    crown = tooth.crown_vertices
    along = crown @ tooth.mesial  # mm toward the midline
    buccal = crown[:, 2]
    middle = 0.5 * (along.max() + along.min())
    outer = buccal > np.median(buccal)
    if name == "mb_cusp":
        pick = np.flatnonzero(outer & (along > middle))
        return crown[pick[np.argmax(crown[pick, 1])]].copy()
    if name != "buccal_groove":
        raise KeyError(name)
    # the buccal cusp ridge: the most occlusal buccal vertex in each 0.25 mm slice along the tooth
    edges = np.arange(along[outer].min(), along[outer].max() + 0.25, 0.25)
    slot = np.digitize(along[outer], edges)
    ridge = np.full(len(edges) + 1, -np.inf)
    np.maximum.at(ridge, slot, crown[outer, 1])
    centre = np.append(edges - 0.125, edges[-1] + 0.125)
    valid = np.isfinite(ridge)
    mesial_half = valid & (centre > middle)
    mb = int(np.flatnonzero(mesial_half)[np.argmax(ridge[mesial_half])])
    width = along.max() - along.min()
    distal = valid & (centre < centre[mb] - 0.2 * width) & (centre > centre[mb] - 0.6 * width)
    point = np.zeros(3)
    groove = mb
    if distal.any():
        db = int(np.flatnonzero(distal)[np.argmax(ridge[distal])])
        between = np.flatnonzero(valid[db:mb + 1]) + db
        groove = int(between[np.argmin(ridge[between])])
    point[0] = centre[groove] * tooth.mesial[0]  # back from "toward the midline" to local x
    point[1], point[2] = ridge[groove], buccal.max()
    return point


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

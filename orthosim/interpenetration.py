"""Interpenetration a model starts with: teeth a scan's segmentation left overlapping, measured per pair.

Segmented CBCT teeth often overlap their neighbours or the teeth they bite on by a fraction of a
millimetre where the segmentation met (a "segmentation touch"). That overlap is the patient's
rest state, not a collision: the simulator measures it once at load, reports it, and from then on
only stops a move that makes such a pair interpenetrate deeper (`orthosim.movement.simulation`).
Which pairs intersect is decided exactly on the meshes (FCL); how deep is the largest depth of any
vertex of one tooth inside the other (`geometry.meshquery.penetration_depth`), in mm.

The same measure sets how much the occlusal sliding rule lets teeth of the two arches sink while
they slide along each other (`default_occlusal_slide_mm`): where a model's surfaces already
overlap by that much at rest, a slide adding less is within what the model can tell apart.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

from .dentition import Dentition


# The occlusal slide a model gets when its case sets none (mm): the touch tolerance at least (a
# parametric model, whose teeth meet without overlapping), and at most the upper end of the mesh
# noise of segmented scans at contacts (about 0.1-0.5 mm).
SLIDE_MIN_MM = 0.05
SLIDE_MAX_MM = 0.5


class ScanInterpenetrationWarning(UserWarning):
    """A loaded model has teeth that interpenetrate at rest; the message names the pairs and depths."""


def rest_interpenetration(dentition: Dentition, pairs=None) -> dict[tuple[int, int], float]:
    """(a, b) -> mm for each pair whose meshes intersect at their rest poses.

    `pairs`: the pairs to check (by default the simulator's candidates: arch neighbours and facing
    teeth of the other arch). A pair FCL finds intersecting keeps its entry even when no vertex
    lies inside the other mesh (edge-edge crossings): its depth is then 0.0 mm.
    """
    from .collision import candidate_pairs
    from .geometry import meshquery

    if pairs is None:
        pairs = candidate_pairs(dentition.fdis)
    objects = {}
    for n in {t for pair in pairs for t in pair}:
        objects[n] = meshquery.fcl_object(dentition.teeth[n].mesh)
        meshquery.set_pose(objects[n], dentition.teeth[n].rest_pose)
    out = {}
    for a, b in pairs:
        if meshquery.collide(objects[a], objects[b])[0]:
            ta, tb = dentition.teeth[a], dentition.teeth[b]
            out[(a, b)] = meshquery.penetration_depth(ta.mesh, ta.rest_pose, tb.mesh, tb.rest_pose)
    return out


def report_rest_interpenetration(dentition: Dentition, where) -> Dentition:
    """The dentition with `info["rest_interpenetration_mm"]` ("a-b" -> mm, deepest first), and one
    `ScanInterpenetrationWarning` line naming the pairs when there are any."""
    depths = rest_interpenetration(dentition)
    ranked = sorted(depths.items(), key=lambda kv: -kv[1])
    info = dict(dentition.info)
    info["rest_interpenetration_mm"] = {f"{a}-{b}": round(d, 4) for (a, b), d in ranked}
    if ranked:
        listed = ", ".join(f"{a}-{b} {d:.2f} mm" for (a, b), d in ranked)
        warnings.warn(f"{where}: {len(ranked)} tooth pairs interpenetrate in the scan ({listed}); "
                      "taken as the rest state, not as collisions", ScanInterpenetrationWarning, stacklevel=3)
    return replace(dentition, info=info)


def default_occlusal_slide_mm(dentition: Dentition) -> float:
    """mm teeth of the two arches in contact may sink deeper than at rest while sliding, when the
    case does not say: the deepest interpenetration the model has at rest (any pair, as measured at
    load, `info["rest_interpenetration_mm"]`), within SLIDE_MIN_MM..SLIDE_MAX_MM. Patient 26 of
    Open-Full-Jaw: 0.30 mm (26-37); parametric teeth: 0.05 mm."""
    depths = dentition.info.get("rest_interpenetration_mm") or {}
    deepest = max((float(d) for d in depths.values()), default=0.0)
    return float(min(max(deepest, SLIDE_MIN_MM), SLIDE_MAX_MM))

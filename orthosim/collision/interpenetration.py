"""Interpenetration a model starts with: teeth a scan's segmentation left overlapping, measured per pair.

Segmented CBCT teeth often overlap their neighbours or the teeth they bite on by a fraction of a
millimetre where the segmentation met (a "segmentation touch"). That overlap is the patient's
rest state, not a collision: the simulator measures it once at load, reports it, and from then on
only stops a move that makes such a pair interpenetrate deeper (`orthosim.movement.simulation`).
Which pairs intersect is decided exactly on the meshes (FCL); how deep is measured on every point of
their triangles and by the largest ball inside both (`geometry.penetration.penetration_depth`), in
mm, so that two teeth at the same place, or crossing edge to edge, read a real depth (a vertex-based
depth reads 0 for both). Meshes that are not closed and consistently oriented have no reliable
inside for that measure and get the vertex-based one (`geometry.meshquery.penetration_depth`).

The same measure sets how much the occlusal sliding rule lets teeth of the two arches sink while
they slide along each other (`default_occlusal_slide_mm`): where a model's surfaces already
overlap by that much at rest, a slide adding less is within what the model can tell apart.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

from orthosim.model.dentition import Dentition


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
    lies inside the other mesh and no ball fits inside both (surfaces crossing by less than the
    depth measure's 0.01 mm tolerance): its depth is then about 0.0 mm.
    """
    from orthosim.collision import candidate_pairs
    from orthosim.geometry import meshquery

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
            out[(a, b)] = pair_depth(ta.mesh, ta.rest_pose, tb.mesh, tb.rest_pose)
    return out


def pair_depth(mesh_a, pose_a, mesh_b, pose_b) -> float:
    """mm two posed tooth meshes interpenetrate: `geometry.penetration.penetration_depth` for closed,
    consistently oriented meshes, else the vertex-based `geometry.meshquery.penetration_depth`."""
    from orthosim.geometry import meshquery
    from orthosim.geometry.penetration import penetration_depth
    from orthosim.geometry.signeddistance import mesh_surface

    if mesh_surface(mesh_a).closed and mesh_surface(mesh_b).closed:  # both have an inside
        return penetration_depth(mesh_a, pose_a, mesh_b, pose_b)
    return meshquery.penetration_depth(mesh_a, pose_a, mesh_b, pose_b)


def start_depths(dentition: Dentition, penetrating, poses) -> list[tuple[tuple[int, int], float]]:
    """The depth of each pair interpenetrating at a run's start, deepest first: the larger of the
    run's own reading (`penetrating`: ((a, b), mm) for the pairs whose meshes intersect, from its
    exact queries, on vertices and edges: about 0 for two teeth at the same place) and `pair_depth` at `poses`, or
    for a pair at its rest poses the depth measured at load (`info["rest_interpenetration_mm"]`)."""
    import numpy as np

    measured = dentition.info.get("rest_interpenetration_mm") or {}
    out = {}
    for (a, b), mm in penetrating:
        ta, tb = dentition.teeth[a], dentition.teeth[b]
        at_rest = all(np.array_equal(np.asarray(poses[t.fdi], float), np.asarray(t.rest_pose, float)) for t in (ta, tb))
        known = measured.get(f"{a}-{b}", measured.get(f"{b}-{a}")) if at_rest else None
        depth = float(known) if known is not None else pair_depth(ta.mesh, poses[a], tb.mesh, poses[b])
        out[(a, b)] = max(float(mm), depth)
    return sorted(out.items(), key=lambda kv: -kv[1])


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

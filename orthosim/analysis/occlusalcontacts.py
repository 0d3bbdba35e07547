"""Occlusal contacts: where and how much the upper and lower teeth meet, per facing pair, on the exact meshes.

The paper's Figure 7 shows the occlusal contact areas of a bite. Here a facing pair (an upper
tooth and a lower tooth of the opposing quadrant, `collision.broadphase.facing_pairs`) is in
contact when its meshes lie within `CONTACT_BAND_MM` of each other (FCL distance; 0 when they
interpenetrate, as segmented scans often do). Its contact area on each tooth is the surface of
that tooth's faces whose centres lie inside the other tooth or within the band of its surface
(signed distance, trimesh), in mm^2; the centres of those faces are kept to draw the areas.
The band stands for the thickness of articulating paper (40-100 um), the clinician's own test.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from orthosim.model.dentition import Dentition

CONTACT_BAND_MM = 0.1  # mm: surfaces this close count as in contact


@dataclass(frozen=True, eq=False)
class OcclusalContact:
    """One facing pair's contact: distance (mm, 0 when interpenetrating), deepest interpenetration
    (mm), contact area on the upper and on the lower tooth (mm^2), and the arch-frame centres (mm)
    of the faces in contact on each (`points_upper` (k, 3), `points_lower` (m, 3))."""

    pair: tuple[int, int]  # (upper FDI, lower FDI)
    distance_mm: float
    depth_mm: float
    area_upper_mm2: float
    area_lower_mm2: float
    points_upper: np.ndarray
    points_lower: np.ndarray

    @property
    def in_contact(self) -> bool:
        return self.area_upper_mm2 > 0.0 or self.area_lower_mm2 > 0.0

    def summary(self) -> dict:
        return {"pair": list(self.pair), "distance_mm": round(self.distance_mm, 4), "depth_mm": round(self.depth_mm, 4),
                "area_upper_mm2": round(self.area_upper_mm2, 3), "area_lower_mm2": round(self.area_lower_mm2, 3)}


def occlusal_contacts(dent: Dentition, poses: dict[int, np.ndarray] | None = None, absent=frozenset(),
                      band_mm: float = CONTACT_BAND_MM) -> list[OcclusalContact]:
    """Every facing pair of present teeth with its contact (in contact or not), upper arch right to left."""
    from orthosim.collision import facing_pairs
    from orthosim.geometry import meshquery

    poses = poses if poses is not None else dent.rest_poses()
    out = []
    objects: dict = {}
    for u, lo in facing_pairs(dent.fdis, absent):
        for n in (u, lo):
            if n not in objects:
                objects[n] = meshquery.fcl_object(dent.teeth[n].mesh)
            meshquery.set_pose(objects[n], poses[n])
        gap = meshquery.distance(objects[u], objects[lo])
        empty = np.zeros((0, 3))
        if gap > band_mm:
            out.append(OcclusalContact((u, lo), gap, 0.0, 0.0, 0.0, empty, empty))
            continue
        tu, tl = dent.teeth[u], dent.teeth[lo]
        depth = meshquery.penetration_depth(tu.mesh, poses[u], tl.mesh, poses[lo]) if gap <= 0.0 else 0.0
        area_u, pts_u = _contact_faces(tu.mesh, poses[u], tl.mesh, poses[lo], band_mm)
        area_l, pts_l = _contact_faces(tl.mesh, poses[lo], tu.mesh, poses[u], band_mm)
        out.append(OcclusalContact((u, lo), gap, depth, area_u, area_l, pts_u, pts_l))
    return out


def _contact_faces(mesh: trimesh.Trimesh, pose: np.ndarray, other: trimesh.Trimesh, other_pose: np.ndarray,
                   band_mm: float) -> tuple[float, np.ndarray]:
    """(mm^2, (k, 3) arch-frame face centres) of `mesh`'s faces within the band of `other` or inside it."""
    M = np.linalg.inv(other_pose) @ pose  # mesh local -> other local
    centres = mesh.triangles_center @ M[:3, :3].T + M[:3, 3]
    # only face centres near the other surface can be within the band: a k-d tree on its vertices
    # finds them (a face centre within the band lies within band + longest edge of some vertex)
    reach = band_mm + float(other.edges_unique_length.max())
    gap, _ = cKDTree(other.vertices).query(centres, distance_upper_bound=reach)
    near = np.flatnonzero(np.isfinite(gap))
    if not len(near):
        return 0.0, np.zeros((0, 3))
    signed = _signed_distance(other, centres[near])
    hit = near[signed >= -band_mm]
    world = mesh.triangles_center[hit] @ pose[:3, :3].T + pose[:3, 3]
    return float(mesh.area_faces[hit].sum()), world


def _signed_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """mm from each point to the closed `mesh`'s surface, positive inside.

    The sign comes from the outward normal of the closest face rather than from trimesh's ray-cast
    inside test (`proximity.signed_distance`, ten times slower here): for points within a fraction
    of a millimetre of a smooth closed surface, which is all this module asks about, both agree.
    """
    closest, distance, face = trimesh.proximity.closest_point(mesh, points)
    inside = np.einsum("ij,ij->i", closest - points, mesh.face_normals[face]) > 0.0
    return np.where(inside, distance, -distance)


def occlusion_record(dent: Dentition, contacts: list[OcclusalContact] | None = None) -> dict:
    """The occlusal measures of a dentition at rest, ready for JSON: overjet, overbite, molar relation
    (mm), Bolton ratios (%), and the facing pairs in contact with their areas."""
    from orthosim.model.fdi import QUADRANTS
    from orthosim.analysis.metrics import occlusion_summary
    from orthosim.model.occlusion import bolton_ratios

    contacts = occlusal_contacts(dent) if contacts is None else contacts
    complete = all(10 * q + p in dent.teeth for q in QUADRANTS for p in range(1, 7))
    return {
        **(occlusion_summary(dent) or {}),
        "bolton_percent": bolton_ratios(dent) if complete else None,
        "contact_band_mm": CONTACT_BAND_MM,
        "contacts": [c.summary() for c in contacts if c.in_contact],
        "rest_interpenetration_mm": dent.info.get("rest_interpenetration_mm", {}),
    }

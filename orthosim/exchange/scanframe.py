"""One scan, several folders, one rigid map: teeth segmented in a scan's frame placed in the arch frame.

A scan (CBCT, intraoral) gives every tooth of both arches in its own coordinate frame, upper and
lower teeth standing as the patient bit. Whatever folders the teeth come in (`maxilla/`,
`mandible/`, one per quadrant), they share that frame, so ONE rigid transform (rotation and
translation, never a scale or a mirror) maps them all into the arch frame (`orthosim.model.dentition`):
every distance between any two teeth, upper or lower, is kept, and with it the scanned bite.
`place_scan` fits that transform from the teeth's axes in the scan frame and returns the teeth in
the arch frame; `scan_to_arch` is the fit itself:
  y  normal of the plane fitted (SVD) through the crown centres (each the centroid of the tooth's
     part coronal of its estimated CEJ, as every report uses), signed so upper long axes
     (apex -> crown) point to -y and lower ones to +y;
  z  in that plane, from the centroid of the crown centres toward the midpoint of the central
     incisors (the nearest-to-midline pair present on both sides, both arches averaged), anterior;
  x  = y cross z, which must put the patient's right teeth at negative x (checked: a mirrored
     scan or a wrong numbering raises `MeshError`; nothing here ever mirrors);
  origin: x and z at the centroid of the crown centres (on the midline by construction of z),
     y = 0 at the mean of the teeth's occlusal-most points (lowest upper / highest lower vertex).
Only teeth with trusted axes (`fit_teeth`) enter the fit, so an estimated axis cannot tilt the frame.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import trimesh

from orthosim.model import fdi as fdi_mod
from orthosim.errors import MeshError
from orthosim.model.fdi import Arch
from orthosim.exchange.meshload import ToothAxes, tooth_from_mesh
from orthosim.model.tooth import Tooth

ORIGIN_RULE = (
    "x, z: centroid of the crown centres projected into their best-fit plane; "
    "y = 0: mean of the teeth's occlusal-most vertices (min y upper, max y lower)"
)


def place_scan(where: str | Path, meshes: dict[int, trimesh.Trimesh], axes: dict[int, ToothAxes],
               sources: dict[int, str], fit_teeth: set[int] | None = None) -> tuple[dict[int, Tooth], np.ndarray]:
    """Teeth of one scan in the arch frame, and the 4x4 rigid scan -> arch transform (mm).

    `meshes`, `axes`: FDI -> mesh and axes, both in the scan frame. `fit_teeth`: the teeth whose
    crown centres and long axes fit the frame (all by default). Each tooth is built in the scan
    frame first (`tooth_from_mesh`: its crown centre is what the frame is fitted to) and then moved
    by the one transform, so `tooth.world_mesh()` is the file's geometry under that transform.
    """
    order = sorted(meshes)
    in_scan = {n: tooth_from_mesh(n, meshes[n], axes[n], source=sources[n]) for n in order}
    fit = sorted(fit_teeth if fit_teeth is not None else order)
    centre = {n: in_scan[n].to_world(in_scan[n].crown_center) for n in fit}
    long_axis = {n: np.asarray(axes[n].long_axis, float) / np.linalg.norm(axes[n].long_axis) for n in fit}
    T = scan_to_arch(where, fit, centre, long_axis, meshes)
    return {n: replace(in_scan[n], rest_pose=T @ in_scan[n].rest_pose) for n in order}, T


def scan_to_arch(where, order, centre, long_axis, meshes) -> np.ndarray:
    """The one rigid 4x4 transform scan frame -> arch frame (see the module docstring)."""
    C = np.array([centre[n] for n in order])
    centroid = C.mean(axis=0)
    _, s, vt = np.linalg.svd(C - centroid)
    if len(order) < 3 or s[1] < 1e-3 * s[0]:
        raise MeshError(where, "c", "the crown centres lie on a line, so no occlusal plane can be fitted",
                        "give at least 3 teeth with axes, spread along the arch")
    y = vt[2]
    # Upper long axes should point to -y and lower ones to +y: sign the normal by their sum.
    toward_occlusal = sum((1.0 if fdi_mod.arch_of(n) is Arch.UPPER else -1.0) * long_axis[n] for n in order)
    if toward_occlusal @ y > 0:
        y = -y

    mid = None
    for pos in (1, 2, 3):
        pairs = [(10 + pos, 20 + pos), (40 + pos, 30 + pos)]
        found = [(centre[a] + centre[b]) / 2 for a, b in pairs if a in centre and b in centre]
        if found:
            mid = np.mean(found, axis=0)
            break
    if mid is None:
        raise MeshError(where, None, "no incisor or canine pair on both sides of the midline, so the anterior "
                        "direction is unknown", "the importer needs e.g. both central incisors (11 and 21)")
    z = mid - centroid
    z -= y * (z @ y)
    if np.linalg.norm(z) < 1.0:
        raise MeshError(where, "c", "the incisors sit at the centroid of the crown centres", "check the axes")
    z /= np.linalg.norm(z)
    x = np.cross(y, z)

    T = np.eye(4)
    T[:3, :3] = np.array([x, y, z])  # rows: arch axes in scan coordinates, so R @ p gives arch coords
    T[:3, 3] = -T[:3, :3] @ centroid
    occlusal = []
    for n in order:
        ys = meshes[n].vertices @ T[1, :3] + T[1, 3]
        occlusal.append(ys.min() if fdi_mod.arch_of(n) is Arch.UPPER else ys.max())
    T[1, 3] -= float(np.mean(occlusal))

    right = [(T[:3, :3] @ centre[n])[0] for n in order if fdi_mod.side(n) < 0]
    left = [(T[:3, :3] @ centre[n])[0] for n in order if fdi_mod.side(n) > 0]
    if right and left and not np.mean(right) < np.mean(left):
        raise MeshError(where, None, "the patient's right teeth come out on the left: the scan is mirrored or "
                        "the tooth numbering is swapped", "check the tooth numbers of the mesh files")
    return T

"""Importer for the Open-Full-Jaw dataset layout: CBCT-segmented teeth in a scan frame, mapped into the arch frame.

A folder holds `tooth_N.stl` (N the Universal tooth number, crown plus roots, mm, scan frame) and
one or more `teeth_axes_*.json` giving, per Universal number, `c` (crown centre of mass) and the
end points `x`, `y`, `z` of three unit axes from `c`. Measured on Patient 26: `z - c` points from
the root toward the crown (the mesh reaches 4-6 mm beyond `c` along it and 12-18 mm behind), `y - c`
is labial/buccal, and `x - c` points DISTALLY on every tooth although the dataset describes it as
mesial; so only `z` and `y` are used (the local x axis is y cross z per `orthosim.tooth`) and the
sense of `x` found is recorded in `info`. The whole jaw is moved into the arch frame
(`orthosim.dentition`) by ONE rigid transform, so the teeth keep their true relative positions:
  y  normal of the plane fitted (SVD) through the crown centres (each the centroid of the tooth's
     part coronal of its estimated CEJ, as every report uses), signed so upper long axes
     (apex -> crown) point to -y and lower ones to +y;
  z  in that plane, from the centroid of the crown centres toward the midpoint of the central
     incisors (the nearest-to-midline pair present on both sides), i.e. anterior;
  x  = y cross z, which must put the patient's right teeth at negative x (checked: a mirrored
     scan or a wrong numbering raises `MeshError`; the importer never mirrors);
  origin: x and z at the centroid of the crown centres (on the midline by construction of z),
     y = 0 at the mean of the teeth's occlusal-most points (lowest upper / highest lower vertex).
Each tooth's CEJ is estimated as in `orthosim.meshload.CEJ_RULE`.
"""

from __future__ import annotations

import json
import re
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from . import fdi as fdi_mod
from .dentition import Dentition
from .errors import MeshError
from .fdi import Arch
from .meshload import CEJ_RULE, MeshRepairWarning, ToothAxes, load_tooth_mesh, tooth_from_mesh

_TOOTH_FILE = re.compile(r"^tooth_(\d+)\.stl$", re.IGNORECASE)

ORIGIN_RULE = (
    "x, z: centroid of the crown centres projected into their best-fit plane; "
    "y = 0: mean of the teeth's occlusal-most vertices (min y upper, max y lower)"
)


def load_open_full_jaw(folder: str | Path) -> Dentition:
    """A `Dentition` in the arch frame from an Open-Full-Jaw folder (`tooth_N.stl` + `teeth_axes_*.json`).

    `info` records the source folder, `scan_to_arch` (4x4 rigid transform, scan frame -> arch
    frame, mm), the origin and CEJ rules, the Universal -> FDI numbering used and the measured
    sense of the json `x` axes.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise MeshError(folder, None, "folder not found", "check the path to the Open-Full-Jaw folder")
    files: dict[int, Path] = {}
    for path in sorted(folder.iterdir()):
        match = _TOOTH_FILE.match(path.name)
        if match:
            files[int(match.group(1))] = path
    if len(files) < 3:
        raise MeshError(folder, None, f"holds {len(files)} tooth_N.stl files; the arch frame needs at least 3 teeth",
                        "point to an Open-Full-Jaw maxilla or mandible folder")
    axes_raw, axes_file = _read_axes(folder)

    fdi_of: dict[int, int] = {}
    for universal in files:
        try:
            fdi_of[universal] = fdi_mod.universal_to_fdi(universal)
        except ValueError:
            raise MeshError(files[universal], None, f"{universal} is not a Universal tooth number (1-32)",
                            "rename the file tooth_N.stl with N in 1-32") from None
        if str(universal) not in axes_raw:
            raise MeshError(axes_file, str(universal), f"no axes for {files[universal].name}",
                            "add the tooth's c, x, y, z entry or remove the mesh")

    centre, long_axis, labial, x_end = {}, {}, {}, {}
    meshes = {}
    for universal, path in files.items():
        n = fdi_of[universal]
        c, xe, ye, ze = (_point(axes_raw, axes_file, universal, key) for key in ("c", "x", "y", "z"))
        meshes[n] = load_tooth_mesh(path)
        centre[n], x_end[n] = c, xe - c
        long_axis[n] = _unit(ze - c, axes_file, f"{universal}.z")
        labial[n] = _unit(ye - c, axes_file, f"{universal}.y")
        # The dataset's z points root -> crown; a flipped entry would put the root on top, so
        # check it against the mesh: the crown centre is nearer the crown end than the apex.
        along = (meshes[n].vertices - c) @ long_axis[n]
        if along.max() > -along.min():
            warnings.warn(f"{axes_file}: {universal}.z points toward the root of {path.name}; reversed it",
                          MeshRepairWarning, stacklevel=2)
            long_axis[n] = -long_axis[n]

    order = sorted(meshes)
    path_of = {fdi_of[u]: p for u, p in files.items()}
    # Build each tooth in the scan frame first: its crown centre (the centroid of the part coronal
    # of the estimated CEJ) is what the arch frame is fitted to, the same centre every report uses.
    in_scan = {n: tooth_from_mesh(n, meshes[n], ToothAxes(long_axis=long_axis[n], labial=labial[n], point=centre[n]),
                                  source=str(path_of[n])) for n in order}
    crown_centre = {n: t.to_world(t.crown_center) for n, t in in_scan.items()}
    scan_to_arch = _scan_to_arch(folder, order, crown_centre, long_axis, meshes)
    R = scan_to_arch[:3, :3]

    teeth = {}
    x_sense = {"mesial": 0, "distal": 0}
    for n in order:
        tooth = replace(in_scan[n], rest_pose=scan_to_arch @ in_scan[n].rest_pose)
        teeth[n] = tooth
        mesial_arch = tooth.rest_pose[:3, :3] @ tooth.mesial
        x_sense["mesial" if (R @ x_end[n]) @ mesial_arch > 0 else "distal"] += 1

    info = {
        "source": str(folder),
        "axes_file": str(axes_file),
        "scan_to_arch": scan_to_arch,
        "origin_rule": ORIGIN_RULE,
        "cej_rule": CEJ_RULE,
        "universal_to_fdi": dict(sorted(fdi_of.items())),
        "json_axes": "z - c: apex -> crown (long axis); y - c: labial; x - c: unused (local x = y cross z)",
        "json_x_sense": x_sense,
    }
    return Dentition(teeth, f"Open-Full-Jaw teeth from {folder}", info)


def _scan_to_arch(folder, order, centre, long_axis, meshes) -> np.ndarray:
    """The one rigid 4x4 transform scan frame -> arch frame for the whole jaw (see the module docstring)."""
    C = np.array([centre[n] for n in order])
    centroid = C.mean(axis=0)
    _, s, vt = np.linalg.svd(C - centroid)
    if s[1] < 1e-3 * s[0]:
        raise MeshError(folder, "c", "the crown centres lie on a line, so no occlusal plane can be fitted",
                        "check the axes file")
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
        raise MeshError(folder, None, "no incisor or canine pair on both sides of the midline, so the anterior "
                        "direction is unknown", "the importer needs e.g. both central incisors (11 and 21)")
    z = mid - centroid
    z -= y * (z @ y)
    if np.linalg.norm(z) < 1.0:
        raise MeshError(folder, "c", "the incisors sit at the centroid of the crown centres", "check the axes file")
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
        raise MeshError(folder, None, "the patient's right teeth come out on the left: the scan is mirrored or "
                        "the tooth numbering is swapped", "check the Universal numbers of the tooth_N.stl files")
    return T


def _read_axes(folder: Path) -> tuple[dict, Path]:
    paths = sorted(folder.glob("teeth_axes_*.json"))
    if not paths:
        raise MeshError(folder, None, "no teeth_axes_*.json file", "add the dataset's axes file to the folder")
    merged: dict = {}
    for path in paths:
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise MeshError(path, None, f"cannot be read as JSON ({exc})", "restore the file from the dataset") from None
        if not isinstance(data, dict):
            raise MeshError(path, None, "is not a JSON object keyed by tooth number", "restore the file from the dataset")
        merged.update(data)
    return merged, paths[0] if len(paths) == 1 else folder


def _point(axes_raw: dict, axes_file: Path, universal: int, key: str) -> np.ndarray:
    entry = axes_raw[str(universal)]
    value = entry.get(key) if isinstance(entry, dict) else None
    try:
        p = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        p = np.empty(0)
    if p.shape != (3,) or not np.isfinite(p).all():
        raise MeshError(axes_file, f"{universal}.{key}", "must be a list of 3 finite numbers (mm)",
                        "restore the file from the dataset")
    return p


def _unit(v: np.ndarray, where, field: str) -> np.ndarray:
    norm = float(np.linalg.norm(v))
    if norm < 1e-9:
        raise MeshError(where, field, "end point equals the crown centre c (zero-length axis)",
                        "restore the file from the dataset")
    return v / norm

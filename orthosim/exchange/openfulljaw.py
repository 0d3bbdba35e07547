"""Importer for the Open-Full-Jaw dataset layout: CBCT-segmented teeth in a scan frame, mapped into the arch frame.

A folder holds `tooth_N.stl` (N the Universal tooth number, crown plus roots, mm, scan frame) and
one or more `teeth_axes_*.json` giving, per Universal number, `c` (crown centre of mass) and the
end points `x`, `y`, `z` of three unit axes from `c`. Measured on Patient 26: `z - c` points from
the root toward the crown (the mesh reaches 4-6 mm beyond `c` along it and 12-18 mm behind), `y - c`
is labial/buccal, and `x - c` points DISTALLY on every tooth although the dataset describes it as
mesial; so only `z` and `y` are used (the local x axis is y cross z per `orthosim.model.tooth`) and the
sense of `x` found is recorded in `info`.

Several folders of one scan (`maxilla/` and `mandible/`, or the patient folder holding both) load
as one model: they share the scan frame, so ONE rigid transform (`orthosim.exchange.scanframe`) maps all
their teeth and the scanned bite is kept exactly. A mesh without an axes entry (the dataset's lower
third molars) gets axes estimated from its shape, with a one-line `AxesEstimatedWarning` naming
it: the long axis is the mean of the mesh's principal axis and its arch neighbours' given long
axes (`estimated_axes`), the labial direction its nearest neighbour's with axes. Teeth with
estimated axes do not enter the frame fit. Teeth that interpenetrate in the scan (segmentation
touches) are measured per pair and reported (`orthosim.collision.interpenetration`).
Each tooth's CEJ is estimated as in `orthosim.exchange.meshload.CEJ_RULE`.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Sequence

import numpy as np

from orthosim.model import fdi as fdi_mod
from orthosim.model.dentition import Dentition
from orthosim.errors import MeshError
from orthosim.collision.interpenetration import report_rest_interpenetration
from orthosim.exchange.meshload import CEJ_RULE, DEFAULT_MAX_TRIANGLES, MeshRepairWarning, ToothAxes, load_tooth_mesh, principal_long_axis
from orthosim.exchange.scanfolders import _TOOTH_FILE, scan_folders
from orthosim.exchange.scanframe import ORIGIN_RULE, place_scan

# A mesh longer than this times its next-widest extent has a principal axis to trust as long axis
# (patient 26: 1.55-2.4 for the teeth with axes, 1.26-1.28 for the squat lower third molars).
LONG_AXIS_MIN_RATIO = 1.45


class AxesEstimatedWarning(UserWarning):
    """A tooth mesh had no axes entry; its axes were estimated from the mesh (the message names it)."""


def load_open_full_jaw(folder: str | Path | Sequence[str | Path],
                       max_triangles: int | None = DEFAULT_MAX_TRIANGLES) -> Dentition:
    """A `Dentition` in the arch frame from Open-Full-Jaw folders of one scan (`tooth_N.stl` + `teeth_axes_*.json`).

    `folder`: one folder, a list of folders of the same scan, or a patient folder holding
    `maxilla/` and `mandible/`. `info` records the source folders, `scan_to_arch` (4x4 rigid
    transform, scan frame -> arch frame, mm), the origin and CEJ rules, the Universal -> FDI
    numbering used, the teeth whose axes were estimated, the measured sense of the json `x` axes
    and the scan's interpenetrating pairs (`rest_interpenetration_mm`). A tooth of more than
    `max_triangles` triangles is simplified to that budget (`orthosim.exchange.meshload.load_tooth_mesh`).
    """
    folders = scan_folders(folder)
    where = folders[0] if len(folders) == 1 else " + ".join(str(f) for f in folders)
    files, axes_raw, axes_file_of = _scan_files(folders, where)
    fdi_of = _fdi_numbers(files)
    meshes = {fdi_of[u]: load_tooth_mesh(path, max_triangles=max_triangles) for u, path in files.items()}
    axes, x_end = _given_axes(files, fdi_of, meshes, axes_raw, axes_file_of)
    given = set(axes)
    if len(given) < 3:
        raise MeshError(where, None, f"only {len(given)} teeth have an axes entry; the arch frame needs at least 3",
                        "restore the dataset's teeth_axes_*.json")
    for universal, path in files.items():
        n = fdi_of[universal]
        if n not in axes:
            axes[n], note = estimated_axes(n, meshes[n], {m: axes[m] for m in given}, meshes)
            warnings.warn(f"{path}: no axes entry for Universal {universal} (FDI {n}, {fdi_mod.name(n)}); "
                          f"estimated from the mesh ({note})", AxesEstimatedWarning, stacklevel=2)

    path_of = {fdi_of[u]: p for u, p in files.items()}
    teeth, scan_to_arch = place_scan(where, meshes, axes, {n: str(p) for n, p in path_of.items()}, fit_teeth=given)
    R = scan_to_arch[:3, :3]
    x_sense = {"mesial": 0, "distal": 0}
    for n in sorted(x_end):
        mesial_arch = teeth[n].rest_pose[:3, :3] @ teeth[n].mesial
        x_sense["mesial" if (R @ x_end[n]) @ mesial_arch > 0 else "distal"] += 1

    dentition = Dentition(teeth, f"Open-Full-Jaw teeth from {where}", {
        "source": str(folders[0]) if len(folders) == 1 else [str(f) for f in folders],
        "axes_file": sorted({str(p) for p in axes_file_of.values()}),
        "scan_to_arch": scan_to_arch,
        "origin_rule": ORIGIN_RULE,
        "cej_rule": CEJ_RULE,
        "universal_to_fdi": dict(sorted(fdi_of.items())),
        "axes_estimated": sorted(set(teeth) - given),
        "json_axes": "z - c: apex -> crown (long axis); y - c: labial; x - c: unused (local x = y cross z)",
        "json_x_sense": x_sense,
    })
    return report_rest_interpenetration(dentition, where)


def _scan_files(folders: list[Path], where) -> tuple[dict[int, Path], dict, dict[str, Path]]:
    """Universal number -> tooth file, the axes entries and the axes file each came from, over the
    scan's folders; MeshError on a missing folder, a tooth given twice or fewer than 3 teeth."""
    files: dict[int, Path] = {}
    axes_raw: dict = {}
    axes_file_of: dict[str, Path] = {}
    for f in folders:
        if not f.is_dir():
            raise MeshError(f, None, "folder not found", "check the path to the Open-Full-Jaw folder")
        for path in sorted(f.iterdir()):
            match = _TOOTH_FILE.match(path.name)
            if match:
                universal = int(match.group(1))
                if universal in files:
                    raise MeshError(path, None, f"tooth {universal} is also in {files[universal]}",
                                    "give each tooth once across the scan's folders")
                files[universal] = path
        raw, axes_file = _read_axes(f)
        for key, entry in raw.items():
            axes_raw[key] = entry
            axes_file_of[key] = axes_file
    if len(files) < 3:
        raise MeshError(where, None, f"holds {len(files)} tooth_N.stl files; the arch frame needs at least 3 teeth",
                        "point to an Open-Full-Jaw maxilla or mandible folder")
    return files, axes_raw, axes_file_of


def _fdi_numbers(files: dict[int, Path]) -> dict[int, int]:
    """Universal -> FDI of each tooth file; MeshError naming a file whose number is not Universal."""
    fdi_of: dict[int, int] = {}
    for universal in files:
        try:
            fdi_of[universal] = fdi_mod.universal_to_fdi(universal)
        except ValueError:
            raise MeshError(files[universal], None, f"{universal} is not a Universal tooth number (1-32)",
                            "rename the file tooth_N.stl with N in 1-32") from None
    return fdi_of


def _given_axes(files, fdi_of, meshes, axes_raw, axes_file_of) -> tuple[dict[int, ToothAxes], dict[int, np.ndarray]]:
    """The dataset's own axes (FDI -> ToothAxes, scan frame) of the teeth that have an entry, and
    each one's json x direction (for the record of its sense)."""
    axes: dict[int, ToothAxes] = {}
    x_end = {}
    for universal, path in files.items():
        n = fdi_of[universal]
        if str(universal) not in axes_raw:
            continue
        axes_file = axes_file_of[str(universal)]
        c, xe, ye, ze = (_point(axes_raw, axes_file, universal, key) for key in ("c", "x", "y", "z"))
        x_end[n] = xe - c
        long_axis = _unit(ze - c, axes_file, f"{universal}.z")
        # The dataset's z points root -> crown; a flipped entry would put the root on top, so
        # check it against the mesh: the crown centre is nearer the crown end than the apex.
        along = (meshes[n].vertices - c) @ long_axis
        if along.max() > -along.min():
            warnings.warn(f"{axes_file}: {universal}.z points toward the root of {path.name}; reversed it",
                          MeshRepairWarning, stacklevel=3)
            long_axis = -long_axis
        axes[n] = ToothAxes(long_axis=long_axis, labial=_unit(ye - c, axes_file, f"{universal}.y"), point=c)
    return axes, x_end


def _arch_neighbours(n: int, given) -> list[int]:
    """The nearest teeth with axes on each side of `n` along its arch (one at an arch's end)."""
    order = fdi_mod.arch_order(fdi_mod.arch_of(n), set(given) | {n})
    i = order.index(n)
    return [order[j] for j in (i - 1, i + 1) if 0 <= j < len(order)]


def estimated_axes(n: int, mesh, given: dict[int, ToothAxes], meshes) -> tuple[ToothAxes, str]:
    """Axes of tooth `n` (FDI) that has no entry, from its mesh and its arch's given axes.

    `mesh`: the tooth; `given`: FDI -> axes of the teeth that have them; `meshes`: FDI -> mesh of
    those teeth; all in one frame (mm), the result in it too. The long axis is the mean of two
    estimates that err independently: the mesh's principal axis (`meshload.principal_long_axis`,
    signed like the arch's given long axes) and the mean given long axis of its arch neighbours
    (the nearest teeth with axes on each side). On Open-Full-Jaw patient 26, each of the 29 teeth
    with axes hidden in turn: 0.2-14.7 degrees from its own given axis (median 4.5), against
    0.8-17.9 (median 6.6) for the principal axis alone. The labial direction is the nearest
    neighbour's. A squat tooth whose principal axis is not clear takes its neighbours' mean.
    Returns the axes and a short note for the warning.
    """
    same_arch = [m for m in given if fdi_mod.arch_of(m) is fdi_mod.arch_of(n)]
    arch = same_arch or list(given)
    axis, centre = principal_long_axis(mesh)
    arch_up = sum(np.asarray(given[m].long_axis, float) for m in arch)
    if axis @ arch_up < 0:
        axis = -axis
    beside = _arch_neighbours(n, same_arch) if same_arch else \
        [min(arch, key=lambda m: np.linalg.norm(meshes[m].center_mass - mesh.center_mass))]
    nearest = min(beside, key=lambda m: np.linalg.norm(meshes[m].center_mass - mesh.center_mass))
    from_neighbours = sum(np.asarray(given[m].long_axis, float) / np.linalg.norm(given[m].long_axis) for m in beside)
    from_neighbours /= np.linalg.norm(from_neighbours)
    names = " and ".join(str(m) for m in beside)
    spread = np.sort(np.ptp((mesh.vertices - centre) @ np.linalg.svd(mesh.vertices - centre, full_matrices=False)[2].T,
                            axis=0))
    if spread[-1] < LONG_AXIS_MIN_RATIO * spread[-2]:
        # A squat tooth (a short-rooted third molar: 14 x 11 x 10 mm) has no clear principal axis;
        # its neighbours' long axis is the better guess.
        long_axis = from_neighbours
        note = (f"no clear principal axis ({spread[-1]:.1f} x {spread[-2]:.1f} mm), so the long axis of "
                f"{names} and the labial direction of {nearest}")
    else:
        tilt = float(np.degrees(np.arccos(np.clip(axis @ from_neighbours, -1.0, 1.0))))
        long_axis = (axis + from_neighbours) / np.linalg.norm(axis + from_neighbours)
        note = (f"mean of its principal axis and the long axis of {names}, {tilt:.0f} degrees apart; "
                f"labial direction of {nearest}")
    return ToothAxes(long_axis=long_axis, labial=np.asarray(given[nearest].labial, float), point=centre), note


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

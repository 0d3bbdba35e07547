"""A folder of per-tooth meshes as one dentition: in the arch frame, or in one scan's frame.

Each file is one tooth (`orthosim.exchange.meshload` loads and checks it); its FDI number comes
from a mapping or from the last number in its name. In a scan's frame, ONE rigid transform
(`orthosim.exchange.scanframe`) maps every tooth into the arch frame and keeps the scanned bite.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from orthosim.collision.interpenetration import report_rest_interpenetration
from orthosim.errors import MeshError
from orthosim.exchange.meshload import (CEJ_RULE, DEFAULT_MAX_TRIANGLES, MESH_SUFFIXES, ToothAxes, estimate_axes,
                                        estimate_scan_axes, load_tooth_mesh, tooth_from_mesh)
from orthosim.exchange.scanframe import ORIGIN_RULE, place_scan
from orthosim.model import fdi as fdi_mod
from orthosim.model.dentition import Dentition
from orthosim.model.fdi import Arch


def load_mesh_folder(
    folder: str | Path,
    mapping: dict[str, int] | None = None,
    *,
    scale: float = 1.0,
    axes: dict[int, ToothAxes] | None = None,
    description: str = "",
    frame: str = "arch",
    max_triangles: int | None = DEFAULT_MAX_TRIANGLES,
) -> Dentition:
    """A `Dentition` from a folder of per-tooth meshes (mm), in the arch frame or in one scan's frame.

    frame="arch": the meshes are ALREADY IN THE ARCH FRAME. frame="scan": they are in one scan's
    frame (e.g. `maxilla/...` and `mandible/...` of one CBCT, named in `mapping` with their
    subfolder): every tooth's axes are estimated in that frame (`estimate_scan_axes`) and ONE
    rigid transform (`orthosim.exchange.scanframe`) maps them all into the arch frame, keeping the bite.

    `mapping`: file name relative to `folder` -> FDI number. Without it every STL/OBJ/PLY file in
    the folder is used and its FDI number is the last number in its name (`11.stl`,
    `tooth_21.obj`, `UL6_26.ply`). `axes`: optional FDI -> `ToothAxes` (arch frame); teeth without
    one get axes from `estimate_axes` (PCA long axis toward the occlusal plane, labial away from
    the centroid of their arch). `scale` multiplies every mesh (e.g. 1000 for metres). A mesh of
    more than `max_triangles` triangles is simplified to that budget (`load_tooth_mesh`).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise MeshError(folder, None, "folder not found", "check the path")
    if mapping is None:
        mapping = _mapping_from_names(folder)
    if not mapping:
        raise MeshError(folder, None, "holds no STL, OBJ or PLY tooth meshes", "check the folder")
    files: dict[int, Path] = {}
    for name, number in mapping.items():
        if not fdi_mod.is_fdi(number):
            raise MeshError(folder, f"mapping[{name!r}]", f"{number!r} is not an FDI tooth number",
                            "use two-digit FDI numbers 11-18, 21-28, 31-38, 41-48")
        if number in files:
            raise MeshError(folder, f"mapping[{name!r}]", f"FDI {number} is also given to {files[number].name}",
                            "map each tooth number to one file")
        files[number] = folder / name

    meshes = {n: load_tooth_mesh(p, scale=scale, max_triangles=max_triangles) for n, p in files.items()}
    if frame == "scan":
        teeth, T = place_scan(folder, meshes, estimate_scan_axes(meshes), {n: str(p) for n, p in files.items()})
        info = {"source": str(folder), "files": {n: str(p) for n, p in files.items()}, "scale": scale,
                "frame": "one scan frame, mapped into the arch frame by one rigid transform", "scan_to_arch": T,
                "origin_rule": ORIGIN_RULE, "axes_estimated": sorted(teeth), "cej_rule": CEJ_RULE}
        return report_rest_interpenetration(Dentition(teeth, description or f"scanned meshes from {folder}", info), folder)
    if frame != "arch":
        raise MeshError(folder, "frame", f"unknown frame {frame!r}", 'use "arch" or "scan"')
    axes = dict(axes or {})
    given = set(axes)
    for arch in (Arch.UPPER, Arch.LOWER):
        members = [n for n in meshes if fdi_mod.arch_of(n) is arch]
        # The arch centroid is a good inside point once the arch has a few teeth; with fewer the
        # frame origin (mid-arch by the arch frame's definition) is the only reference there is.
        if len(members) >= 3:
            arch_center = np.mean([meshes[n].center_mass for n in members], axis=0)
        else:
            arch_center = np.zeros(3)
        for n in members:
            if n not in axes:
                axes[n] = estimate_axes(n, meshes[n], arch_center, str(files[n]))
    teeth = {n: tooth_from_mesh(n, meshes[n], axes[n], source=str(files[n])) for n in meshes}
    info = {
        "source": str(folder),
        "files": {n: str(p) for n, p in files.items()},
        "scale": scale,
        "frame": "input meshes taken as already in the arch frame",
        "axes_estimated": sorted(n for n in teeth if n not in given),
        "cej_rule": CEJ_RULE,
    }
    return Dentition(teeth, description or f"meshes from {folder}", info)


def _mapping_from_names(folder: Path) -> dict[str, int]:
    mapping: dict[str, int] = {}
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() not in MESH_SUFFIXES or not path.is_file():
            continue
        numbers = re.findall(r"\d+", path.stem)
        number = int(numbers[-1]) if numbers else None
        if number is None or not fdi_mod.is_fdi(number):
            raise MeshError(path, None, "the file name holds no FDI tooth number",
                            "rename it (e.g. tooth_11.stl) or pass mapping={file name: FDI number}")
        mapping[path.name] = number
    return mapping

"""A folder of per-tooth meshes as one dentition: in the arch frame, or in one scan's frame.

Each file is one tooth (`orthosim.exchange.meshload` loads and checks it); its FDI number comes
from a mapping or from the last number in its name. In a scan's frame, ONE rigid transform
(`orthosim.exchange.scanframe`) maps every tooth into the arch frame and keeps the scanned bite.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from orthosim.collision.interpenetration import report_rest_interpenetration
from orthosim.errors import MeshError
from orthosim.exchange.meshload import (CEJ_RULE, DEFAULT_MAX_TRIANGLES, MESH_SUFFIXES, ToothAxes, estimate_axes,
                                        estimate_scan_axes, load_tooth_mesh, tooth_from_mesh)
from orthosim.exchange.scanframe import ORIGIN_RULE, place_scan
from orthosim.model import fdi as fdi_mod
from orthosim.model.anatomy import dimensions
from orthosim.model.dentition import Dentition
from orthosim.model.fdi import Arch


# A closed mesh counts as a crown only while no extent exceeds this times its type's largest crown dimension.
CROWN_SIZE_FACTOR = 1.4


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
    A crown without a root (open at the gum line; in the arch frame also a closed crown) is given
    an estimated root (`orthosim.model.rootsynthesis`, announced by a `RootEstimatedWarning`) and
    marked `root_origin == "estimated"`.
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

    meshes = {n: load_tooth_mesh(p, scale=scale, max_triangles=max_triangles, crowns=True) for n, p in files.items()}
    if frame not in ("arch", "scan"):
        raise MeshError(folder, "frame", f"unknown frame {frame!r}", 'use "arch" or "scan"')
    crown_axes = _root_crowns(meshes, files, frame)
    if frame == "scan":
        scan_axes = {**estimate_scan_axes(meshes), **crown_axes}
        teeth, T = place_scan(folder, meshes, scan_axes, {n: str(p) for n, p in files.items()})
        teeth = _mark_estimated(teeth, crown_axes)
        info = {"source": str(folder), "files": {n: str(p) for n, p in files.items()}, "scale": scale,
                "frame": "one scan frame, mapped into the arch frame by one rigid transform", "scan_to_arch": T,
                "origin_rule": ORIGIN_RULE, "axes_estimated": sorted(teeth), "cej_rule": CEJ_RULE}
        return report_rest_interpenetration(Dentition(teeth, description or f"scanned meshes from {folder}", info), folder)
    given = set(axes or {})
    axes = {**crown_axes, **(axes or {})}
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
    teeth = _mark_estimated({n: tooth_from_mesh(n, meshes[n], axes[n], source=str(files[n])) for n in meshes},
                            crown_axes)
    info = {
        "source": str(folder),
        "files": {n: str(p) for n, p in files.items()},
        "scale": scale,
        "frame": "input meshes taken as already in the arch frame",
        "axes_estimated": sorted(n for n in teeth if n not in given),
        "cej_rule": CEJ_RULE,
    }
    return Dentition(teeth, description or f"meshes from {folder}", info)


def _root_crowns(meshes: dict, files: dict[int, Path], frame: str) -> dict[int, ToothAxes]:
    """Give every crown-only mesh an estimated root, in place in `meshes`; returns their axes (FDI -> axes).

    Crown-only: open (a crown cut at the gum line), or, in the arch frame, closed but reaching less
    than a quarter of a root below the crown (opened at its cervical end first). Each is announced
    by a `RootEstimatedWarning` naming the file.
    """
    from orthosim.exchange.labelledscan import labial_directions
    from orthosim.model.rootsynthesis import (RootEstimatedWarning, margin_frame, open_closed_crown,
                                              synthesize_root)

    frames = {}
    for n, mesh in meshes.items():
        occlusal = np.array([0.0, -1.0 if fdi_mod.arch_of(n) is Arch.UPPER else 1.0, 0.0])
        if not mesh.metadata.get("open"):
            if frame != "arch" or not _rootless(n, mesh, occlusal):
                continue
            mesh = open_closed_crown(mesh, occlusal)
        frames[n] = (mesh, margin_frame(mesh, str(files[n]), occlusal if frame == "arch" else None))
    labial = labial_directions({n: f for n, (_, f) in frames.items()}) if frame == "scan" else \
        {n: _labial_in_arch(n, f.centre, meshes) for n, (_, f) in frames.items()}
    axes = {}
    for n, (crown, margin) in frames.items():
        rooted = synthesize_root(crown, n, str(files[n]), labial=labial[n], frame=margin)
        meshes[n] = rooted.mesh
        axes[n] = ToothAxes(long_axis=rooted.long_axis, labial=labial[n], point=rooted.margin_centre)
        roots = f"{rooted.roots} root{'s' if rooted.roots > 1 else ''}"
        warnings.warn(f"{files[n]}: a crown without a root; an estimated root of {rooted.root_length_mm:.1f} mm "
                      f"({roots}) was built for it (not the patient's root)", RootEstimatedWarning, stacklevel=3)
    return axes


def _labial_in_arch(n: int, centre: np.ndarray, meshes: dict) -> np.ndarray:
    """Labial direction of a crown in the arch frame: horizontal, from its arch's centre (as `estimate_axes`)."""
    members = [m for m in meshes if fdi_mod.arch_of(m) is fdi_mod.arch_of(n)]
    arch_centre = (np.mean([meshes[m].vertices.mean(axis=0) for m in members], axis=0) if len(members) >= 3
                   else np.zeros(3))
    labial = centre - arch_centre
    labial[1] = 0.0
    return labial


def _rootless(n: int, mesh, occlusal: np.ndarray) -> bool:
    """Whether a closed mesh in the arch frame is a crown only: it reaches less than a quarter root below the
    CEJ, and no way across is it longer than a crown (a whole tooth lying on its side is no crown)."""
    dims = dimensions(n)
    along = mesh.vertices @ occlusal
    short = float(along.max() - along.min()) < dims.crown_height + 0.25 * dims.root_length
    largest = max(dims.md_width, dims.bl_width, dims.crown_height)
    return short and float(mesh.extents.max()) < CROWN_SIZE_FACTOR * largest


def _mark_estimated(teeth: dict, crowns) -> dict:
    return {n: replace(t, root_origin="estimated") if n in crowns else t for n, t in teeth.items()}


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

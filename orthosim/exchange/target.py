"""The set-up: where each tooth should end, read from a case's `[target]` section.

A target is given per tooth as a movement in the tooth's own terms, or as a folder of meshes of the
teeth in their final positions. Either way it becomes a target pose per tooth (4x4, local -> arch
frame, mm), reached from the start pose along the motion the continuous detector checks.

Movement components, all in the tooth's frame at the start (`orthosim.model.tooth`; local origin at the
CEJ centre on the long axis, which is also the centre of every rotation):
  mesial_mm     the origin's displacement along `Tooth.mesial` (negative: distal)
  buccal_mm     along the labial/buccal axis (local +z; negative: lingual)
  extrusion_mm  along the long axis toward the crown (local +y; negative: intrusion)
  tip_deg       about the buccolingual axis, positive when the crown tips mesially
  torque_deg    about the mesiodistal axis, positive when the crown moves buccally (buccal crown torque)
  rotation_deg  about the long axis, positive when the mesial surface turns buccally (mesial-out)
The three angles are the components of one rotation vector in that frame, so no order of
rotations is implied, and the per-stage components of the staging chart are measured the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from orthosim.errors import CaseError
from orthosim.exchange.casefields import FieldReader

COMPONENTS = ("mesial", "buccal", "extrusion", "tip", "torque", "rotation")  # chart and limit order
UNITS = {"mesial": "mm", "buccal": "mm", "extrusion": "mm", "tip": "deg", "torque": "deg", "rotation": "deg"}
REGISTRATION_RMS_MAX_MM = 0.05  # a target mesh must match its tooth within this RMS after registration
MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off")


@dataclass(frozen=True)
class ToothMovement:
    """A planned movement of one tooth, in its own terms (see the module docstring)."""

    mesial_mm: float = 0.0
    buccal_mm: float = 0.0
    extrusion_mm: float = 0.0
    tip_deg: float = 0.0
    torque_deg: float = 0.0
    rotation_deg: float = 0.0

    def components(self) -> np.ndarray:
        """(6,) in COMPONENTS order: mm, mm, mm, deg, deg, deg."""
        return np.array([self.mesial_mm, self.buccal_mm, self.extrusion_mm, self.tip_deg, self.torque_deg, self.rotation_deg])


@dataclass(frozen=True, eq=False)
class TargetSpec:
    """The `[target]` section: per-tooth movements, or a folder of final-position meshes."""

    movements: Mapping[int, ToothMovement] = field(default_factory=dict)  # FDI -> movement
    folder: Path | None = None  # meshes of the teeth at the target, in the arch frame
    files: Mapping[str, int] = field(default_factory=dict)  # folder: file name -> FDI
    source: Path | None = None  # the case file, for error messages


def local_axes(tooth) -> np.ndarray:
    """(6, 3) unit vectors, local frame: the axis of each component (translation direction for mm,
    rotation axis for degrees), in COMPONENTS order."""
    m = tooth.mesial
    y = np.array([0.0, 1.0, 0.0])
    z = np.array([0.0, 0.0, 1.0])
    return np.stack([m, z, y, np.cross(y, m), np.cross(y, z), np.cross(m, z)])


def target_pose(tooth, start_pose: np.ndarray, movement: ToothMovement) -> np.ndarray:
    """(4, 4) pose of `tooth` after `movement` from `start_pose` (local -> arch frame, mm)."""
    c = movement.components()
    axes = local_axes(tooth)
    offset = c[:3] @ axes[:3]  # local mm
    w = np.radians(c[3:]) @ axes[3:]  # local rotation vector, radians
    from orthosim.geometry.motion import rotation_matrix

    M = np.eye(4)
    M[:3, :3] = rotation_matrix(w)
    M[:3, 3] = offset
    return np.asarray(start_pose, float) @ M


def movement_components(tooth, start_pose: np.ndarray, pose_a: np.ndarray, pose_b: np.ndarray) -> np.ndarray:
    """(6,) the motion from pose_a to pose_b in the tooth's start frame: mm, mm, mm, deg, deg, deg
    (COMPONENTS order). Translation is of the local origin; angles are the components of the
    rotation vector of the motion (the motion law's rotation: `geometry.motion`)."""
    from orthosim.geometry.motion import rotation_vector

    R0 = np.asarray(start_pose, float)[:3, :3]
    axes = local_axes(tooth)
    d_local = R0.T @ (np.asarray(pose_b, float)[:3, 3] - np.asarray(pose_a, float)[:3, 3])
    w_local = R0.T @ rotation_vector(pose_a, pose_b)
    return np.concatenate([axes[:3] @ d_local, np.degrees(axes[3:] @ w_local)])


_TARGET_KEYS = ("folder", "files")
_MOVEMENT_KEYS = ("mesial_mm", "buccal_mm", "extrusion_mm", "tip_deg", "torque_deg", "rotation_deg")
_LIMIT_MM, _LIMIT_DEG = 20.0, 90.0  # sanity bounds on a whole movement; beyond them a unit is wrong


def read_target(path: Path, raw: Any, present: set[int], extracted: set[int], section: str = "target") -> TargetSpec:
    """Validate a case's `[target]` (or `[start]`) table (see README, "Aligner staging"); CaseError
    on any problem. `[start]` takes per-tooth movements only: where each tooth stands at the start
    of treatment, moved from the model's rest pose (a malocclusion on the parametric model).

        [target]
        folder = "final/"            # meshes at the target: <FDI>.stl etc., or a [target.files] table
        [target.41]                  # or per tooth, in the tooth's own terms
        buccal_mm = 0.8
        rotation_deg = -6
    """

    keys = tuple(str(k) for k in raw) if isinstance(raw, dict) else ()
    allowed = _TARGET_KEYS if section == "target" else ()
    if section == "start" and isinstance(raw, dict):
        for k in keys:
            if not k.isdigit():
                raise CaseError(path, f"start.{k}", "unknown key",
                                "[start] takes per-tooth tables only, e.g. [start.41] buccal_mm = -2")
    r = FieldReader(path, section, raw, allowed + tuple(k for k in keys if k.isdigit()))
    teeth = [k for k in r.table if k.isdigit()]
    if "folder" in r.table:
        if teeth:
            r.fail(teeth[0], "a target is either a folder of meshes or per-tooth movements, not both",
                   "remove the per-tooth tables or the folder")
        return _read_folder(path, r, present, extracted)
    if "files" in r.table:
        r.fail("files", "only used with folder", "add folder = \"...\" or remove files")
    if not teeth:
        r.fail(None, "is empty", f"give per-tooth movements, e.g. [{section}.41] buccal_mm = 0.5"
               + (", or folder = \"...\"" if section == "target" else ""))
    movements = {}
    for key in teeth:
        number = r.tooth(key, int(key), present)
        if number in extracted:
            r.fail(key, f"tooth {number} is extracted in this case and cannot be moved", "remove its target")
        m = FieldReader(path, f"{section}.{key}", r.table[key], _MOVEMENT_KEYS)
        values = {k: m.number(k, 0.0, minimum=None) for k in _MOVEMENT_KEYS}
        for k, v in values.items():
            bound = _LIMIT_MM if k.endswith("_mm") else _LIMIT_DEG
            if abs(v) > bound:
                m.fail(k, f"{v:g} is beyond {bound:g} {k.rsplit('_', 1)[1]} for one tooth's whole movement",
                       "check the unit (mm and degrees)")
        movements[number] = ToothMovement(**values)
    return TargetSpec(movements=movements, source=path)


def _read_folder(path: Path, r, present: set[int], extracted: set[int]) -> TargetSpec:
    folder = Path(r.string("folder")).expanduser()
    if not folder.is_absolute():
        folder = (path.parent / folder).resolve()
    if not folder.is_dir():
        r.fail("folder", f"no such folder {folder}", "give the folder of target meshes, relative to the case file or absolute")
    files: dict[str, int] = {}
    raw_files = r.get("files")
    if raw_files is not None:
        if not isinstance(raw_files, dict) or not raw_files:
            r.fail("files", "must be a non-empty table", "write [target.files] mapping each mesh file to its FDI number")
        for name, number in raw_files.items():
            if not (folder / name).is_file():
                r.fail(f"files.{name}", f"no such file in {folder}", "check the file name")
            files[name] = r.tooth(f"files.{name}", number, present)
    else:
        for p in sorted(folder.iterdir()):
            if p.suffix.lower() in MESH_SUFFIXES and p.stem.isdigit():
                files[p.name] = r.tooth(f"folder ({p.name})", int(p.stem), present)
        if not files:
            r.fail("folder", f"no <FDI>.stl (or .ply, .obj, .off) meshes in {folder}",
                   "name each target mesh by its tooth, e.g. 41.stl, or add a [target.files] table")
    if len(set(files.values())) != len(files):
        r.fail("files", "two meshes are given for the same tooth", "give each tooth once")
    for name, number in files.items():
        if number in extracted:
            r.fail(f"files.{name}", f"tooth {number} is extracted in this case and cannot have a target", "remove it")
    return TargetSpec(folder=folder, files=files, source=path)


def target_poses(dentition, spec: TargetSpec, start: Mapping[int, np.ndarray] | None = None) -> dict[int, np.ndarray]:
    """FDI -> (4, 4) target pose of every tooth of `spec` (teeth not named keep their start pose).

    start: FDI -> (4, 4) start poses (the dentition's rest poses by default). A folder target
    registers each target mesh to its tooth's start mesh (`register_target_mesh`) and raises
    CaseError naming the file when it does not match within REGISTRATION_RMS_MAX_MM.
    """
    start = dict(start or dentition.rest_poses())
    out = dict(start)
    if spec.folder is None:
        for n, mv in spec.movements.items():
            out[n] = target_pose(dentition.teeth[n], start[n], mv)
        return out
    from orthosim.exchange.meshload import load_tooth_mesh

    for name, n in spec.files.items():
        file = spec.folder / name
        mesh = load_tooth_mesh(file)
        tooth = dentition.teeth[n]
        M, rms = register_target_mesh(tooth.mesh, start[n], mesh)
        if rms > REGISTRATION_RMS_MAX_MM:
            raise CaseError(spec.source, f"target.folder ({name})",
                            f"tooth {n} does not register to its start mesh: RMS {rms:.3f} mm > {REGISTRATION_RMS_MAX_MM} mm",
                            "give the same tooth's mesh, moved rigidly into its final position in the arch frame")
        out[n] = M @ start[n]
    return out


def register_target_mesh(local_mesh, start_pose: np.ndarray, target_mesh) -> tuple[np.ndarray, float]:
    """(M (4, 4), rms mm): the rigid motion taking the tooth at its start pose onto `target_mesh`,
    and the RMS distance (mm) of the moved start vertices to the target surface.

    trimesh's ICP (vertices to the target surface) from the centroid offset: no correspondence by
    vertex index is assumed, since a mesh file written and read again may merge or reorder vertices.
    """
    import trimesh

    from orthosim.geometry.lazymesh import as_trimesh

    target_mesh = as_trimesh(target_mesh)  # icp takes a mesh only as a trimesh (else as points)
    start_v = np.asarray(local_mesh.vertices, float) @ start_pose[:3, :3].T + start_pose[:3, 3]
    tv = np.asarray(target_mesh.vertices, float)
    guess = np.eye(4)
    guess[:3, 3] = tv.mean(axis=0) - start_v.mean(axis=0)
    M, _, _ = trimesh.registration.icp(start_v, target_mesh, initial=guess, threshold=1e-9, max_iterations=300,
                                       reflection=False, scale=False)
    moved = start_v @ M[:3, :3].T + M[:3, 3]
    _, dist, _ = trimesh.proximity.closest_point(target_mesh, moved)
    return np.asarray(M, float), float(math.sqrt(float(np.mean(dist ** 2))))


@dataclass(frozen=True, eq=False)
class CaseStaging:
    """A case's staging sections: the start (None: the model's rest poses) and the target."""

    start: TargetSpec | None
    target: TargetSpec | None

    def poses(self, dentition) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
        """(start, target): FDI -> (4, 4) poses of every tooth of `dentition`."""
        rest = dentition.rest_poses()
        start = target_poses(dentition, self.start, rest) if self.start is not None else rest
        target = target_poses(dentition, self.target, start) if self.target is not None else dict(start)
        return start, target


def read_case_staging(path: Path, data: dict, present: set[int], extracted: set[int]) -> CaseStaging | None:
    """The case file's `[start]` and `[target]` sections, validated (None when it has neither)."""
    if "start" not in data and "target" not in data:
        return None
    start = read_target(path, data["start"], present, extracted, "start") if "start" in data else None
    target = read_target(path, data["target"], present, extracted, "target") if "target" in data else None
    return CaseStaging(start, target)

"""Loading real tooth meshes (STL, OBJ, PLY) into `Tooth` models: validation, safe repair, local frames.

A user's mesh is the one input most likely to be subtly broken (holes, flipped winding, metres
instead of millimetres), and a broken mesh silently accepted would give a wrong simulation, so
every file goes through `load_tooth_mesh`: it repairs what can be repaired without changing the
shape (merging vertices, dropping degenerate or duplicate faces and tiny detached specks, filling
triangle or quad holes, fixing winding so the volume is positive) with a warning naming the file, and raises a
one-line `MeshError` for anything else. `load_mesh_folder` turns a folder of per-tooth meshes that
are already in the arch frame (see `orthosim.model.dentition`) into a `Dentition`, estimating each
tooth's local frame (`orthosim.model.tooth`) from its shape; `tooth_from_mesh` is the shared step that
places a mesh in its local frame given a long axis and a labial direction (the Open-Full-Jaw
importer, `orthosim.exchange.openfulljaw`, uses it with the dataset's own axes). All lengths are mm.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from orthosim.model import fdi as fdi_mod
from orthosim.model.anatomy import dimensions
from orthosim.errors import MeshError
from orthosim.model.fdi import Arch
from orthosim.model.tooth import Tooth, part_of_faces

MESH_SUFFIXES = (".stl", ".obj", ".ply")

# A human tooth (crown plus root) is 15-30 mm long and 5-12 mm wide, so its bounding-box diagonal
# sits well inside these limits; a diagonal outside them means the file is in other units.
TOOTH_DIAGONAL_MM = (8.0, 45.0)
# Unit factors tried when the size is wrong, most common first: what each factor means.
_UNIT_GUESSES = ((1000.0, "metres"), (25.4, "inches"), (10.0, "centimetres"), (0.001, "micrometres"))

# Long axis estimated from the shape (PCA) must be within this angle of the arch frame's y axis;
# beyond it the mesh is almost certainly not in the arch frame and the estimate would be nonsense.
MAX_PCA_TILT_DEG = 60.0

# Separate pieces beside the main body are dropped (with a warning) only up to this volume fraction.
MAX_DROPPED_VOLUME = 0.02

# Triangles a tooth may have before it is simplified (case files: [model] max_triangles_per_tooth).
# The densest real teeth in use (Open-Full-Jaw, CBCT, 0.18 mm edges) have 16,000-45,000; the sphere
# trees, the exact meshes and the drawing gain nothing from more, while a scan exported at millions
# of triangles would make every phase take minutes.
DEFAULT_MAX_TRIANGLES = 100_000
# The largest edge-collapse tolerance used to meet the budget (mm). The surface moved by up to about
# 2.6 times the tolerance in our measurements, so a simplified tooth stays within about 0.05 mm.
MAX_SIMPLIFY_TOLERANCE_MM = 0.02

CEJ_RULE = (
    "CEJ on the long axis at (occlusal-most point of the mesh along the axis) minus the Wheeler "
    "crown height of the tooth type (orthosim.model.anatomy); root length = extent of the mesh below it"
)


class MeshRepairWarning(UserWarning):
    """A tooth mesh was repaired on load; the message names the file and what was changed."""


class MeshSimplifiedWarning(MeshRepairWarning):
    """A tooth mesh above the triangle budget is being simplified; the message names the file, the counts and the fix."""


@dataclass(frozen=True)
class ToothAxes:
    """A tooth's anatomical directions in the arch frame (mm), used to build its local frame.

    `long_axis` points from the apex toward the crown; `labial` need not be orthogonal to it
    (it is orthogonalised); `point` is a point on the long axis (e.g. the crown centre), or None
    to use the centroid of the mesh volume.
    """

    long_axis: np.ndarray  # (3,) arch frame, apex -> crown
    labial: np.ndarray  # (3,) arch frame, toward the lips / cheek
    point: np.ndarray | None = None  # (3,) arch frame, mm, a point on the long axis


def load_tooth_mesh(path: str | Path, scale: float = 1.0,
                    max_triangles: int | None = DEFAULT_MAX_TRIANGLES, crowns: bool = False) -> trimesh.Trimesh:
    """Read one tooth mesh (STL, OBJ or PLY), multiply by `scale`, validate it, repair it if safe.

    Returns a closed mesh with consistent outward winding (positive volume), in mm. Repairs are
    reported with a `MeshRepairWarning`; anything unrepairable, or a size that is not a tooth's in
    millimetres, raises `MeshError` naming the file and the fix. A mesh of more than
    `max_triangles` triangles (None: no limit) is simplified to at most that many by edge
    collapse (`simplify_to_budget`), announced by a `MeshSimplifiedWarning` before the work starts;
    the result's `metadata` keeps the file's count (`triangles_in_file`) and, when simplified, how
    far the surface may have moved (`simplify_tolerance_mm`). `crowns`: a mesh left open after the
    safe hole filling is returned open (`metadata["open"]`: a crown from an intraoral scan, whose
    root `orthosim.model.rootsynthesis` builds) instead of refused.
    """
    path = Path(path)
    where = str(path)
    if not np.isfinite(scale) or scale <= 0:
        raise MeshError(where, "scale", f"must be a positive number, got {scale!r}", "pass e.g. scale=1000 for metres")
    if not path.is_file():
        raise MeshError(where, None, "file not found", "check the path and the file name")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(where, None, f"unsupported mesh format '{path.suffix}'", "convert it to STL, OBJ or PLY")
    repaired: list[str] = []
    mesh = _finite_mesh(_read_mesh_file(path, where), scale, where, repaired)

    _check_units(mesh, where, scale)
    in_file = len(mesh.faces)
    if max_triangles is not None and in_file > max_triangles:
        # said before the work: merging and simplifying millions of triangles takes seconds to a minute
        warnings.warn(f"{where}: {in_file:,} triangles, above the budget of {max_triangles:,} a tooth: "
                      f"simplifying it to at most {max_triangles:,} (closed, edge-collapse tolerance at most {MAX_SIMPLIFY_TOLERANCE_MM:g} mm); "
                      "set [model] max_triangles_per_tooth in the case file to change the budget",
                      MeshSimplifiedWarning, stacklevel=2)

    _drop_degenerate_faces(mesh, repaired)
    full = None
    if max_triangles is not None and len(mesh.faces) > max_triangles:
        full, mesh = mesh, simplify_to_budget(mesh, max_triangles, where)
        tolerance = mesh.metadata["simplify_tolerance_mm"]
    if len(mesh.faces) < 4:
        raise MeshError(where, None, "has fewer than 4 valid triangles, so it cannot enclose a volume",
                        "re-export the tooth as a closed mesh")

    if full is not None and not mesh.is_watertight and full.is_watertight:
        raise MeshError(where, None, f"simplifying its {in_file:,} triangles to {max_triangles:,} opened holes in it",
                        f"simplify it in a mesh editor (e.g. MeshLab 'Quadric Edge Collapse Decimation', preserve "
                        f"topology) to under {max_triangles:,} triangles, or raise [model] max_triangles_per_tooth")
    is_open = _close_holes(mesh, where, crowns, repaired)
    _consistent_winding(mesh, where, repaired)
    if mesh.body_count > 1:
        mesh = _largest_piece(mesh, where, is_open, repaired)
    if not is_open and mesh.volume < 0:
        mesh.invert()
        repaired.append("inverted inside-out winding (normals now point outward)")
    if not is_open and not mesh.volume > 0:
        raise MeshError(where, None, "encloses no volume", "re-export the tooth as a closed solid")
    mesh.metadata["open"] = is_open

    if repaired:
        warnings.warn(f"{where}: repaired mesh: {'; '.join(repaired)}", MeshRepairWarning, stacklevel=2)
    mesh.metadata["triangles_in_file"] = in_file
    if full is not None:
        mesh.metadata["simplify_tolerance_mm"] = tolerance
    return mesh


def _read_mesh_file(path: Path, where: str) -> trimesh.Trimesh:
    """The file's triangles as they are (no processing: repairs are done step by step, each reported)."""
    try:
        text_safe = _ascii_safe_bytes(path)
        if text_safe is None:
            mesh = trimesh.load(str(path), force="mesh", process=False)
        else:
            mesh = trimesh.load(io.BytesIO(text_safe), file_type=path.suffix.lower()[1:], force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for a corrupt file; all mean "unreadable"
        raise MeshError(where, None, f"cannot be read as a mesh ({type(exc).__name__}: {exc})",
                        "re-export it as a binary STL") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise MeshError(where, None, "contains no triangles", "re-export the tooth as a closed triangle mesh")
    return mesh


def _finite_mesh(mesh: trimesh.Trimesh, scale: float, where: str, repaired: list[str]) -> trimesh.Trimesh:
    """The mesh scaled to mm, without faces on NaN or infinite vertices; MeshError on bad indices."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError(where, "faces", "refer to vertices that do not exist", "re-export the mesh")
    bad_vertex = ~np.isfinite(vertices).all(axis=1)
    if bad_vertex.any():
        keep = ~bad_vertex[faces].any(axis=1)
        repaired.append(f"dropped {int((~keep).sum())} faces on {int(bad_vertex.sum())} NaN/infinite vertices")
        faces = faces[keep]
        if len(faces) == 0:
            raise MeshError(where, "vertices", "every face uses a NaN or infinite vertex", "re-export the mesh")
    mesh = trimesh.Trimesh(vertices * scale, faces, process=False)
    mesh.remove_unreferenced_vertices()
    return mesh


def _drop_degenerate_faces(mesh: trimesh.Trimesh, repaired: list[str]) -> None:
    """Coincident vertices merged (an STL is a triangle soup: that is how it is read, not a repair),
    then zero-area and duplicate faces dropped, in place."""
    mesh.merge_vertices()
    keep = mesh.nondegenerate_faces()
    if not keep.all():
        repaired.append(f"dropped {int((~keep).sum())} zero-area faces")
        mesh.update_faces(keep)
    keep = mesh.unique_faces()
    if not keep.all():
        repaired.append(f"dropped {int((~keep).sum())} duplicate faces")
        mesh.update_faces(keep)
    mesh.remove_unreferenced_vertices()


def _close_holes(mesh: trimesh.Trimesh, where: str, crowns: bool, repaired: list[str]) -> bool:
    """Small holes filled in place; whether the mesh stays open (allowed for crowns only)."""
    if mesh.is_watertight:
        return False
    before = len(mesh.faces)
    trimesh.repair.fill_holes(mesh)  # fills only triangle and quad holes: safe, shape kept
    if len(mesh.faces) > before:
        repaired.append(f"filled small holes with {len(mesh.faces) - before} faces")
    if not mesh.is_watertight and not crowns:
        raise MeshError(where, None, "is not watertight (it has holes or edges shared by more than two faces)",
                        "close the mesh in a mesh editor (e.g. MeshLab 'Close Holes') and export it again")
    return not mesh.is_watertight


def _consistent_winding(mesh: trimesh.Trimesh, where: str, repaired: list[str]) -> None:
    if not mesh.is_winding_consistent:
        trimesh.repair.fix_winding(mesh)
        if not mesh.is_winding_consistent:
            raise MeshError(where, None, "has inconsistent face winding that cannot be fixed (non-manifold)",
                            "repair the mesh in a mesh editor and export it again")
        repaired.append("made face winding consistent")


def _largest_piece(mesh: trimesh.Trimesh, where: str, is_open: bool, repaired: list[str]) -> trimesh.Trimesh:
    """CBCT segmentations can leave specks (or an inner pulp shell) beside the tooth: dropping them
    is safe when they are tiny; a second big piece means two teeth or a split tooth (MeshError)."""
    pieces = mesh.split(only_watertight=False)
    volumes = np.array([p.area if is_open else abs(p.volume) for p in pieces])  # an open crown: by area
    biggest = int(volumes.argmax())
    rest = float(volumes.sum() - volumes[biggest])
    if rest > MAX_DROPPED_VOLUME * volumes[biggest]:
        raise MeshError(where, None, f"holds {len(pieces)} separate closed pieces, the others "
                        f"{100 * rest / volumes[biggest]:.0f}% of the largest's volume",
                        "export one tooth per file as a single closed surface")
    repaired.append(f"dropped {len(pieces) - 1} small separate pieces "
                    f"({100 * rest / volumes[biggest]:.2f}% of the tooth's volume)")
    return pieces[biggest]


def simplify_to_budget(mesh: trimesh.Trimesh, max_triangles: int, where: str) -> trimesh.Trimesh:
    """`mesh` (closed, vertices merged, mm) simplified to at most `max_triangles` triangles, its shape kept.

    manifold3d's `simplify` (already orthosim's boolean engine) collapses only edges whose removal
    keeps the surface within a tolerance, and keeps the mesh closed and manifold; the tolerance is
    the smallest that meets the budget (0.0001 mm x 4^k up to `MAX_SIMPLIFY_TOLERANCE_MM`, then
    three halvings of the last step in log scale), recorded in the result's
    `metadata["simplify_tolerance_mm"]`. A mesh that needs more is refused.
    (fast-simplification, a quadric decimator by count, was measured and not kept: on a molar
    loop-subdivided to 1.8 M triangles it stalled near 120,000 whatever the target or aggression,
    and it bounds no distance.)
    """
    import manifold3d

    solid = manifold3d.Manifold(manifold3d.Mesh(vert_properties=np.asarray(mesh.vertices, np.float32),
                                                tri_verts=np.asarray(mesh.faces, np.uint32)))
    if solid.status() != manifold3d.Error.NoError:
        raise MeshError(where, None, f"cannot be simplified to {max_triangles:,} triangles: it is not a closed "
                        "manifold surface", "repair it in a mesh editor, or raise [model] max_triangles_per_tooth "
                        "in the case file")
    tolerance, too_small = 1e-4, None  # mm: far below a scanner's resolution; the budget decides how far it grows
    while (smaller := solid.simplify(tolerance)).num_tri() > max_triangles:
        if tolerance >= MAX_SIMPLIFY_TOLERANCE_MM:
            raise MeshError(where, None, f"cannot be simplified to {max_triangles:,} triangles with an edge-collapse "
                            f"tolerance of {MAX_SIMPLIFY_TOLERANCE_MM:g} mm", "simplify it in a mesh "
                            "editor, or raise [model] max_triangles_per_tooth in the case file")
        too_small, tolerance = tolerance, min(tolerance * 4, MAX_SIMPLIFY_TOLERANCE_MM)
    if too_small is not None:  # narrow the step that crossed the budget: keep as much of the surface as it allows
        for _ in range(3):
            middle = (too_small * tolerance) ** 0.5
            candidate = solid.simplify(middle)
            if candidate.num_tri() <= max_triangles:
                smaller, tolerance = candidate, middle
            else:
                too_small = middle
    out = smaller.to_mesh()
    simplified = trimesh.Trimesh(np.asarray(out.vert_properties[:, :3], np.float64),
                                 np.asarray(out.tri_verts, np.int64), process=False)
    simplified.metadata["simplify_tolerance_mm"] = tolerance
    return simplified


def _ascii_safe_bytes(path: Path) -> bytes | None:
    """The file's bytes with the non-ASCII bytes of its text part made `?`, or None when it needs no such care.

    The text of an ASCII STL, an OBJ or a PLY header is keywords and numbers, all ASCII; only names
    and comments carry other bytes (an exporter's `solid Zahn_\xe4` in Latin-1, say). trimesh decodes
    text that is not UTF-8 by guessing its encoding with charset_normalizer, which it does not
    install; a guess is not needed when the geometry cannot hold such bytes, so they become `?`,
    byte for byte (lengths kept, a binary PLY body left alone).
    """
    suffix = path.suffix.lower()
    data = path.read_bytes()
    if suffix == ".stl" and len(data) >= 84 and len(data) == 84 + 50 * int.from_bytes(data[80:84], "little"):
        return None  # binary STL: its 80-byte header is never decoded
    text_end = len(data)
    if suffix == ".ply":
        end = data.find(b"end_header")
        text_end = len(data) if end < 0 else end
    text = data[:text_end]
    if text.isascii():
        return None
    try:
        text.decode("utf-8")
        return None
    except UnicodeDecodeError:
        pass
    codes = np.frombuffer(text, np.uint8)
    return np.where(codes < 0x80, codes, ord("?")).astype(np.uint8).tobytes() + data[text_end:]


def _check_units(mesh: trimesh.Trimesh, where: str, scale: float) -> None:
    """Refuse a mesh whose size is not a tooth's in mm, naming the `scale` that would fix it."""
    diagonal = float(np.linalg.norm(mesh.extents))
    low, high = TOOTH_DIAGONAL_MM
    if low <= diagonal <= high:
        return
    for factor, unit in _UNIT_GUESSES:
        if low <= diagonal * factor <= high:
            fix = f"the file looks like {unit}: pass scale={scale * factor:g}"
            break
    else:
        fix = "check that the file holds one tooth, and pass scale= to convert its units to mm"
    raise MeshError(where, "size", f"bounding-box diagonal {diagonal:.4g} mm (after scale={scale:g}) is outside "
                    f"the {low:g}-{high:g} mm of a tooth in millimetres", fix)


def tooth_from_mesh(fdi: int, mesh: trimesh.Trimesh, axes: ToothAxes, source: str = "mesh") -> Tooth:
    """A `Tooth` from a closed mesh already in the arch frame and its axes (arch frame).

    The local frame follows `orthosim.model.tooth`: +y along `axes.long_axis`, +z the labial direction
    orthogonalised against it, +x = y cross z, origin at the CEJ estimated by `CEJ_RULE` on the
    long axis through `axes.point`. The mesh is stored in that frame and `rest_pose` maps it back,
    so `tooth.world_mesh()` reproduces the input geometry (a rigid map, exact up to rounding).
    """
    where = source
    y = _unit(axes.long_axis, where, "long axis")
    z = np.asarray(axes.labial, float) - y * (np.asarray(axes.labial, float) @ y)
    z = _unit(z, where, "labial direction (parallel to the long axis)")
    x = np.cross(y, z)
    point = mesh.center_mass if axes.point is None else np.asarray(axes.point, float)

    along = (mesh.vertices - point) @ y
    dims = dimensions(fdi)
    cej_level = float(along.max()) - dims.crown_height
    root_length = cej_level - float(along.min())
    if root_length < 0.25 * dims.root_length:
        raise MeshError(where, "root", f"the mesh reaches only {max(root_length, 0.0):.1f} mm below the estimated "
                        f"CEJ ({dims.crown_height:g} mm below the crown tip); orthosim needs crown and root",
                        "use a tooth mesh that includes the root (e.g. segmented from CBCT)")

    rest_pose = np.eye(4)
    rest_pose[:3, 0], rest_pose[:3, 1], rest_pose[:3, 2] = x, y, z
    rest_pose[:3, 3] = point + cej_level * y
    local = mesh.copy()
    inverse = np.eye(4)
    inverse[:3, :3] = rest_pose[:3, :3].T
    inverse[:3, 3] = -rest_pose[:3, :3].T @ rest_pose[:3, 3]
    local.apply_transform(inverse)

    face_part = part_of_faces(local)
    crown = face_part == 0
    if not crown.any():
        raise MeshError(where, "crown", "no face lies above the estimated CEJ", "check the long axis direction")
    # Surface centre of the crown faces, area weighted so dense triangulation does not bias it.
    area = local.area_faces[crown]
    crown_center = (local.triangles_center[crown] * area[:, None]).sum(axis=0) / area.sum()
    return Tooth(
        fdi=fdi,
        mesh=local,
        face_part=face_part,
        crown_center=crown_center,
        apex=np.array([0.0, -root_length, 0.0]),
        rest_pose=rest_pose,
        source=source,
    )


def principal_long_axis(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """(unit axis (3,), centre (3,) mm): the surface's longest principal axis and its area-weighted centre.

    Area-weighted so a densely triangulated crown does not pull the axis; the sign is arbitrary
    (see `crown_end_sign`). On Open-Full-Jaw patient 26 it lies 1-18 degrees from the dataset's
    long axes (median 6).
    """
    centers = mesh.triangles_center
    weights = mesh.area_faces / mesh.area
    mean = weights @ centers
    d = centers - mean
    cov = (d * weights[:, None]).T @ d
    _, vecs = np.linalg.eigh(cov)
    return vecs[:, -1], mean


def crown_end_sign(mesh: trimesh.Trimesh, axis: np.ndarray, centre: np.ndarray) -> float:
    """+1 when the crown end of a tooth lies toward +axis, -1 when toward -axis.

    A root tapers to its apex while a crown is widest near its occlusal end, so the end whose
    outermost 15% of vertices (along the axis) spread wider across it is the crown (right on all 29
    teeth of Open-Full-Jaw patient 26 that have axes).
    """
    axis = np.asarray(axis, float)
    along = (mesh.vertices - centre) @ axis
    lo, hi = np.quantile(along, [0.15, 0.85])

    def spread(sel):
        v = mesh.vertices[sel] - mesh.vertices[sel].mean(axis=0)
        v -= np.outer(v @ axis, axis)
        return float(np.sqrt((v ** 2).sum(axis=1).mean()))

    return 1.0 if spread(along > hi) >= spread(along < lo) else -1.0


def estimate_axes(fdi: int, mesh: trimesh.Trimesh, arch_center: np.ndarray, where: str) -> ToothAxes:
    """Axes of a tooth mesh given in the arch frame, from its shape alone.

    Long axis: the longest principal axis of the surface (area-weighted PCA), pointed toward the
    occlusal plane (-y for upper teeth, +y for lower). Labial: the horizontal direction from
    `arch_center` (3,) to the tooth's centroid. The axis passes through the volume centroid.
    """
    long_axis, _ = principal_long_axis(mesh)
    toward_occlusal = -1.0 if fdi_mod.arch_of(fdi) is Arch.UPPER else 1.0
    if long_axis[1] * toward_occlusal < 0:
        long_axis = -long_axis
    tilt = np.degrees(np.arccos(min(1.0, abs(long_axis[1]))))
    if tilt > MAX_PCA_TILT_DEG:
        raise MeshError(where, "orientation", f"the tooth's long axis is {tilt:.0f} degrees from the arch frame's "
                        "vertical (y) axis, so the mesh does not seem to be in the arch frame",
                        "transform the meshes into the arch frame (y up, occlusal plane y=0, +z anterior) "
                        "or pass axes= for each tooth")
    center = mesh.center_mass
    labial = center - np.asarray(arch_center, float)
    labial[1] = 0.0
    if np.linalg.norm(labial) < 1e-6:
        raise MeshError(where, "position", "the tooth sits at the arch centre, so its labial side is unknown",
                        "pass axes= for this tooth")
    return ToothAxes(long_axis=long_axis, labial=labial, point=center)


def estimate_scan_axes(meshes: dict[int, trimesh.Trimesh]) -> dict[int, ToothAxes]:
    """Axes of every tooth of one scan, in the scan's frame, from the meshes alone.

    Long axis: the principal axis (`principal_long_axis`) pointed at the crown end
    (`crown_end_sign`), then made to agree with the majority of its arch. Labial: across the arch
    tangent (from the previous to the next tooth along the arch) and the long axis, signed away from
    the centroid of the arch. The axis passes through the surface centre.
    """
    out: dict[int, ToothAxes] = {}
    for arch in (Arch.UPPER, Arch.LOWER):
        order = fdi_mod.arch_order(arch, set(meshes))
        if not order:
            continue
        axis, centre = {}, {}
        for n in order:
            a, c = principal_long_axis(meshes[n])
            axis[n], centre[n] = a * crown_end_sign(meshes[n], a, c), c
        majority = sum(axis.values())
        arch_centre = np.mean([centre[n] for n in order], axis=0)
        for i, n in enumerate(order):
            if axis[n] @ majority < 0:
                axis[n] = -axis[n]
            prev, nxt = order[max(i - 1, 0)], order[min(i + 1, len(order) - 1)]
            tangent = centre[nxt] - centre[prev]
            labial = np.cross(tangent, axis[n]) if np.linalg.norm(tangent) > 0 else centre[n] - arch_centre
            if labial @ (centre[n] - arch_centre) < 0:
                labial = -labial
            out[n] = ToothAxes(long_axis=axis[n], labial=labial, point=centre[n])
    return out


def _unit(v: np.ndarray, where: str, what: str) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(v))
    if not np.isfinite(n) or n < 1e-9:
        raise MeshError(where, "axes", f"the {what} has zero length", "give a non-zero direction")
    return v / n

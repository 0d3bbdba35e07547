"""Labelled intraoral arch scans (the Teeth3DS / 3DTeethSeg22 layout) split into crown-only teeth and gum.

An intraoral scan is one mesh per arch (OBJ, STL or PLY, mm), crowns and gum in one surface, open
at its edge. A segmentation tool writes a JSON beside it (`X_upper.obj` -> `X_upper.json`) holding
`id_patient`, `jaw` ("upper" or "lower"), `labels` (one per vertex, in the order the mesh file lists
its vertices, an STL's being its triangles' corners: the FDI number of the tooth it belongs to, 0 for gum) and optionally `instances` (one
per vertex too). Each tooth label's triangles (those whose three vertices carry it) become one open
crown, given an estimated root (`orthosim.model.rootsynthesis`); every other triangle is the gum,
kept as its own mesh (`Dentition.gingiva`) that is drawn and exported but never enters the
collision model. Both arches share the scanner's frame, so ONE rigid transform
(`orthosim.exchange.scanframe`) places them in the arch frame and the scanned bite is kept.
Anything wrong in a label file is refused in one line naming the file, the field and the fix.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import trimesh

from orthosim.errors import MeshError
from orthosim.model import fdi as fdi_mod
from orthosim.model.fdi import Arch

JAWS = {"upper": Arch.UPPER, "lower": Arch.LOWER}
MIN_TOOTH_VERTICES = 150  # fewer cannot outline a crown (a scanned incisor crown has thousands)
MAX_STRAY_FRACTION = 0.05  # a tooth's extra pieces are dropped up to this share of its triangles
ARCH_DIAGONAL_MM = (20.0, 200.0)  # a scanned arch (even a sextant) in mm lies within this diagonal


class ScanRepairWarning(UserWarning):
    """Part of a labelled scan was dropped on load (stray pieces of a tooth label); the message names them."""


@dataclass(frozen=True)
class LabelledScan:
    """One arch scan and its labels, checked against each other."""

    path: Path  # the mesh file
    labels_path: Path  # the JSON beside it
    jaw: str  # "upper" | "lower"
    mesh: trimesh.Trimesh  # as in the file, vertices in file order, mm, scanner frame
    labels: np.ndarray  # (n_vertices,) int64: FDI number, 0 gum


def labels_path_for(mesh_path: str | Path) -> Path:
    """The label JSON of a scan: beside it, same name, `.json`."""
    return Path(mesh_path).with_suffix(".json")


def read_labelled_scan(path: str | Path, jaw: str) -> LabelledScan:
    """Read a scan mesh and its label JSON, given as the `jaw` ("upper"/"lower") scan; check them together."""
    path = Path(path)
    labels_path = labels_path_for(path)
    data = _read_json(labels_path)
    _check_jaw(data, labels_path, jaw)
    mesh = _read_mesh(path)
    labels = _labels(data, labels_path, "labels", len(mesh.vertices), path)
    if "instances" in data:
        _labels(data, labels_path, "instances", len(mesh.vertices), path)
    _check_fdi(labels, labels_path, jaw)
    return LabelledScan(path, labels_path, jaw, mesh, labels)


def labelled_teeth(upper: Path | None, lower: Path | None) -> set[int]:
    """FDI numbers labelled in the scans' label files (read and checked without loading the meshes)."""
    present: set[int] = set()
    for jaw, path in (("upper", upper), ("lower", lower)):
        if path is None:
            continue
        labels_path = labels_path_for(path)
        data = _read_json(labels_path)
        _check_jaw(data, labels_path, jaw)
        labels = _labels(data, labels_path, "labels", None, Path(path))
        present |= _check_fdi(labels, labels_path, jaw)
    return present


def _check_jaw(data: dict, labels_path: Path, jaw: str) -> None:
    said = data.get("jaw")
    if said not in JAWS:
        raise MeshError(labels_path, "jaw", f"must be \"upper\" or \"lower\", got {said!r}",
                        "write the scan's jaw in the label file")
    if said != jaw:
        raise MeshError(labels_path, "jaw", f"is {said!r} but the file is given as the {jaw} scan",
                        f"give it as model.{said}, or use the {jaw} scan's label file")


def _check_fdi(labels: np.ndarray, labels_path: Path, jaw: str) -> set[int]:
    """The tooth labels (FDI of `jaw`); anything else but 0 refused."""
    found = set(np.unique(labels).tolist())
    unknown = sorted(found - set(fdi_mod.arch_order(JAWS[jaw])) - {0})
    if unknown:
        quadrants = "11-18, 21-28" if jaw == "upper" else "31-38, 41-48"
        raise MeshError(labels_path, "labels", f"holds {', '.join(map(str, unknown[:5]))}, not FDI numbers of the "
                        f"{jaw} jaw", f"label {jaw} teeth {quadrants} and the gum 0")
    return found - {0}


def split_scan(scan: LabelledScan) -> tuple[dict[int, trimesh.Trimesh], trimesh.Trimesh]:
    """(FDI -> open crown mesh, gum mesh), all in the scanner frame (mm).

    A triangle goes to a tooth when its three vertices carry that tooth's label; every other
    triangle (gum, and the few between gum and crown or between touching crowns) goes to the gum.
    """
    faces = np.asarray(scan.mesh.faces, np.int64)
    corner = scan.labels[faces]
    same = (corner[:, 0] == corner[:, 1]) & (corner[:, 1] == corner[:, 2])
    owner = np.where(same, corner[:, 0], 0)
    crowns = {}
    for n in sorted(set(np.unique(scan.labels).tolist()) - {0}):
        count = int((scan.labels == n).sum())
        if count < MIN_TOOTH_VERTICES:
            raise MeshError(scan.labels_path, "labels", f"tooth {n} has only {count} vertices, too few to be a "
                            f"crown (at least {MIN_TOOTH_VERTICES})", "label them 0 (gum) or re-run the segmentation")
        crowns[n] = _one_piece(_submesh(scan.mesh, faces[owner == n]), scan, n)
    gum = _submesh(scan.mesh, faces[owner == 0])
    gum.merge_vertices()  # an STL's triangle soup, joined so the gum shades smoothly
    return crowns, gum


def _submesh(mesh: trimesh.Trimesh, faces: np.ndarray) -> trimesh.Trimesh:
    used, inverse = np.unique(faces, return_inverse=True)
    return trimesh.Trimesh(np.asarray(mesh.vertices, float)[used], inverse.reshape(-1, 3), process=False)


def _one_piece(crown: trimesh.Trimesh, scan: LabelledScan, n: int) -> trimesh.Trimesh:
    """The crown's one connected piece; specks beside it dropped (warned), a second real piece refused."""
    crown.merge_vertices()
    crown.update_faces(crown.nondegenerate_faces())  # zero-area slivers are no piece of a crown
    crown.remove_unreferenced_vertices()
    pieces = crown.split(only_watertight=False)
    if len(pieces) <= 1:
        return crown
    sizes = np.array([len(p.faces) for p in pieces])
    order = np.argsort(sizes)[::-1]
    biggest, rest = pieces[order[0]], int(sizes.sum() - sizes[order[0]])
    if sizes[order[1]] > MAX_STRAY_FRACTION * sizes[order[0]]:
        raise MeshError(scan.labels_path, "labels", f"tooth {n}'s crown is in {len(pieces)} separate pieces (the "
                        f"second {100 * sizes[order[1]] / sizes[order[0]]:.0f}% of the largest)",
                        "give each tooth one label and each label one tooth, then re-run the segmentation")
    warnings.warn(f"{scan.labels_path}: tooth {n}: dropped {len(pieces) - 1} stray pieces labelled {n} "
                  f"({rest} triangles)", ScanRepairWarning, stacklevel=3)
    return biggest


def _read_json(labels_path: Path) -> dict:
    if not labels_path.is_file():
        raise MeshError(labels_path, None, "label file not found beside the scan",
                        "put the segmentation's JSON beside the mesh, with the same name")
    try:
        data = json.loads(labels_path.read_text())
    except (OSError, ValueError) as exc:
        raise MeshError(labels_path, None, f"cannot be read as JSON ({type(exc).__name__})",
                        "write the label file again from the segmentation tool") from None
    if not isinstance(data, dict):
        raise MeshError(labels_path, None, "is not a JSON object with jaw and labels",
                        "write the label file again from the segmentation tool")
    return data


def _labels(data: dict, labels_path: Path, key: str, n_vertices: int | None, mesh_path: Path) -> np.ndarray:
    raw = data.get(key)
    # JSON gives whole numbers as int, never a subclass but bool: one C-level pass over the types
    # (a scan has hundreds of thousands of labels; a per-value isinstance test cost a second)
    if not isinstance(raw, list) or not set(map(type, raw)) <= {int}:
        raise MeshError(labels_path, key, "must be a list of whole numbers, one per vertex",
                        "write the label file again from the segmentation tool")
    if n_vertices is not None and len(raw) != n_vertices:
        raise MeshError(labels_path, key, f"holds {len(raw):,} values for the {n_vertices:,} vertices of "
                        f"{mesh_path.name}", "use the label file made for this mesh (one value per vertex, in file order)")
    return np.asarray(raw, np.int64)


def _read_mesh(path: Path) -> trimesh.Trimesh:
    from orthosim.exchange.meshload import MESH_SUFFIXES

    if not path.is_file():
        raise MeshError(path, None, "scan file not found", "check the path in the case file")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(path, None, f"unsupported mesh format '{path.suffix}'", "convert it to OBJ, STL or PLY")
    try:  # process=False keeps the vertices in file order, which the labels follow
        mesh = trimesh.load(str(path), force="mesh", process=False, maintain_order=True)
    except Exception as exc:  # trimesh raises many types for a corrupt file; all mean "unreadable"
        raise MeshError(path, None, f"cannot be read as a mesh ({type(exc).__name__})", "export the scan again") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(path, None, "contains no triangles", "export the scan again as a triangle mesh")
    if not np.isfinite(mesh.vertices).all():
        raise MeshError(path, "vertices", "holds NaN or infinite coordinates", "export the scan again")
    diagonal = float(np.linalg.norm(mesh.extents))
    low, high = ARCH_DIAGONAL_MM
    if not low <= diagonal <= high:
        raise MeshError(path, "size", f"bounding-box diagonal {diagonal:.4g} is not an arch's in mm ({low:g}-{high:g})",
                        "export the scan in millimetres")
    return mesh


def load_labelled_scans(upper: str | Path | None, lower: str | Path | None,
                        max_triangles: int | None = None):
    """A `Dentition` in the arch frame from a labelled upper and/or lower scan of one patient (one scanner frame).

    Every tooth is a crown with an estimated root (`Tooth.root_origin == "estimated"`); the gum
    of each arch is `dentition.gingiva["upper" / "lower"]`, moved by the same transform.
    """
    from orthosim.collision.interpenetration import report_rest_interpenetration
    from orthosim.exchange.meshload import DEFAULT_MAX_TRIANGLES, simplify_to_budget
    from orthosim.exchange.scanframe import ORIGIN_RULE, place_scan
    from orthosim.model.dentition import Dentition
    from orthosim.model.rootsynthesis import margin_frame, synthesize_root

    budget = DEFAULT_MAX_TRIANGLES if max_triangles is None else max_triangles
    scans = [read_labelled_scan(p, jaw) for jaw, p in (("upper", upper), ("lower", lower)) if p is not None]
    crowns, gums, sources = {}, {}, {}
    for scan in scans:
        teeth, gums[scan.jaw] = split_scan(scan)
        crowns.update(teeth)
        sources.update({n: f"{scan.path} (tooth {n})" for n in teeth})
    frames = {n: margin_frame(c, sources[n]) for n, c in crowns.items()}
    labial = labial_directions(frames)
    meshes, axes = {}, {}
    for n, crown in crowns.items():
        rooted = synthesize_root(crown, n, sources[n], labial=labial[n], frame=frames[n])
        mesh = rooted.mesh
        if len(mesh.faces) > budget:
            mesh = simplify_to_budget(mesh, budget, sources[n])
        meshes[n] = mesh
        axes[n] = _axes(rooted, labial[n])
    where = " + ".join(str(s.path) for s in scans)
    if len(meshes) < 3:
        raise MeshError(where, "labels", f"{len(meshes)} labelled teeth; the arch frame needs at least 3",
                        "label the teeth of the scan (FDI numbers)")
    placed, T = place_scan(where, meshes, axes, sources)
    teeth = {n: replace(t, root_origin="estimated") for n, t in placed.items()}
    gingiva = {jaw: gum.copy().apply_transform(T) for jaw, gum in gums.items()}
    # "files" (not "labels"): run.json keeps machine paths, metrics.json does not (orthosim.runtime.run)
    info = {"kind": "labelled-scan", "source": [str(s.path) for s in scans], "files": [str(s.labels_path) for s in scans],
            "frame": "one scanner frame, mapped into the arch frame by one rigid transform", "scan_to_arch": T,
            "origin_rule": ORIGIN_RULE, "roots": "estimated for every tooth (orthosim.model.rootsynthesis)",
            "axes_estimated": sorted(teeth)}
    dent = Dentition(teeth, f"labelled intraoral scans {where}", info, gingiva)
    return report_rest_interpenetration(dent, where)


def _axes(rooted, labial: np.ndarray):
    from orthosim.exchange.meshload import ToothAxes

    return ToothAxes(long_axis=rooted.long_axis, labial=labial, point=rooted.margin_centre)


def labial_directions(frames: dict) -> dict[int, np.ndarray]:
    """FDI -> labial direction in the scanner frame: across the arch tangent and the long axis, away from the arch's centre."""
    out = {}
    for arch in (Arch.UPPER, Arch.LOWER):
        order = fdi_mod.arch_order(arch, set(frames))
        if not order:
            continue
        centre = {n: frames[n].centre for n in order}
        middle = np.mean(list(centre.values()), axis=0)
        for i, n in enumerate(order):
            prev, nxt = order[max(i - 1, 0)], order[min(i + 1, len(order) - 1)]
            tangent = centre[nxt] - centre[prev]
            outward = centre[n] - middle
            labial = np.cross(tangent, frames[n].long_axis) if np.linalg.norm(tangent) > 0 else outward
            out[n] = labial if labial @ outward >= 0 else -labial
    return out

"""Labelled intraoral arch scans made from any dentition, for tests and the bench (never from committed data).

A scan is crowns only: each tooth is cut at its CEJ (its local y = 0, `orthosim.model.tooth`), and
a gum collar (two rings, 1.5 and 3 mm out from the margin and down toward the root) is hung from
its margin, labelled 0; everything is written as one OBJ per arch with a Teeth3DS-style JSON beside
it (`id_patient`, `jaw`, per-vertex `labels` and `instances`), in the dentition's arch frame (mm).
`subdivisions` splits every crown triangle into four that many times, to reach real scan sizes
(100k-500k triangles per arch).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import trimesh

from orthosim.geometry.meshcut import keep_above_plane
from orthosim.model import fdi as fdi_mod
from orthosim.model.rootsynthesis import boundary_loops


def crown_at_cej(tooth) -> trimesh.Trimesh:
    """The tooth's crown, cut open at its CEJ plane, in the arch frame at its rest pose (mm)."""
    crown = keep_above_plane(tooth.mesh, [0.0, 1.0, 0.0], [0.0, 0.0, 0.0])
    pieces = crown.split(only_watertight=False)
    crown = max(pieces, key=lambda p: len(p.faces)) if len(pieces) > 1 else crown
    crown.apply_transform(tooth.rest_pose)
    return crown


def _collar(crown: trimesh.Trimesh, tooth, rings: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(new vertices, faces over crown + new vertex indices, margin loop) of a gum collar under the crown's
    margin: `rings` rings out to 3 mm from the margin and 2 mm down."""
    loop = max(boundary_loops(crown), key=len)
    margin = crown.vertices[loop]
    axis = tooth.rest_pose[:3, 1]
    centre = margin.mean(axis=0)
    radial = margin - centre
    radial -= np.outer(radial @ axis, axis)
    radial /= np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-9)
    n = len(crown.vertices)
    steps = np.linspace(0.0, 1.0, rings + 1)[1:]
    ring_points = [margin + 3.0 * s * radial - 2.0 * s * axis for s in steps]
    faces, prev = [], loop
    for k in range(rings):
        cur = n + k * len(loop) + np.arange(len(loop))
        p1, c1 = np.roll(prev, -1), np.roll(cur, -1)
        faces += [np.column_stack([p1, prev, cur]), np.column_stack([p1, cur, c1])]
        prev = cur
    return np.vstack(ring_points), np.vstack(faces), loop


def write_labelled_arch(dentition, jaw: str, folder: str | Path, stem: str = "scan", subdivisions: int = 0,
                        suffix: str = ".obj", teeth: set[int] | None = None, gum_rings: int = 2) -> Path:
    """Write `<stem>_<jaw><suffix>` and `<stem>_<jaw>.json` for one arch of `dentition` (only `teeth`
    when given; the gum collar in `gum_rings` rings); returns the mesh path."""
    arch = fdi_mod.Arch.UPPER if jaw == "upper" else fdi_mod.Arch.LOWER
    vertices, faces, labels = [], [], []
    count = 0
    for n in dentition.arch(arch):
        if teeth is not None and n not in teeth:
            continue
        tooth = dentition.teeth[n]
        crown = crown_at_cej(tooth)
        for _ in range(subdivisions):
            crown = crown.subdivide()
        ring, collar_faces, _ = _collar(crown, tooth, gum_rings)
        vertices += [crown.vertices, ring]
        faces += [crown.faces + count, collar_faces + count]
        labels += [np.full(len(crown.vertices), n), np.zeros(len(ring), int)]
        count += len(crown.vertices) + len(ring)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{stem}_{jaw}{suffix}"
    all_faces = np.vstack(faces)
    trimesh.Trimesh(np.vstack(vertices), all_faces, process=False).export(path)
    all_labels = np.concatenate(labels)
    if suffix.lower() == ".stl":  # an STL is a triangle soup: its vertices are the triangles' corners, in order
        all_labels = all_labels[all_faces].ravel()
    all_labels = all_labels.tolist()
    instances = [0 if v == 0 else i + 1 for i, v in enumerate(sorted(set(all_labels)))]
    lookup = dict(zip(sorted(set(all_labels)), instances))
    (folder / f"{stem}_{jaw}.json").write_text(json.dumps({
        "id_patient": stem, "jaw": jaw, "labels": all_labels, "instances": [lookup[v] for v in all_labels]}))
    return path


def labelled_scan_timings(faces_target: int = 300_000) -> dict:
    """Seconds to make one labelled arch scan of at least `faces_target` triangles ready to simulate.

    The upper arch of the smooth parametric model, its crowns subdivided until the scan has that
    many triangles (once), then its gum collar given rings until the scan has them (a real scan's
    triangles are about half gum), is loaded as a `labelled-scan` model (split, roots estimated,
    placed, the dentition cached) and its sphere trees built (`CollisionModel.from_dentition`), first
    with empty caches (cold, in a fresh `$ORTHOSIM_CACHE`), then again from the caches (warm, same
    process); the model and the trees are timed apart. Targets: 12 s cold on two cores (issue 42),
    2 s warm in all. `cold_trees_built` counts the trees the cold run wrote to its empty cache, one
    per tooth shape it built: equal to `teeth` (a scan's teeth are no exact mirror images, each
    crown's root and frame being estimated on its own), none came from the entries shipped with
    the package (the demo model's, `orthosim.storage.shipped`), so the cold figure times the builds.
    """
    import os
    import tempfile
    import time

    from orthosim.collision.model import CollisionModel
    from orthosim.exchange.case import ModelSpec
    from orthosim.model.dentition_cache import cached_dentition
    from orthosim.model.parametric import parametric_dentition

    model = parametric_dentition("smooth")
    with tempfile.TemporaryDirectory() as tmp:
        def scan(rings: int) -> tuple[Path, int]:
            path = write_labelled_arch(model, "upper", tmp, "bench", subdivisions=1, gum_rings=rings)
            return path, len(trimesh.load(path, force="mesh", process=False).faces)

        _, two = scan(2)
        _, three = scan(3)  # each ring adds the same number of triangles
        path, faces = scan(max(2, 2 + int(np.ceil((faces_target - two) / (three - two)))))
        spec = ModelSpec("labelled-scan", upper=path)
        from orthosim.exchange.case import Case, Wire

        case = Case(Path(tmp) / "bench.toml", "bench", "", spec, (), (), Wire(), 1.0, 1.0, "continuous")
        parameters, inputs = case._mesh_model_key()
        old = os.environ.get("ORTHOSIM_CACHE")
        os.environ["ORTHOSIM_CACHE"] = str(Path(tmp) / "cache")
        seconds, written = [], []
        try:
            for _ in range(2):
                start = time.perf_counter()
                dent = cached_dentition(parameters, case._load_meshes, inputs)
                built = time.perf_counter()
                CollisionModel.from_dentition(dent)
                seconds.append((built - start, time.perf_counter() - built))
                written.append(len(list((Path(tmp) / "cache").glob("*.npz"))))  # tree entries (dentitions: a subfolder)
        finally:
            if old is None:
                os.environ.pop("ORTHOSIM_CACHE", None)
            else:
                os.environ["ORTHOSIM_CACHE"] = old
    return {"faces": faces, "teeth": len(dent.teeth), "model_triangles": sum(len(t.mesh.faces) for t in dent.teeth.values()),
            "cold_s": sum(seconds[0]), "warm_s": sum(seconds[1]),
            "cold_model_s": seconds[0][0], "cold_trees_s": seconds[0][1],
            "warm_model_s": seconds[1][0], "warm_trees_s": seconds[1][1],
            "cold_trees_built": written[0], "target_cold_s": 12.0, "target_warm_s": 2.0}

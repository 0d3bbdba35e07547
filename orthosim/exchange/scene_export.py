"""The posed teeth of chosen steps as 3D files for Blender, MeshLab or Open3D (through trimesh).

    export_scenes(dentition, records, extracted, out_dir / "scene", "glb")

glb: one binary glTF scene per step, `step_NNNNN.glb`, one node per present tooth named
`tooth_<FDI>` whose mesh is in the tooth's local frame and whose transform is the tooth's pose at
that step (so a viewer shows the arch and keeps each tooth its own object). In metres, as glTF
2.0 defines its unit (section 3.4: metres, +Y up, the front facing +Z, right-handed): the arch
frame (y up, +z anterior, +x the patient's left) is already that, so vertices and translations are
only scaled by 0.001 (before 2026-11-28 they were written in millimetres, and Blender opened a
50 m arch; a tool that wants millimetres scales by 1000 on import).
ply: PLY holds one mesh, so each step is a folder `step_NNNNN/` of `tooth_<FDI>.ply`, each posed
in the arch frame (mm). Extracted teeth are left out. A scanned gum (`Dentition.gingiva`, labelled
intraoral scans) is written too, as `gingiva_<upper|lower>`, where it was scanned (it never moves).
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from orthosim.storage.atomic import write_bytes

GLB_METRES_PER_MM = 0.001  # glTF's unit is the metre


def export_scenes(dentition, records: Iterable, extracted: set[int], out_dir: str | Path, fmt: str) -> list[Path]:
    """Write each record's posed teeth (records: anything with `step` and `poses` {FDI: (4, 4) mm});
    returns the files written."""
    import trimesh

    out_dir = Path(out_dir)
    written: list[Path] = []
    for record in records:
        teeth = [n for n in dentition.fdis if n not in extracted]
        if fmt == "glb":
            scene = trimesh.Scene()
            for n in teeth:
                pose = np.array(record.poses[n], float)
                pose[:3, 3] *= GLB_METRES_PER_MM
                scene.add_geometry(_in_metres(dentition.teeth[n].mesh), node_name=f"tooth_{n}", geom_name=f"tooth_{n}",
                                   transform=pose)
            for name, gum in dentition.gingiva.items():
                scene.add_geometry(_in_metres(gum), node_name=f"gingiva_{name}", geom_name=f"gingiva_{name}")
            path = out_dir / f"step_{record.step:05d}.glb"
            write_bytes(path, scene.export(file_type="glb"))
            written.append(path)
        elif fmt == "ply":
            for n in teeth:
                path = out_dir / f"step_{record.step:05d}" / f"tooth_{n}.ply"
                write_bytes(path, dentition.teeth[n].world_mesh(record.poses[n]).export(file_type="ply"))
                written.append(path)
            for name, gum in dentition.gingiva.items():
                path = out_dir / f"step_{record.step:05d}" / f"gingiva_{name}.ply"
                write_bytes(path, gum.export(file_type="ply"))
                written.append(path)
        else:
            raise ValueError(f"unknown scene format {fmt!r}")
    return written


def _in_metres(mesh):
    """A copy of `mesh` (mm) with its vertices in metres, faces as they are."""
    import trimesh

    return trimesh.Trimesh(np.asarray(mesh.vertices, float) * GLB_METRES_PER_MM, np.asarray(mesh.faces), process=False)

"""Stage models for the lab: every stage's posed teeth, one file per arch, to print aligners on.

    export_stage_models(dentition, [plan.poses(k) for k in range(plan.n_stages + 1)], "models", "stl",
                        reduced=reduced_meshes(meshes, plan.ipr, plan.target))

For stage k (0 = the start) and each arch with staged teeth: `stage_NN_upper.<fmt>` and
`stage_NN_lower.<fmt>` (NN zero-padded to two digits, more when there are 100 stages or more).
Coordinates are the case's arch frame in millimetres (y up, +z anterior), as the tooth models are,
so a lab's model-base software loads them as they are.

stl and ply: one mesh per file, the arch's teeth each a closed body of its own (the tooth models are
watertight; neighbours are separate bodies even where they touch). glb: one node per tooth named
`tooth_<FDI>`, its mesh in the tooth's local frame and its pose as the node's transform (mm as
written; glTF viewers assume metres).

Before writing, vertices of a tooth within `WELD_MM` of each other are welded and the faces that
collapse are dropped (the parametric molars have a zero-height sliver at a root seam, two vertices
2e-11 mm apart: STL's float32 coordinates would weld them on reading and leave the molar open).
The tooth stays closed and its volume unchanged.

Where interproximal reduction is planned, stage 0 holds the teeth as they are and every later stage
the reduced teeth (`reduced`: the planned enamel cut off each contact side, `staging.reduction`),
the teeth the certificate's clearances are measured on. `stage_tooth_meshes` gives the meshes of a
stage, for any other writer of stage models. What is not there: gingiva (no case of orthosim has a
gingiva model yet).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from orthosim.model import fdi as F
from orthosim.storage.atomic import write_bytes

FORMATS = ("stl", "ply", "glb")
WELD_MM = 1e-6  # vertices closer than this are one vertex in a printed model


def printable(mesh):
    """A copy of `mesh` with vertices within about WELD_MM welded and collapsed faces dropped."""
    import trimesh

    out = trimesh.Trimesh(np.asarray(mesh.vertices, float).copy(), np.asarray(mesh.faces).copy(), process=False)
    out.merge_vertices(digits_vertex=int(round(-np.log10(WELD_MM))))
    out.update_faces(out.nondegenerate_faces(height=1e-9))
    out.remove_unreferenced_vertices()
    return out


def stage_file_name(stage: int, arch: str, n_stages: int, fmt: str) -> str:
    """`stage_NN_<arch>.<fmt>`: NN zero-padded to at least two digits, enough for the last stage."""
    width = max(2, len(str(n_stages)))
    return f"stage_{stage:0{width}d}_{arch}.{fmt}"


def arch_teeth(teeth: Sequence[int]) -> dict[str, list[int]]:
    """'upper' / 'lower' -> the given teeth of that arch (FDI order); arches without teeth left out."""
    out: dict[str, list[int]] = {}
    for n in sorted(teeth):
        out.setdefault("upper" if F.quadrant(n) in (1, 2) else "lower", []).append(n)
    return out


def stage_tooth_meshes(dentition, teeth: Sequence[int], stage: int, reduced: Mapping[int, object] | None = None) -> dict:
    """FDI -> the tooth-frame mesh (mm) a stage holds: the whole tooth at stage 0, the reduced one
    (reduced[FDI], where given) from stage 1 on, when the reduction has been done."""
    return {n: (reduced or {}).get(n, dentition.teeth[n].mesh) if stage >= 1 else dentition.teeth[n].mesh for n in teeth}


def arch_mesh(dentition, teeth: Sequence[int], poses: Mapping[int, np.ndarray], meshes: Mapping[int, object] | None = None):
    """One trimesh of the teeth posed in the arch frame (mm), each tooth a separate closed body;
    meshes: FDI -> tooth-frame mesh to pose (default: the dentition's)."""
    import trimesh

    local = meshes or {n: dentition.teeth[n].mesh for n in teeth}

    def posed(n):
        m = local[n].copy()
        m.apply_transform(np.asarray(poses[n], float))
        return m

    return trimesh.util.concatenate([printable(posed(n)) for n in teeth])


def _arch_bytes(dentition, teeth, poses, fmt: str, meshes: Mapping[int, object]) -> bytes:
    if fmt == "glb":
        import trimesh

        scene = trimesh.Scene()
        for n in teeth:
            scene.add_geometry(printable(meshes[n]), node_name=f"tooth_{n}", geom_name=f"tooth_{n}",
                               transform=np.asarray(poses[n], float))
        return scene.export(file_type="glb")
    return arch_mesh(dentition, teeth, poses, meshes).export(file_type=fmt)


def export_stage_models(dentition, stage_poses: Sequence[Mapping[int, np.ndarray]], out_dir: str | Path,
                        fmt: str = "stl", teeth: Sequence[int] | None = None,
                        reduced: Mapping[int, object] | None = None) -> list[Path]:
    """Write every stage's arches (stage_poses[k]: FDI -> (4, 4) pose at stage k, mm) into out_dir;
    teeth: the staged teeth (default: those posed at stage 0); reduced: FDI -> the tooth-frame mesh
    of each tooth reduced by IPR, held from stage 1 on. Returns the files written."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown stage model format {fmt!r}")
    out_dir = Path(out_dir)
    arches = arch_teeth(teeth if teeth is not None else list(stage_poses[0]))
    n_stages = len(stage_poses) - 1
    written = []
    for k, poses in enumerate(stage_poses):
        for arch, members in arches.items():
            path = out_dir / stage_file_name(k, arch, n_stages, fmt)
            meshes = stage_tooth_meshes(dentition, members, k, reduced)
            write_bytes(path, _arch_bytes(dentition, members, poses, fmt, meshes))
            written.append(path)
    return written

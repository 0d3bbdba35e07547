"""Stage models held to stages.json: what `orthosim stage verify` checks of a folder's models/.

A lab prints the stage models, not stages.json; an edited or stale model file would put teeth
where no certificate puts them. Each `stage_NN_<arch>.<fmt>` file present (`models.FORMATS`) is
rebuilt from stages.json's poses of that stage with the writer's own function (`models.arch_mesh`:
the teeth reduced by the recorded IPR from stage 1 on, `staging.reduction`) and compared triangle
by triangle within `MODEL_ATOL_MM` (float32 files keep about 1e-5 mm at 100 mm); a glb's nodes are
compared tooth by tooth (pose and tooth-frame mesh). A format that lacks some stage's file, or a
file for a stage stages.json does not have, is named too.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from orthosim.staging.models import FORMATS, arch_mesh, arch_teeth, printable, stage_file_name, stage_tooth_meshes
from orthosim.staging.reduction import reduced_meshes

MODEL_ATOL_MM = 1e-4  # a model's coordinates within this of what stages.json gives (mm)
_NAME = re.compile(r"stage_(\d+)_(upper|lower)\.(\w+)$")


def check_stage_models(models: Path, written, dentition, target: dict) -> tuple[list[tuple[int, str]], int]:
    """((stage, one-line problem) for every model file that disagrees with stages.json, the count
    of files checked); nothing to check when the folder is absent."""
    if not models.is_dir():
        return [], 0
    problems: list[tuple[int, str]] = []
    found = {m.group(0): m for m in (_NAME.match(p.name) for p in sorted(models.iterdir())) if m and m.group(3) in FORMATS}
    formats = sorted({m.group(3) for m in found.values()})
    arches = arch_teeth(written.teeth)
    reduced = reduced_meshes({n: dentition.teeth[n].mesh for n in written.teeth}, written.ipr, target)
    expected = {stage_file_name(k, arch, written.n_stages, fmt): (k, arch)
                for fmt in formats for k in range(written.n_stages + 1) for arch in arches}
    for name in sorted(found.keys() - expected.keys()):
        problems.append((written.n_stages, f"models/{name}: no such stage or arch in stages.json"))
    for name, (k, arch) in expected.items():
        if name not in found:
            problems.append((k, f"models/{name}: missing (stages.json has stage {k})"))
            continue
        meshes = stage_tooth_meshes(dentition, arches[arch], k, reduced)
        off = _difference(models / name, dentition, arches[arch], written.poses[k], meshes)
        if off is not None:
            problems.append((k, f"models/{name}: {off}, not stage {k} as stages.json poses it"))
    return problems, len(expected.keys() & found.keys())


def _difference(path: Path, dentition, teeth, poses, meshes) -> str | None:
    """What differs between the model file and the stage's teeth, or None when it matches."""
    import trimesh

    try:
        loaded = trimesh.load(path, process=False)
    except Exception as err:  # any unreadable model file is a disagreement, named (trimesh raises many kinds)
        return f"unreadable ({err.__class__.__name__})"
    if isinstance(loaded, trimesh.Scene):
        return _scene_difference(loaded, teeth, poses, meshes)
    want = arch_mesh(dentition, teeth, poses, meshes)
    if len(loaded.faces) != len(want.faces):
        return f"holds {len(loaded.faces)} triangles where the stage's teeth have {len(want.faces)}"
    off = float(np.abs(np.asarray(loaded.triangles) - want.triangles).max(initial=0.0))
    return None if off <= MODEL_ATOL_MM else f"a vertex lies {off:.4g} mm from the stage's teeth"


def _scene_difference(scene, teeth, poses, meshes) -> str | None:
    nodes = set(scene.graph.nodes_geometry)
    for n in teeth:
        node = f"tooth_{n}"
        if node not in nodes:
            return f"has no node {node}"
        transform, geometry = scene.graph[node]
        if np.abs(np.asarray(transform) - poses[n]).max() > MODEL_ATOL_MM:
            return f"{node} is posed elsewhere"
        got, want = scene.geometry[geometry], printable(meshes[n])
        if len(got.faces) != len(want.faces) or np.abs(np.asarray(got.triangles) - want.triangles).max() > MODEL_ATOL_MM:
            return f"{node} is another shape than the tooth (reduced where IPR is planned)"
    extra = nodes - {f"tooth_{n}" for n in teeth}
    return f"has nodes of teeth not in this arch ({', '.join(sorted(extra))})" if extra else None

"""Interproximal reduction as the lab makes it: enamel taken off each tooth's contact side by a plane.

For an IPR contact between arch neighbours a and b (FDI), each tooth loses everything beyond a
plane perpendicular to its own mesiodistal axis that lies `depth_mm` inside its farthest point on
the side facing the other tooth: an `EnamelCut` each, depth half the contact's planned reduction
(`contact_cuts`). The plane is fixed in the tooth's own frame, so the flat face moves with the
tooth through every stage, as the stripped enamel of a real tooth does. The reduction is done before stage 1:
stage 0 is the teeth as they are, every later stage the reduced teeth.

The planner's contact checks, the certificate, `orthosim stage verify` and the exported stage
models all take their reduced teeth from here (`reduced_meshes`), so what the certificate credits
is what the printed models hold. The cut is manifold3d's plane trim (a closed solid: the cut face
capped flat), in double precision (`Mesh64`); cut meshes are remembered per (tooth mesh, cuts)
within a process, since every stage and every check asks for the same few.

Units: mm; normals unit vectors in the tooth frame.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
import trimesh

from orthosim.errors import MeshError

CACHE_SIZE = 64  # cut meshes remembered (a staging cuts two teeth per IPR contact)


@dataclass(frozen=True)
class EnamelCut:
    """One tooth's reduced side: the part beyond the plane `depth_mm` inside its farthest point
    along `normal` (unit, tooth frame, pointing out of the reduced side toward the neighbour)."""

    fdi: int
    normal: tuple[float, float, float]
    depth_mm: float

    def plane_offset(self, mesh: trimesh.Trimesh) -> float:
        """mm along `normal` (tooth frame) of the cut plane: the full tooth's farthest point less the depth."""
        return float((np.asarray(mesh.vertices, float) @ np.asarray(self.normal)).max()) - self.depth_mm


def contact_cuts(a: int, b: int, amount_mm: float, direction: np.ndarray, target_a: np.ndarray,
                 target_b: np.ndarray) -> tuple[EnamelCut, EnamelCut]:
    """The two cuts of an IPR contact: half of `amount_mm` off a's side facing b and off b's facing
    a. Each plane is perpendicular to its tooth's mesiodistal axis (the tooth frame's x), the
    side the one facing the other tooth: direction (3,) unit, arch frame, from a's crown centre to
    b's at the targets ((4, 4) poses). A face cut so stays parallel to the tooth's labiolingual
    and occlusal directions, as a strip drawn through the contact leaves it, and a tooth moving
    labially or lingually into line slides along its neighbour's cut face instead of into it."""
    u = np.asarray(direction, float)
    half = 0.5 * float(amount_mm)
    out = []
    for n, T, toward in ((a, target_a, u), (b, target_b, -u)):
        local = np.asarray(T, float)[:3, :3].T @ toward
        local[2] = 0.0  # no labiolingual component: the face the strip leaves runs labiolingually
        out.append(EnamelCut(n, tuple(float(x) for x in local / np.linalg.norm(local)), half))
    return out[0], out[1]


_cache: OrderedDict[tuple, trimesh.Trimesh] = OrderedDict()


def _mesh_key(mesh: trimesh.Trimesh) -> bytes:
    h = hashlib.sha1(np.ascontiguousarray(mesh.vertices, float).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, np.int64).tobytes())
    return h.digest()


def cut_tooth(mesh: trimesh.Trimesh, cuts: Sequence[EnamelCut]) -> trimesh.Trimesh:
    """`mesh` (tooth frame, mm, closed) with every cut's part removed and the cut faces capped flat;
    the mesh itself when there are no cuts. Remembered per (mesh, cuts)."""
    if not cuts:
        return mesh
    key = (_mesh_key(mesh), tuple(sorted((c.normal, c.depth_mm) for c in cuts)))
    if key in _cache:
        _cache.move_to_end(key)
        return _cache[key]
    import manifold3d

    solid = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=np.asarray(mesh.vertices, np.float64),
                                                  tri_verts=np.asarray(mesh.faces, np.uint64)))
    if solid.status() != manifold3d.Error.NoError or solid.is_empty():
        raise MeshError(None, f"tooth {cuts[0].fdi}", f"is not a closed manifold solid ({solid.status().name}): "
                        "its interproximal reduction cannot be cut", "repair the tooth's mesh (close its holes, one body)")
    for c in cuts:  # keep n . x <= offset: the trim keeps the side its normal points to
        solid = solid.trim_by_plane(tuple(-x for x in c.normal), -c.plane_offset(mesh))
    out = solid.to_mesh64()
    reduced = trimesh.Trimesh(np.asarray(out.vert_properties, float)[:, :3], np.asarray(out.tri_verts, np.int64), process=False)
    _cache[key] = reduced
    while len(_cache) > CACHE_SIZE:
        _cache.popitem(last=False)
    return reduced


def tooth_cuts(reductions, targets: Mapping[int, np.ndarray]) -> dict[int, list[EnamelCut]]:
    """FDI -> the cuts of that tooth from every IPR contact (`InterproximalReduction`s; targets: FDI -> (4, 4))."""
    out: dict[int, list[EnamelCut]] = {}
    for r in reductions:
        for c in contact_cuts(r.a, r.b, r.amount_mm, r.direction, targets[r.a], targets[r.b]):
            out.setdefault(c.fdi, []).append(c)
    return out


def reduced_meshes(meshes: Mapping[int, trimesh.Trimesh], reductions, targets: Mapping[int, np.ndarray]) -> dict[int, trimesh.Trimesh]:
    """FDI -> every tooth's mesh after the reductions (tooth frame, mm): cut teeth cut, the rest as given."""
    cuts = tooth_cuts(reductions, targets)
    return {n: cut_tooth(m, cuts.get(n, ())) for n, m in meshes.items()}


def reduced_depth(full: trimesh.Trimesh, reduced: trimesh.Trimesh, normal) -> float:
    """mm: how much less far the reduced tooth reaches along `normal` (tooth frame) than the full one:
    the enamel a cut removed at the contact, measured on the meshes themselves."""
    n = np.asarray(normal, float)
    return float((np.asarray(full.vertices) @ n).max() - (np.asarray(reduced.vertices) @ n).max())

"""The crown/root boundary drawn as a smooth line: triangles that straddle the CEJ plane are cut along it.

A tooth's faces are labelled crown or root by which side of its CEJ plane (local y = 0) their
centres lie (`orthosim.model.tooth.part_of_faces`); coloured face by face, the boundary of a dense real
tooth comes out as a staircase of whole triangles. For drawing only, each straddling triangle is
cut along the plane into one triangle and one quad (two triangles), new vertices placed on its
edges with positions and normals interpolated linearly, so crown and root colours meet on the
plane. The model's mesh is untouched: sphere trees, `leaf_of_face` and every measurement keep its
faces; `cut_at_cej` says where each drawn face and vertex came from, so a picture that colours
the model's faces (exact contact faces) or vertices (distance maps) colours the cut mesh too
(`vertex_blend`). Written here because trimesh's `slice_mesh_plane` cuts positions but not vertex normals,
and the shading must run on smoothly across the seam.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from orthosim.model.tooth import CROWN, ROOT, part_of_faces


@dataclass(frozen=True)
class CejCut:
    """A tooth mesh as drawn, cut along its CEJ plane, and where each part came from.

    vertices (n, 3) mm and normals (n, 3), local frame; faces (m, 3); part (m,) CROWN or ROOT.
    source_face (m,): the model's face each drawn face is (part of). Drawn vertex i lies at
    (1 - t[i]) * model vertex ends[i, 0] + t[i] * model vertex ends[i, 1] (model vertices: ends
    (i, i), t 0).
    """

    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    part: np.ndarray
    source_face: np.ndarray
    ends: np.ndarray
    t: np.ndarray


def split_at_cej(mesh: trimesh.Trimesh, face_part: np.ndarray, level_mm: float = 0.0):
    """(vertices (n, 3), normals (n, 3), faces (m, 3), part (m,)) with straddling faces cut at y = level_mm."""
    cut = cut_at_cej(mesh, face_part, level_mm)
    return cut.vertices, cut.normals, cut.faces, cut.part


def cut_at_cej(mesh: trimesh.Trimesh, face_part: np.ndarray, level_mm: float = 0.0) -> CejCut:
    """The mesh with the faces straddling y = level_mm cut along it (see `CejCut`).

    Only when `face_part` is the plane rule's labelling (`part_of_faces`); a model with its own
    CEJ line (the parametric teeth, whose rings follow it) is returned as it is.
    """
    vertices = np.asarray(mesh.vertices, float)
    normals = np.asarray(mesh.vertex_normals, float)
    faces = np.asarray(mesh.faces)
    n_vertices = len(vertices)
    same = np.arange(n_vertices)
    uncut = CejCut(vertices, normals, faces, face_part, np.arange(len(faces)), np.stack([same, same], axis=1),
                   np.zeros(n_vertices))
    if not np.array_equal(part_of_faces(mesh, level_mm), face_part):
        return uncut
    above = vertices[:, 1] >= level_mm
    count = above[faces].sum(axis=1)
    straddle = (count == 1) | (count == 2)
    if not straddle.any():
        return uncut
    kept = np.flatnonzero(~straddle)
    keep_faces, keep_part = faces[kept], face_part[kept]
    cut_ids = np.flatnonzero(straddle)
    cut = faces[cut_ids]
    # Rotate each cut triangle so its lone vertex (the one on its own side) comes first; the
    # rotation keeps the winding.
    lone_above = count[straddle] == 1
    flags = above[cut]
    lone = np.where(lone_above, flags.argmax(axis=1), (~flags).argmax(axis=1))
    order = (lone[:, None] + np.arange(3)[None, :]) % 3
    tri = np.take_along_axis(cut, order, axis=1)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]

    def on_plane(p, q):
        t = np.clip((level_mm - vertices[p, 1]) / (vertices[q, 1] - vertices[p, 1]), 0.0, 1.0)
        pos = vertices[p] + t[:, None] * (vertices[q] - vertices[p])
        nrm = normals[p] + t[:, None] * (normals[q] - normals[p])
        return pos, nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12), t

    pab, nab, tab = on_plane(a, b)
    pac, nac, tac = on_plane(a, c)
    k = len(tri)
    iab = n_vertices + np.arange(k)
    iac = n_vertices + k + np.arange(k)
    lone_tri = np.stack([a, iab, iac], axis=1)
    quad = np.concatenate([np.stack([iab, b, c], axis=1), np.stack([iab, c, iac], axis=1)])
    lone_part = np.where(lone_above, CROWN, ROOT).astype(face_part.dtype)
    quad_part = np.tile(np.where(lone_above, ROOT, CROWN).astype(face_part.dtype), 2)
    ends = np.concatenate([uncut.ends, np.stack([a, b], axis=1), np.stack([a, c], axis=1)])
    return CejCut(np.concatenate([vertices, pab, pac]), np.concatenate([normals, nab, nac]),
                  np.concatenate([keep_faces, lone_tri, quad]), np.concatenate([keep_part, lone_part, quad_part]),
                  np.concatenate([kept, cut_ids, cut_ids, cut_ids]), ends, np.concatenate([uncut.t, tab, tac]))


@dataclass(frozen=True)
class VertexBlend:
    """Drawn vertices as blends of some model vertices (`known`, e.g. a crown's, in that order):
    drawn vertex i gets (1 - t[i]) * value[a[i]] + t[i] * value[b[i]], a and b indexing `known`."""

    a: np.ndarray
    b: np.ndarray
    t: np.ndarray

    def apply(self, values: np.ndarray) -> np.ndarray:
        """(n, ...) drawn-vertex values from (len(known), ...) model-vertex values."""
        values = np.asarray(values)
        w = self.t.reshape((-1,) + (1,) * (values.ndim - 1)).astype(values.dtype)
        return (1 - w) * values[self.a] + w * values[self.b]


def vertex_blend(known: np.ndarray, ends: np.ndarray, t: np.ndarray, drawn: np.ndarray,
                 model_vertices: np.ndarray) -> VertexBlend:
    """How drawn vertices (`CejCut.ends`, `.t`; positions `drawn` (n, 3) mm) take a value given on
    the model vertices `known` (k,) only: linearly along a cut edge; from the one end that is
    known when the other is not; from the nearest known vertex when neither is (a vertex just
    coronal of the plane whose faces the plane rule all called root)."""
    from scipy.spatial import cKDTree

    slot = np.full(len(model_vertices), -1, np.int64)
    slot[known] = np.arange(len(known))
    a, b = slot[ends[:, 0]], slot[ends[:, 1]]
    a, b = np.where(a < 0, b, a), np.where(b < 0, a, b)
    t = np.where((a == b), 0.0, t).astype(float)
    lost = np.flatnonzero(a < 0)
    if len(lost):
        _, nearest = cKDTree(np.asarray(model_vertices, float)[known]).query(np.asarray(drawn, float)[lost])
        a[lost] = b[lost] = nearest
    return VertexBlend(a, b, t)

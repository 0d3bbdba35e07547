"""The crown/root boundary drawn as a smooth line: triangles that straddle the CEJ plane are cut along it.

A tooth's faces are labelled crown or root by which side of its CEJ plane (local y = 0) their
centres lie (`orthosim.tooth.part_of_faces`); coloured face by face, the boundary of a dense real
tooth comes out as a staircase of whole triangles. For drawing only, each straddling triangle is
cut along the plane into one triangle and one quad (two triangles), new vertices placed on its
edges with positions and normals interpolated linearly, so crown and root colours meet on the
plane. The model's mesh is untouched: sphere trees, `leaf_of_face` and every measurement keep its
faces. Written here because trimesh's `slice_mesh_plane` cuts positions but not vertex normals,
and the shading must run on smoothly across the seam.
"""

from __future__ import annotations

import numpy as np
import trimesh

from orthosim.tooth import CROWN, ROOT, part_of_faces


def split_at_cej(mesh: trimesh.Trimesh, face_part: np.ndarray, level_mm: float = 0.0):
    """(vertices (n, 3), normals (n, 3), faces (m, 3), part (m,)) with straddling faces cut at y = level_mm.

    Only when `face_part` is the plane rule's labelling (`part_of_faces`); a model with its own
    CEJ line (the parametric teeth, whose rings follow it) is returned as it is.
    """
    vertices = np.asarray(mesh.vertices, float)
    normals = np.asarray(mesh.vertex_normals, float)
    faces = np.asarray(mesh.faces)
    if not np.array_equal(part_of_faces(mesh, level_mm), face_part):
        return vertices, normals, faces, face_part
    above = vertices[:, 1] >= level_mm
    count = above[faces].sum(axis=1)
    straddle = (count == 1) | (count == 2)
    if not straddle.any():
        return vertices, normals, faces, face_part
    keep_faces, keep_part = faces[~straddle], face_part[~straddle]
    cut = faces[straddle]
    # Rotate each cut triangle so its lone vertex (the one on its own side) comes first; the
    # rotation keeps the winding.
    lone_above = count[straddle] == 1
    flags = above[cut]
    lone = np.where(lone_above, flags.argmax(axis=1), (~flags).argmax(axis=1))
    order = (lone[:, None] + np.arange(3)[None, :]) % 3
    tri = np.take_along_axis(cut, order, axis=1)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]

    def on_plane(p, q):
        t = (level_mm - vertices[p, 1]) / (vertices[q, 1] - vertices[p, 1])
        t = np.clip(t, 0.0, 1.0)[:, None]
        pos = vertices[p] + t * (vertices[q] - vertices[p])
        nrm = normals[p] + t * (normals[q] - normals[p])
        return pos, nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)

    pab, nab = on_plane(a, b)
    pac, nac = on_plane(a, c)
    k = len(tri)
    base = len(vertices)
    iab = base + np.arange(k)
    iac = base + k + np.arange(k)
    lone_tri = np.stack([a, iab, iac], axis=1)
    quad = np.concatenate([np.stack([iab, b, c], axis=1), np.stack([iab, c, iac], axis=1)])
    lone_part = np.where(lone_above, CROWN, ROOT).astype(face_part.dtype)
    quad_part = np.tile(np.where(lone_above, ROOT, CROWN).astype(face_part.dtype), 2)
    return (np.concatenate([vertices, pab, pac]), np.concatenate([normals, nab, nac]),
            np.concatenate([keep_faces, lone_tri, quad]), np.concatenate([keep_part, lone_part, quad_part]))

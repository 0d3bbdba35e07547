"""Cutting a triangle mesh by a plane, keeping one side open: how a crown is taken from a whole tooth.

trimesh's own plane slice needs shapely (not installed, and only wanted for its cap); this one
clips each triangle that crosses the plane exactly, with one new vertex per crossed edge shared by
the two triangles on either side of it, so the kept part has one clean boundary along the cut.
Used to open a closed crown at its cervical end (`orthosim.model.rootsynthesis`) and to make
crown-only test teeth from whole ones. Coordinates in mm.
"""

from __future__ import annotations

import numpy as np
import trimesh

ON_PLANE_MM = 1e-6  # a vertex this close to the plane lies on it


def keep_above_plane(mesh: trimesh.Trimesh, normal: np.ndarray, point: np.ndarray) -> trimesh.Trimesh:
    """The part of `mesh` on the `normal` (3,) side of the plane through `point` (3,) mm, open along the cut.

    Triangles wholly on that side are kept as they are, those wholly on the other side dropped,
    and crossing ones clipped (one or two triangles each, wound like the original).
    """
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    d = (np.asarray(mesh.vertices, float) - np.asarray(point, float)) @ normal
    on_plane = np.abs(d) < ON_PLANE_MM  # kept, and a cut through it is the vertex itself (no sliver)
    above = (d > 0) | on_plane
    faces = np.asarray(mesh.faces, np.int64)
    inside = above[faces]
    whole = faces[inside.all(axis=1)]
    crossing = faces[inside.any(axis=1) & ~inside.all(axis=1)]
    vertices = [np.asarray(mesh.vertices, float)]
    new_index: dict[tuple[int, int], int] = {}
    count = len(mesh.vertices)

    def cut(a: int, b: int) -> int:
        nonlocal count
        if on_plane[a] or on_plane[b]:
            return a if on_plane[a] else b
        key = (min(a, b), max(a, b))
        if key not in new_index:
            t = d[key[0]] / (d[key[0]] - d[key[1]])
            p = mesh.vertices[key[0]] + t * (mesh.vertices[key[1]] - mesh.vertices[key[0]])
            vertices.append(p[None])
            new_index[key] = count
            count += 1
        return new_index[key]

    clipped = []
    for tri in crossing:
        keep = above[tri]
        # rotate so the odd vertex (the lone kept one, or the lone dropped one) comes first
        odd = int(np.flatnonzero(keep != (keep.sum() >= 2))[0]) if keep.sum() in (1, 2) else 0
        a, b, c = np.roll(tri, -odd)
        ab, ac = cut(a, b), cut(a, c)
        if above[a]:
            clipped.append((a, ab, ac))
        else:
            clipped += [(ab, b, c), (ab, c, ac)]
    clipped = np.array(clipped, np.int64).reshape(-1, 3)
    clipped = clipped[(clipped[:, 0] != clipped[:, 1]) & (clipped[:, 1] != clipped[:, 2]) & (clipped[:, 0] != clipped[:, 2])]
    all_faces = np.vstack([whole, clipped])
    out = trimesh.Trimesh(np.vstack(vertices), all_faces, process=False)
    out.remove_unreferenced_vertices()
    return out

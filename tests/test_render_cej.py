"""The crown/root boundary is drawn along the CEJ plane, not as a staircase of whole triangles."""

from __future__ import annotations

import numpy as np
import trimesh

from orthosim.tooth import CROWN, ROOT, part_of_faces
from render.cej import split_at_cej


def _ball():
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=5.0)
    mesh.apply_translation([0.0, 1.3, 0.0])  # the CEJ plane y = 0 cuts it off-centre
    return mesh


def test_straddling_triangles_are_cut_so_crown_and_root_colours_meet_on_the_cej_plane():
    mesh = _ball()
    vertices, normals, faces, part = split_at_cej(mesh, part_of_faces(mesh))
    ys = vertices[faces][:, :, 1]
    assert (ys[part == CROWN] >= -1e-9).all()  # no crown colour below the plane
    assert (ys[part == ROOT] <= 1e-9).all()  # no root colour above it
    drawn = trimesh.Trimesh(vertices, faces, process=False)
    assert abs(drawn.area - mesh.area) < 1e-9  # the same surface, only cut
    drawn.merge_vertices()
    assert drawn.is_watertight  # no crack along the seam
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)


def test_a_model_with_its_own_cej_line_is_drawn_as_labelled():
    mesh = _ball()
    own = np.zeros(len(mesh.faces), np.int8)
    own[::2] = ROOT  # not the plane rule: left as the model says
    vertices, _, faces, part = split_at_cej(mesh, own)
    assert len(faces) == len(mesh.faces) and np.array_equal(part, own)

"""The crown/root boundary is drawn along the CEJ plane, not as a staircase of whole triangles."""

from __future__ import annotations

import numpy as np
import trimesh

from orthosim.model.tooth import CROWN, ROOT, part_of_faces
from orthosim_render.cej import cut_at_cej, split_at_cej, vertex_blend


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


def test_every_drawn_face_and_vertex_of_the_cut_says_where_on_the_model_it_lies():
    mesh = _ball()
    cut = cut_at_cej(mesh, part_of_faces(mesh))
    assert len(cut.faces) > len(mesh.faces)  # some faces were cut
    v = np.asarray(mesh.vertices)
    rebuilt = (1 - cut.t)[:, None] * v[cut.ends[:, 0]] + cut.t[:, None] * v[cut.ends[:, 1]]
    np.testing.assert_allclose(rebuilt, cut.vertices, atol=1e-9)
    # the pieces of each model face cover exactly that face
    drawn_area = trimesh.triangles.area(cut.vertices[cut.faces])
    np.testing.assert_allclose(np.bincount(cut.source_face, drawn_area, len(mesh.faces)), mesh.area_faces, atol=1e-9)


def test_a_value_given_on_the_crowns_vertices_is_carried_linearly_onto_the_cut():
    mesh = _ball()
    part = part_of_faces(mesh)
    cut = cut_at_cej(mesh, part)
    crown = np.unique(mesh.faces[part == CROWN])
    drawn = np.unique(cut.faces[cut.part == CROWN])
    blend = vertex_blend(crown, cut.ends[drawn], cut.t[drawn], cut.vertices[drawn], mesh.vertices)
    height = mesh.vertices[crown][:, 1]  # linear along every edge, so carried exactly
    on_cut = blend.apply(height)
    ends_known = np.isin(cut.ends[drawn], crown)
    both = ends_known.all(axis=1)
    np.testing.assert_allclose(on_cut[both], cut.vertices[drawn][both, 1], atol=1e-9)
    # an edge running into the root (no value there) takes its crown end's value
    one = ends_known[:, 0] != ends_known[:, 1]
    assert one.any()
    known_end = np.where(ends_known[one, 0], cut.ends[drawn][one, 0], cut.ends[drawn][one, 1])
    np.testing.assert_allclose(on_cut[one], mesh.vertices[known_end, 1], atol=1e-9)
    assert np.all(np.isfinite(on_cut))


def _ball_dentition():
    from orthosim.model.dentition import Dentition
    from orthosim.model.tooth import Tooth

    mesh = _ball()
    tooth = Tooth(11, mesh, part_of_faces(mesh), np.array([0.0, 4.0, 0.0]), np.array([0.0, -4.0, 0.0]), np.eye(4), {})
    return Dentition({11: tooth}, "a ball", {})


def test_a_crown_painted_per_model_vertex_is_drawn_on_the_cut_mesh_with_those_colours():
    from orthosim_render.scene import DentitionScene, paint_crowns

    dent = _ball_dentition()
    scene = DentitionScene(dent, (64, 48), hide_roots=True, show_markers=False)
    drawn = scene.teeth[11]
    assert len(drawn.indices) > (dent.teeth[11].face_part == CROWN).sum()  # the smooth cut is on
    crown = dent.teeth[11].crown_vertices
    shade = np.clip(crown[:, 1:2] / 7.0, 0, 1) * np.ones((1, 3))  # a colour that grows with height
    paint_crowns(scene, {11: shade})
    colours = drawn.primitive.color_0[:, :3]
    positions = drawn.primitive.positions
    on_plane = np.abs(positions[:, 1]) < 1e-6
    assert on_plane.sum() > 10  # the cut's own vertices are painted too, from the crown just above
    assert np.all(colours[on_plane, 0] < 0.15) and np.all(colours[on_plane, 0] >= 0.0)
    far = positions[:, 1] > 1.0  # the model's crown vertices keep their own colour
    np.testing.assert_allclose(colours[far, 0], np.clip(positions[far, 1] / 7.0, 0, 1), atol=1e-5)


def test_exact_contact_faces_colour_the_pieces_of_the_cut_faces_they_name():
    from orthosim_render.scene import DentitionScene

    dent = _ball_dentition()
    scene = DentitionScene(dent, (64, 48), hide_roots=False, show_markers=False, contact_faces_exact=True)
    drawn = scene.teeth[11]
    cut_faces = np.flatnonzero(np.bincount(drawn.face_of_row, minlength=len(dent.teeth[11].mesh.faces)) > 1)
    assert len(cut_faces)
    rows = np.flatnonzero(np.isin(drawn.face_of_row, cut_faces[:1]))
    assert len(rows) == 3  # one model face drawn as a triangle and a quad, crown and root colours
    corners = drawn.primitive.positions[drawn.indices[rows]].reshape(-1, 3)
    model = dent.teeth[11].mesh.triangles[cut_faces[0]]
    # every piece lies on the model face it came from
    normal = np.cross(model[1] - model[0], model[2] - model[0])
    np.testing.assert_allclose((corners - model[0]) @ normal / np.linalg.norm(normal), 0.0, atol=1e-5)

"""The parametric dental model: anatomy, arch layout and occlusion, measured on the meshes."""

import numpy as np
import pytest

from orthosim.model import fdi as F
from orthosim.model.anatomy import dimensions
from orthosim.geometry.meshquery import MeshQuery
from orthosim.model.occlusion import bolton_ratios, mesiodistal_width, molar_relation, overbite, overjet
from orthosim.model.parametric import parametric_dentition
from orthosim.model.tooth import CROWN, ROOT


@pytest.fixture(scope="module")
def dent():
    return parametric_dentition("smooth")


@pytest.fixture(scope="module")
def query(dent):
    return MeshQuery({n: t.mesh for n, t in dent.teeth.items()})


def test_default_model_has_28_teeth_named_by_fdi(dent):
    assert sorted(dent.teeth) == [10 * q + p for q in (1, 2, 3, 4) for p in range(1, 8)]


def test_third_molars_are_optional():
    assert {18, 28, 38, 48} <= set(parametric_dentition("coarse", third_molars=True).teeth)


@pytest.mark.parametrize("resolution", ["coarse", "smooth"])
def test_every_tooth_is_closed_with_positive_volume(resolution):
    for tooth in parametric_dentition(resolution).teeth.values():
        m = tooth.mesh
        assert m.is_watertight and m.is_winding_consistent, tooth.fdi
        assert m.volume > 100, tooth.fdi  # mm^3; a real incisor is about 300-600
        # outward normals: the volume-weighted normals point away from the centre of mass
        out = (m.triangles_center - m.center_mass) * m.face_normals
        assert (out.sum(axis=1) * m.area_faces).sum() > 0


def test_resolution_knob_spans_the_papers_coarse_teeth_to_smooth_ones():
    coarse = [len(t.mesh.vertices) for t in parametric_dentition("coarse").teeth.values()]
    smooth = [len(t.mesh.faces) for t in parametric_dentition("smooth").teeth.values()]
    assert 100 <= np.median(coarse) <= 200  # the paper: about 125 vertices, 180 polygons
    assert min(smooth) >= 2000


def test_crowns_have_wheeler_widths_and_heights(dent):
    for n, tooth in dent.teeth.items():
        d = dimensions(n)
        assert mesiodistal_width(dent, n) == pytest.approx(d.md_width, abs=0.02)
        crown = tooth.crown_vertices
        assert np.ptp(crown[:, 2]) == pytest.approx(d.bl_width, abs=0.05)
        assert crown[:, 1].max() == pytest.approx(d.crown_height, abs=0.05)
        assert tooth.root_length == pytest.approx(d.root_length)
        assert tooth.mesh.vertices[:, 1].min() == pytest.approx(-d.root_length, abs=0.05)


def _roots_at(mesh, level):
    section = mesh.section(plane_origin=[0, level, 0], plane_normal=[0, 1, 0])
    return len(section.discrete)


@pytest.mark.parametrize("n", [11, 12, 13, 14, 15, 16, 17, 31, 32, 33, 34, 35, 36, 37])
def test_root_count_matches_anatomy(dent, n):
    tooth = dent.teeth[n]
    level = -0.6 * tooth.root_length  # well below the furcation, above the apices
    assert _roots_at(tooth.mesh, level) == dimensions(n).roots


def test_crown_and_root_parts_are_told_apart_at_the_cej(dent):
    for tooth in dent.teeth.values():
        y = tooth.mesh.triangles_center[:, 1]
        assert (y[tooth.face_part == CROWN] >= 0).all() and (y[tooth.face_part == ROOT] < 0).all()
        assert (tooth.face_part == CROWN).any() and (tooth.face_part == ROOT).any()
        assert 0 < tooth.crown_center[1] < dimensions(tooth.fdi).crown_height


def test_local_frames_point_mesial_labial_and_occlusal(dent):
    centers = dent.crown_centers()
    for n, tooth in dent.teeth.items():
        R = tooth.rest_pose[:3, :3]
        assert np.allclose(R.T @ R, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
        occlusal = R @ tooth.long_axis
        assert occlusal[1] < -0.9 if F.arch_of(n) is F.Arch.UPPER else occlusal[1] > 0.9  # crowns toward y = 0
        labial = R @ tooth.labial
        c = centers[n]
        assert labial[[0, 2]] @ (c[[0, 2]] - np.array([0.0, -10.0])) > 0  # away from the arch interior
        mesial = R @ tooth.mesial
        assert mesial[0] * c[0] < 0 or abs(c[0]) < 5  # toward the midline


def test_patients_right_is_negative_x_and_arches_run_right_to_left(dent):
    centers = dent.crown_centers()
    for arch in (F.Arch.UPPER, F.Arch.LOWER):
        order = dent.arch(arch)
        xs = [centers[n][0] for n in order]
        assert xs[0] < 0 < xs[-1]
        mid = len(order) // 2
        assert np.all(np.diff(xs[:mid]) > 0) and np.all(np.diff(xs[mid:]) > 0)


def test_adjacent_crowns_touch_without_overlap(dent, query):
    poses = dent.rest_poses()
    for a, b in dent.adjacent_pairs():
        assert not query.intersects(a, poses[a], b, poses[b]), (a, b)  # penetration 0
        assert query.distance(a, poses[a], b, poses[b]) <= 0.1, (a, b)


def test_upper_and_lower_teeth_do_not_interpenetrate_and_posteriors_occlude(dent, query):
    poses = dent.rest_poses()
    closest = np.inf
    for u in dent.arch(F.Arch.UPPER):
        for low in dent.arch(F.Arch.LOWER):
            assert not query.intersects(u, poses[u], low, poses[low]), (u, low)
            if F.position(u) >= 4 and F.position(low) >= 4 and F.side(u) == F.side(low):
                closest = min(closest, query.distance(u, poses[u], low, poses[low]))
    assert closest <= 0.1  # the posterior teeth are in occlusion, not floating apart


def test_overjet_and_overbite_are_about_2_mm(dent):
    assert overjet(dent) == pytest.approx(2.0, abs=0.5)
    assert overbite(dent) == pytest.approx(2.0, abs=0.5)


def test_molars_are_in_angle_class_i(dent):
    # mesiobuccal cusp of the upper first molar over the buccal groove of the lower one
    assert abs(molar_relation(dent)) < 1.0


def test_bolton_ratios_match_the_ideal(dent):
    ratios = bolton_ratios(dent)
    assert ratios["overall"] == pytest.approx(91.4, abs=0.5)
    assert ratios["anterior"] == pytest.approx(77.8, abs=0.5)


def test_upper_arch_is_wider_than_the_lower_one_at_the_molars(dent):
    c = dent.crown_centers()
    assert c[26][0] - c[16][0] > c[36][0] - c[46][0] + 2.0  # upper buccal cusps overlap the lower ones


def test_diastema_opens_a_space_between_the_central_incisors():
    from orthosim.analysis.metrics import tooth_to_tooth_distances

    closed = parametric_dentition("coarse")
    opened = parametric_dentition("coarse", diastema_mm=2.0)
    q = MeshQuery({n: t.mesh for n, t in opened.teeth.items()})
    p = opened.rest_poses()
    for a, b in ((11, 21), (41, 31)):
        assert q.distance(a, p[a], b, p[b]) == pytest.approx(2.0, abs=0.06)
    d0 = {d.pair: d.distance_mm for d in tooth_to_tooth_distances(closed)}
    d1 = {d.pair: d.distance_mm for d in tooth_to_tooth_distances(opened)}
    assert d1[(11, 21)] > d0[(11, 21)] + 1.5
    assert d1[(12, 11)] == pytest.approx(d0[(12, 11)], abs=0.3)  # the rest of the arch still touches


@pytest.mark.parametrize("resolution, diastema", [("coarse", 0.0), ("coarse", 2.0), ("smooth", 2.0)])
def test_every_variant_of_the_model_keeps_normal_occlusion_without_interpenetration(resolution, diastema):
    d = parametric_dentition(resolution, diastema_mm=diastema)
    q = MeshQuery({n: t.mesh for n, t in d.teeth.items()})
    p = d.rest_poses()
    for u in d.arch(F.Arch.UPPER):
        for low in d.arch(F.Arch.LOWER):
            assert not q.intersects(u, p[u], low, p[low]), (u, low)
    for a, b in d.adjacent_pairs():
        assert not q.intersects(a, p[a], b, p[b]), (a, b)
    assert overjet(d) == pytest.approx(2.0, abs=0.5) and overbite(d) == pytest.approx(2.0, abs=0.5)
    assert abs(molar_relation(d)) < 1.0

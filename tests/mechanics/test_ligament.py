"""A tooth held by its periodontal ligament: a root symmetric about its axis has its centre of
resistance on the axis, a force through it translates the tooth and a couple turns the tooth about
it; the published ranges and the bone level are checked; every real tooth gets a centre on its root."""

import numpy as np
import pytest
import trimesh

from orthosim.errors import CaseError
from orthosim.mechanics.ligament import DEFAULT, LigamentProperties, RootSupport, root_support
from orthosim.model.tooth import Tooth, part_of_faces

ROOT_MM, CROWN_MM, RADIUS_MM = 12.0, 8.0, 3.0


def _cylinder_tooth(fdi: int = 11) -> Tooth:
    """A round peg: a closed cylinder about the long axis, root 12 mm apical of the CEJ, crown 8 mm."""
    mesh = trimesh.creation.cylinder(radius=RADIUS_MM, height=ROOT_MM + CROWN_MM, sections=48)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))
    mesh.apply_translation([0.0, (CROWN_MM - ROOT_MM) / 2, 0.0])
    mesh = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, 1.0))
    return Tooth(fdi, mesh, part_of_faces(mesh), np.array([0.0, CROWN_MM / 2, 0.0]), np.array([0.0, -ROOT_MM, 0.0]), np.eye(4))


@pytest.fixture(scope="module")
def peg() -> RootSupport:
    return root_support(_cylinder_tooth())


def test_a_symmetric_roots_centre_of_resistance_lies_on_its_axis_within_the_embedded_root(peg):
    c = peg.center_of_resistance
    assert abs(c[0]) < 1e-6 and abs(c[2]) < 1e-6
    assert -ROOT_MM < c[1] < -DEFAULT.crest_below_cej_mm
    assert peg.resistance_residual_mm < 1e-6
    assert peg.embedded_area_mm2 == pytest.approx(2 * np.pi * RADIUS_MM * (ROOT_MM - 1.5) + np.pi * RADIUS_MM ** 2, rel=0.05)


@pytest.mark.parametrize("direction", [[0, 0, -1.0], [1.0, 0, 0], [0.6, 0, 0.8], [0, -1.0, 0]])
def test_a_force_through_the_centre_of_resistance_translates_the_tooth_without_turning(peg, direction):
    t, w = peg.motion(np.array(direction), peg.center_of_resistance)
    assert np.linalg.norm(w) < 1e-9 * np.linalg.norm(t)
    assert np.cross(t / np.linalg.norm(t), direction) == pytest.approx(np.zeros(3), abs=1e-9)
    assert np.all(np.isinf(peg.center_of_rotation(np.array(direction), peg.center_of_resistance)))


@pytest.mark.parametrize("axis", [[1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])
def test_a_couple_turns_the_tooth_about_its_centre_of_resistance(peg, axis):
    t, w = peg.motion(np.zeros(3), np.zeros(3), np.array(axis))
    c = peg.center_of_resistance
    assert np.linalg.norm(peg.translation_at(c, t, w)) < 1e-9 * np.linalg.norm(w)
    assert peg.center_of_rotation(np.zeros(3), np.zeros(3), np.array(axis)) == pytest.approx(c, abs=1e-9)


def test_a_force_at_the_crown_tips_the_tooth_about_a_point_apical_of_the_centre(peg):
    bracket = np.array([0.0, 4.0, RADIUS_MM])
    cr = peg.center_of_rotation(np.array([0, 0, -1.0]), bracket)
    assert -ROOT_MM < cr[1] < peg.center_of_resistance[1]
    # a couple opposing the tipping moves the centre of rotation toward the apex
    d = bracket[1] - peg.center_of_resistance[1]
    deeper = peg.center_of_rotation(np.array([0, 0, -1.0]), bracket, np.array([0.8 * d, 0, 0]))  # the force turns the tooth about -x
    assert deeper[1] < cr[1]


def test_the_stiffness_is_symmetric_and_positive_definite(peg):
    K = peg.stiffness
    assert np.allclose(K, K.T, atol=1e-9 * np.abs(K).max())
    assert np.all(np.linalg.eigvalsh(K) > 0)


def test_a_stiffer_ligament_scales_the_stiffness_but_not_the_centre():
    tooth = _cylinder_tooth()
    soft, stiff = root_support(tooth), root_support(tooth, LigamentProperties(modulus_mpa=1.36))
    assert stiff.stiffness == pytest.approx(2 * soft.stiffness)
    assert stiff.center_of_resistance == pytest.approx(soft.center_of_resistance)


def test_bone_loss_moves_the_centre_of_resistance_toward_the_apex():
    tooth = _cylinder_tooth()
    healthy, lost = root_support(tooth), root_support(tooth, crest_below_cej_mm=5.0)
    assert lost.center_of_resistance[1] < healthy.center_of_resistance[1] - 1.0
    assert lost.embedded_area_mm2 < healthy.embedded_area_mm2


@pytest.mark.parametrize("field, value", [("modulus_mpa", 200.0), ("poisson", 0.5), ("thickness_mm", 1.0),
                                          ("crest_below_cej_mm", 4.0)])
def test_a_ligament_parameter_outside_its_published_range_is_refused_naming_it(field, value):
    with pytest.raises(CaseError, match=f"ligament.{field}.*published range"):
        LigamentProperties(**{field: value})


def test_a_bone_level_deeper_than_the_root_is_refused():
    with pytest.raises(CaseError, match=r"ligament.bone_level_mm.11.*deeper than tooth 11's root"):
        root_support(_cylinder_tooth(), crest_below_cej_mm=12.5)


def test_a_tooth_with_no_embedded_root_left_is_refused():
    tooth = _cylinder_tooth()
    crownless = Tooth(11, tooth.mesh, np.zeros(len(tooth.mesh.faces), np.int8), tooth.crown_center, tooth.apex, np.eye(4))
    with pytest.raises(CaseError, match="no root surface"):
        root_support(crownless)


@pytest.mark.real_data
@pytest.mark.slow
def test_every_real_tooth_has_its_centre_of_resistance_on_its_embedded_root():
    from fulljaw_helpers import full_jaw

    dentition, _ = full_jaw()
    assert len(dentition.teeth) == 31
    for n, tooth in dentition.teeth.items():
        s = root_support(tooth)
        c = s.center_of_resistance
        assert tooth.apex[1] < c[1] < -DEFAULT.crest_below_cej_mm, n
        assert np.hypot(c[0], c[2]) < 2.5, n  # near the long axis
        assert s.resistance_residual_mm < 0.25 * tooth.root_length, n


def test_the_reference_premolars_embedded_share_is_the_one_the_rate_law_counts():
    from orthosim.mechanics.ligament import EMBEDDED_SHARE_OF_REFERENCE
    from orthosim.model.parametric import parametric_dentition
    from orthosim.model.tooth import ROOT

    premolar = parametric_dentition("smooth").teeth[15]
    whole = premolar.mesh.area_faces[premolar.face_part == ROOT].sum()
    assert root_support(premolar).embedded_area_mm2 / whole == pytest.approx(EMBEDDED_SHARE_OF_REFERENCE, abs=0.001)

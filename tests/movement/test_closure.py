"""The bite closes after every step: a molar glides over its antagonist's cusp, the bite opens by the
cusp's height and closes again, and nothing passes through anything."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from collision_helpers import median_split_tree
from orthosim.collision import CollisionModel, ExactQueries
from orthosim.errors import CaseError
from orthosim import load_case
from orthosim.model.dentition import Dentition
from orthosim.model.tooth import Tooth, part_of_faces
from orthosim.movement.closure import (ClosureModel, ClosureSettings, close_bite, closure_settings,
                                       estimate_hinge_axis)

CUSP_MM = 1.0  # the lower molar's ridge stands this far above its edges
AXIS = ((-50.0, 40.0, -60.0), (50.0, 40.0, -60.0))  # right and left condyles, 60 mm behind the molar


def _tooth(n: int, mesh: trimesh.Trimesh, pose: np.ndarray) -> Tooth:
    return Tooth(n, mesh, part_of_faces(mesh), np.array([0.0, 1.0, 0.0]), np.array([0.0, -6.0, 0.0]), pose, {})


def _upside_down(x: float, y: float, z: float) -> np.ndarray:
    """An upper tooth's pose: local +y (toward the occlusal surface) points down."""
    T = np.diag([1.0, -1.0, -1.0, 1.0])
    T[:3, 3] = x, y, z
    return T


def cusp_model() -> tuple[Dentition, dict]:
    """A lower molar (46) with one transverse ridge CUSP_MM high (a gable: edges at y = 2 mm at z = +-5,
    apex at y = 3 at z = 0), an upper molar (16, a flat-bottomed block 4 mm long) resting beside it at
    the edges' level, and an incisor stop (11 on 41, 0.005 mm apart) that holds the bite at rest."""
    gable = trimesh.convex.convex_hull(np.array([[x, y, z] for x in (-5.0, 5.0) for y, z in
                                                 ((-6.0, -5.0), (-6.0, 5.0), (2.0, -5.0), (2.0, 5.0), (3.0, 0.0))]))
    upper = trimesh.creation.box(extents=[8.0, 6.0, 4.0])
    upper.apply_translation([0.0, 3.0, 0.0])  # crown from the local origin up to y = 6
    incisor = trimesh.creation.box(extents=[6.0, 6.0, 4.0])
    incisor.apply_translation([0.0, 3.0, 0.0])
    lower_incisor = incisor.copy()
    teeth = {
        46: _tooth(46, gable, np.eye(4)),
        16: _tooth(16, upper, _upside_down(0.0, 8.0, -8.0)),  # bottom at y = 2, spanning z -10..-6
        41: _tooth(41, lower_incisor, _translation(0.0, -6.005, 40.0)),  # top at y = -0.005
        11: _tooth(11, incisor, _upside_down(0.0, 6.0, 40.0)),  # bottom at y = 0
    }
    return Dentition(teeth, "a molar ridge and an incisor stop", {"kind": "test"}), {}


def _translation(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = x, y, z
    return T


@pytest.fixture(scope="module")
def cusp():
    dent, _ = cusp_model()
    cm = ClosureModel.build(ClosureSettings("hinge", AXIS), dent, [(16, 46), (11, 41)])
    collision = CollisionModel.from_dentition(dent, tree_builder=median_split_tree)
    return dent, cm, collision


def test_an_upper_molar_glides_over_the_lower_cusp_and_the_bite_opens_by_its_height_then_closes(cusp):
    dent, cm, collision = cusp
    queries = ExactQueries(collision)
    poses = dent.rest_poses()
    angle, openings = 0.0, []
    for dz in np.arange(0.0, 16.01, 0.25):  # the upper molar from behind the ridge to beyond it
        poses[16] = _translation(0.0, 0.0, dz) @ dent.teeth[16].rest_pose
        closed = close_bite(cm, collision, queries, poses, angle)
        assert not closed.unresolved
        for pair in cm.facing:  # nothing passes through anything
            assert not queries.intersects(pair, closed.poses), (dz, pair)
        angle = closed.angle_deg
        poses = closed.poses
        openings.append(cm.opening_mm(angle)[1])
    openings = np.array(openings)
    assert abs(openings.max() - CUSP_MM) <= 0.1, openings.max()
    assert abs(openings[0]) <= 0.02 and abs(openings[-1]) <= 0.02, (openings[0], openings[-1])  # closed before and after
    assert np.all(openings >= -0.02)  # the incisor stop holds the bite: it never closes past rest


def test_closing_a_bite_that_nothing_changed_leaves_it_where_it_stood(cusp):
    dent, cm, collision = cusp
    closed = close_bite(cm, collision, ExactQueries(collision), dent.rest_poses(), 0.0)
    incisors, molars = cm.opening_mm(closed.angle_deg)
    assert 0.0 <= incisors <= 0.02 + 1e-9  # within the contact tolerance of travel, on the open side
    assert not closed.unresolved


def test_a_contact_opening_cannot_clear_is_reported_unresolved(cusp):
    """An upper molar driven sideways into the middle of the lower one: the hinge opening the case allows
    (2 degrees, 2 mm at the molar) cannot lift the lower molar out of it."""
    dent, _, collision = cusp
    cm = ClosureModel.build(ClosureSettings("hinge", AXIS, max_opening_deg=2.0), dent, [(16, 46), (11, 41)])
    poses = dent.rest_poses()
    poses[16] = _translation(0.0, -4.0, 8.0) @ dent.teeth[16].rest_pose  # 4 mm down into 46
    closed = close_bite(cm, collision, ExactQueries(collision), poses, 0.0)
    assert (16, 46) in closed.unresolved


def test_the_hinge_axis_of_an_arch_lies_by_bonwills_triangle():
    from orthosim.model.parametric import parametric_dentition

    dent = parametric_dentition()
    axis = estimate_hinge_axis(dent)
    cm = ClosureModel.build(ClosureSettings("hinge"), dent, [(11, 41)])
    assert np.linalg.norm(axis.left_mm - axis.right_mm) == pytest.approx(100.0)
    for condyle in (axis.left_mm, axis.right_mm):
        assert np.linalg.norm(condyle - cm.incisal_mm) == pytest.approx(100.0)
    assert axis.left_mm[0] > axis.right_mm[0]  # the patient's left is +x in the arch frame
    # opening moves the incisors down: a positive angle is an open bite
    assert cm.opening_mm(2.0)[0] > 0 > cm.opening_mm(-2.0)[0]


def test_the_paper_cases_close_no_bite_and_mesh_models_do(tmp_path):
    case = load_case(Path(__file__).resolve().parents[2] / "cases" / "case1_first_premolar_extraction.toml")
    assert closure_settings(case).mode == "none"
    text = (tmp_path / "c.toml")
    text.write_text('[model]\nkind = "parametric"\n[occlusion]\nclosure = "hinge"\n'
                    'condylar_axis = [[-50, 40, -60], [50, 40, -60]]\n')
    chosen = closure_settings(load_case(text))
    assert chosen.mode == "hinge" and chosen.condylar_axis_mm == ((-50.0, 40.0, -60.0), (50.0, 40.0, -60.0))


@pytest.mark.parametrize("table, field", [
    ('closure = "open"', "occlusion.closure"),
    ("condylar_axis = [[0, 0, 0]]", "occlusion.condylar_axis"),
    ("condylar_axis = [[0, 0, 0], [10, 0, 0]]", "occlusion.condylar_axis"),
    ('condylar_axis = [[0, 0, 0], [100, 0, "a"]]', "occlusion.condylar_axis[1]"),
    ("max_opening_deg = 45", "occlusion.max_opening_deg"),
    ("hinge = true", "occlusion.hinge"),
])
def test_a_bad_occlusion_table_names_the_field_and_the_fix(tmp_path, table, field):
    path = tmp_path / "bad.toml"
    path.write_text(f"[model]\nkind = \"parametric\"\n[occlusion]\n{table}\n")
    with pytest.raises(CaseError) as err:
        load_case(path)
    assert field in str(err.value) and str(path) in str(err.value)

"""The bounding-circles detector reports where teeth meet, so its frames show contacts like the others'."""

import numpy as np

from orthosim.collision import CollisionModel, detect_step
from orthosim.model.dentition import Dentition
from orthosim.model.parametric import parametric_dentition
from orthosim.geometry.pose import translation
from orthosim.spheretree import cached_sphere_tree


def test_a_circles_contact_is_a_sphere_in_the_overlap_of_the_two_circles():
    dent = parametric_dentition("smooth")
    two = Dentition({n: dent.teeth[n] for n in (16, 15)})
    model = CollisionModel.from_dentition(two, tree_builder=cached_sphere_tree)
    rest = two.rest_poses()
    c = two.crown_centers()
    toward = (c[15] - c[16]) / np.linalg.norm(c[15] - c[16])
    pushed = {**rest, 16: translation(0.5 * toward) @ rest[16]}
    res = detect_step(model, pushed, None, pairs=[(16, 15)], detector="circles")
    assert res.touching_pairs() == [(16, 15)]
    assert len(res.radii_a) == 1 and res.radii_a[0] > 0 and np.all(res.leaf_pairs == -1)
    # the marker sits between the two crowns, in the occlusal plane's projection
    c16 = two.teeth[16].to_world(two.teeth[16].crown_center, pushed[16])
    p = res.centers_a[0]
    u = (c[15] - c16)[[0, 2]]
    along = float((p - c16)[[0, 2]] @ u / (u @ u))
    assert 0.0 < along < 1.0
    # pulled well apart: no contact, nothing to draw
    apart = {**rest, 16: translation(-6.0 * toward) @ rest[16]}
    res = detect_step(model, apart, None, pairs=[(16, 15)], detector="circles")
    assert not res.any_touching and len(res.radii_a) == 0


def test_a_circles_simulation_records_contacts_for_its_touching_pairs():
    from orthosim import load_case
    from orthosim.movement.simulation import MovementModel, simulate

    from pathlib import Path

    case = load_case(Path(__file__).resolve().parents[2] / "cases" / "case3_incisor_space_closure.toml")
    model = MovementModel.build(case)
    first = next(iter(simulate(model, "circles", steps=0)))
    assert first.touching and len(first.contact_radii) == len(first.touching)
    assert np.all(first.contact_radii > 0)

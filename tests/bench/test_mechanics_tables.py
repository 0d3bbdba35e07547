"""The tooth-mechanics tables (`orthosim_bench.mechanics`): as M/F at an incisor's bracket rises, the
ligament alone orders the four classical movements, and the tooth translates at M/F equal to its
bracket's distance from the centre of resistance (Smith and Burstone's linear theory)."""

import pytest

from orthosim.model.parametric import parametric_dentition
from orthosim_bench.mechanics import resistance_rows, rotation_crossings, rotation_rows

ORDER = ["uncontrolled tipping", "controlled tipping", "translation", "root movement"]


@pytest.fixture(scope="module")
def dent():
    return parametric_dentition("coarse")


def test_the_movement_classes_come_in_their_published_order_as_m_over_f_rises(dent):
    classes = [r["class"] for r in rotation_rows(dent.teeth[11], [x / 4 for x in range(57)])]
    seen = [c for i, c in enumerate(classes) if i == 0 or c != classes[i - 1]]
    assert [c for c in seen if c != "translation"] == ["uncontrolled tipping", "controlled tipping", "root movement"]
    assert classes[0] == "uncontrolled tipping" and classes[-1] == "root movement"


def test_the_incisor_translates_at_m_over_f_equal_to_its_bracket_lever_and_tips_controlled_below_it(dent):
    x = rotation_crossings(dent.teeth[11])
    assert x["translation_mf_mm"] == pytest.approx(x["bracket_to_cr_mm"], abs=0.5)
    assert 0 < x["controlled_tipping_mf_mm"] < x["translation_mf_mm"]


def test_single_rooted_parametric_teeth_have_their_centre_a_third_to_a_half_down_the_embedded_root(dent):
    for row in resistance_rows(dent):
        if not row["molar"]:
            assert 1 / 3 - 0.05 < row["share"] < 0.5, row

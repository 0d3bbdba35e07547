"""Occlusion on the real bite: the occlusal measures, the contacts per pair, and their areas drawn in
the maxillary and mandibular occlusal views (the real counterpart of the paper's Figure 7)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from fulljaw_helpers import full_jaw
from orthosim.analysis.occlusalcontacts import occlusal_contacts, occlusion_record


@lru_cache(maxsize=1)
def _contacts():
    return occlusal_contacts(full_jaw()[0])


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
@pytest.mark.real_data
def test_the_occlusal_measures_of_the_parametric_model_come_out_on_the_real_bite():
    dent, _ = full_jaw()
    record = occlusion_record(dent, _contacts())
    # measured on this patient: overjet 1.0 mm, overbite 1.6 mm, molar relation -1.3 mm
    assert 0.0 < record["overjet_mm"] < 4.0 and 0.0 < record["overbite_mm"] < 4.0
    assert abs(record["molar_relation_mm"]) < 3.0  # within about half a cusp of Angle class I
    bolton = record["bolton_percent"]
    assert 85.0 < bolton["overall"] < 97.0 and 68.0 < bolton["anterior"] < 84.0
    assert {tuple(c["pair"]) for c in record["contacts"]} >= {(16, 46), (17, 47), (26, 37), (25, 36), (15, 45)}


@pytest.mark.real_data
def test_posterior_teeth_meet_on_both_sides_with_areas_of_square_millimetres_at_the_occlusal_plane():
    contacts = [c for c in _contacts() if c.in_contact]
    for side in ((15, 16, 17), (25, 26, 27)):
        here = [c for c in contacts if c.pair[0] in side]
        assert sum(c.area_upper_mm2 for c in here) > 5.0, here
    for c in contacts:
        # the same patch seen from both teeth: areas agree within a third, and it lies at the bite
        assert c.area_lower_mm2 == pytest.approx(c.area_upper_mm2, rel=0.35, abs=0.05)
        assert np.all(np.abs(c.points_upper[:, 1]) < 3.0)
    apart = [c for c in _contacts() if not c.in_contact]
    assert all(c.distance_mm > 0.1 for c in apart)


@pytest.mark.real_data
def test_the_contact_areas_are_drawn_in_both_occlusal_views():
    from orthosim_render.occlusion_figure import FIGURE_VIEWS, render_occlusal_contacts
    from orthosim_render.scene import CONTACT_COLOR

    dent, _ = full_jaw()
    images = render_occlusal_contacts(dent, _contacts(), size=(320, 240))
    red = (np.asarray(CONTACT_COLOR) * 255).astype(int)
    for view in FIGURE_VIEWS:
        img = images[view].astype(int)
        painted = (img[..., 0] > 150) & (img[..., 1] < 0.5 * img[..., 0]) & (img[..., 2] < 0.8 * img[..., 0])
        assert painted.sum() > 30, view  # the contact patches show in this view
        assert red[0] > red[2]
    plain = render_occlusal_contacts(dent, [], size=(320, 240))
    for view in FIGURE_VIEWS:
        img = plain[view].astype(int)
        assert ((img[..., 0] > 150) & (img[..., 1] < 0.5 * img[..., 0]) & (img[..., 2] < 0.8 * img[..., 0])).sum() < 5

"""Estimated roots against real ones: the 31 CBCT teeth of Open-Full-Jaw patient 26 cut at their CEJ and rebuilt.

The table per tooth type is in docs/notes/intraoral-scans.md (made by `orthosim_bench.rootaccuracy`).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from orthosim.exchange.case import CASES_DIR, load_case

pytestmark = [pytest.mark.real_data, pytest.mark.slow]


@pytest.fixture(scope="module")
def errors():
    from orthosim_bench.rootaccuracy import root_errors

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dentition = load_case(CASES_DIR / "open_full_jaw_case1_first_premolar_extraction.toml").build_dentition()
    return root_errors(dentition)


def test_all_31_real_teeth_are_rebuilt_from_their_crowns(errors):
    assert len(errors) == 31


def test_the_estimated_centre_of_resistance_lies_within_1_5_mm_of_the_real_one_in_the_median(errors):
    assert float(np.median([e.resistance_mm for e in errors])) < 1.5


def test_the_estimated_long_axis_lies_within_8_degrees_of_the_real_one_in_the_median(errors):
    assert float(np.median([e.axis_deg for e in errors])) < 8.0


def test_no_estimated_centre_of_resistance_is_off_by_a_whole_root(errors):
    assert max(e.resistance_mm for e in errors) < 5.0

"""The real full jaw (Open-Full-Jaw patient 26, both arches), loaded once per test session.

Loading 31 dense teeth and measuring their scan interpenetration takes tens of seconds; every
real-data test module that needs the whole jaw shares this one load (and the movement model's
sphere trees come from the project's cache)."""

from __future__ import annotations

import warnings
from functools import lru_cache

from orthosim.exchange.openfulljaw import load_open_full_jaw
from orthosim.exchange.shareddata import open_full_jaw_dir

UPPER = [18, 17, 16, 15, 14, 13, 12, 11, 21, 22, 23, 24, 25, 26, 27]
LOWER = [48, 47, 46, 45, 44, 43, 42, 41, 31, 32, 33, 34, 35, 36, 37, 38]


@lru_cache(maxsize=1)
def full_jaw():
    """(dentition, [warning messages]) of both arches loaded from the patient folder."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        dentition = load_open_full_jaw(open_full_jaw_dir("maxilla").parent)
    return dentition, [str(w.message) for w in caught]

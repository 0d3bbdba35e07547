"""Broad phase: neighbours along the arch (extraction spaces skipped), facing teeth of the other
arch, and the sweep-and-prune fallback for bodies that are not an arch."""

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from orthosim.collision.broadphase import arch_neighbour_pairs, candidate_pairs, facing_pairs, sweep_and_prune
from orthosim.model.fdi import ALL_FDI

ADULT_28 = [n for n in ALL_FDI if n % 10 != 8]


def test_teeth_either_side_of_an_extraction_space_become_neighbours():
    pairs = arch_neighbour_pairs(ADULT_28, absent={14, 24})
    assert (13, 15) in pairs or (15, 13) in pairs
    assert (24, 25) not in pairs and (23, 25) in pairs
    assert not any(14 in p for p in pairs)


def test_neighbours_are_the_adjacent_teeth_of_the_same_arch_only():
    pairs = arch_neighbour_pairs(ADULT_28)
    assert len(pairs) == 2 * 13
    assert (11, 21) in pairs and (41, 31) in pairs  # across the midline
    assert all((a // 10 in (1, 2)) == (b // 10 in (1, 2)) for a, b in pairs)


def test_upper_teeth_face_the_lower_teeth_of_class_one_occlusion():
    pairs = facing_pairs(ADULT_28)
    assert (16, 46) in pairs and (16, 47) in pairs  # upper first molar over lower 6 and 7
    assert (13, 43) in pairs and (13, 44) in pairs  # canine over lower canine and first premolar
    assert (11, 41) in pairs and (11, 31) in pairs and (21, 31) in pairs  # incisors across the midline
    assert all(a // 10 in (1, 2) and b // 10 in (3, 4) for a, b in pairs)


def test_a_tooth_whose_opposing_teeth_are_extracted_faces_the_nearest_remaining_one():
    present = [16, 46, 47, 48]
    assert facing_pairs(present, absent={46, 47}) == [(16, 48)]


def test_candidate_pairs_have_no_duplicates():
    pairs = candidate_pairs(ADULT_28)
    assert len({frozenset(p) for p in pairs}) == len(pairs)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 10**6), n=st.integers(0, 40), margin=st.floats(0, 2))
def test_sweep_and_prune_finds_exactly_the_overlapping_spheres(seed, n, margin):
    rng = np.random.default_rng(seed)
    c = rng.uniform(-30, 30, size=(n, 3))
    r = rng.uniform(0.5, 6, size=n)
    got = {tuple(p) for p in sweep_and_prune(c, r, margin)}
    want = {(i, j) for i, j in itertools.combinations(range(n), 2)
            if np.linalg.norm(c[i] - c[j]) <= r[i] + r[j] + 2 * margin}
    assert got == want

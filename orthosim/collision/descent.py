"""Simultaneous descent of two sphere trees, for every candidate pair of a step at once.

The frontier is three parallel arrays (pair, node of tree a, node of tree b), global node indices
of one level (see `CollisionModel`). Each level keeps the node pairs a test accepts, then replaces
every kept node pair by the product of their children: children are contiguous in the next level,
so the expansion is arithmetic on (start, count) arrays. Both trees descend together, one level
per round, so a depth-4 query is four rounds of numpy work whatever the number of pairs.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .model import CollisionModel


def expand_children(model: CollisionModel, level: int, pair: np.ndarray, na: np.ndarray, nb: np.ndarray):
    """Every (child of na, child of nb) of the given level-`level` node pairs, with their pair index."""
    sa, ka = model.child_start[level][na], model.child_count[level][na]
    sb, kb = model.child_start[level][nb], model.child_count[level][nb]
    m = ka * kb
    total = int(m.sum())
    rep = np.repeat(np.arange(len(m)), m)
    j = np.arange(total) - np.repeat(np.cumsum(m) - m, m)
    kbr = kb[rep]
    return pair[rep], sa[rep] + j // kbr, sb[rep] + j % kbr


def descend(model: CollisionModel, pair_idx: np.ndarray, keep: Callable, first_only: bool = False):
    """Run the descent; returns (pair, leaf a, leaf b) global leaf pairs every level's test kept.

    pair_idx: (p, 2) body indices. keep(level, pair, na, nb) -> (f,) bool says which node pairs of
    a level may hold a contact (for leaves: which do). first_only keeps one leaf pair per pair.
    """
    p = len(pair_idx)
    pair = np.arange(p, dtype=np.int64)
    na = model.start[0][pair_idx[:, 0]]
    nb = model.start[0][pair_idx[:, 1]]
    last = model.depth - 1
    for level in range(model.depth):
        ok = keep(level, pair, na, nb)
        pair, na, nb = pair[ok], na[ok], nb[ok]
        if level == last or len(pair) == 0:
            break
        pair, na, nb = expand_children(model, level, pair, na, nb)
    if first_only and len(pair):
        _, first = np.unique(pair, return_index=True)
        pair, na, nb = pair[first], na[first], nb[first]
    return pair, na, nb

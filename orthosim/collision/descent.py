"""Simultaneous descent of two sphere trees, for every candidate pair of a step at once.

The frontier is two parallel arrays (node of tree a, node of tree b) of flat node indices (see
`CollisionModel`), plus the tooth pair of each entry when a body can appear in several pairs with
different poses (`track_pair`). Each round tests every frontier entry with numpy, keeps the node
pairs that may hold a contact, sets aside leaf-leaf pairs as results, and replaces every other
kept entry by the children of its larger sphere (or of the one that is not a leaf) against the
other node: the classic rule that descends the node whose sphere is bigger (it tests about a
third as many node pairs here as expanding both nodes at once). Children are contiguous, so
expansion is arithmetic on (start, count) arrays; a round costs a fixed number of numpy calls
whatever the number of tooth pairs, and a depth-d query takes at most 2 (d - 1) + 1 rounds.
"""

from __future__ import annotations

import sys
from typing import Callable

import numpy as np

from orthosim.collision.model import CollisionModel

_compiled = []  # the descent_compiled module, or None without numba (imported on first use)
# Numpy descents a process makes before the compiled walk pays. Compiling its kernels costs about
# 5 s of CPU once per machine (more on a loaded one): a thousand descents buy that back. Loading
# them from numba's cache still costs numba's import and its typing set-up, 0.77 s of CPU against
# 9-10 ms that the walk saves a descent on the paper's arch at rest (both measured in one process,
# load 6.7, 2026-11-28): about 85 descents buy that back, so the walk waits for a hundred even when
# cached. A short run (the demo's 20 steps make about 45 descents) never imports numba, and none
# waits for it before its first step.
PAYS_AFTER_DESCENTS = 1000
LOADING_PAYS_AFTER_DESCENTS = 100
_numpy_descents = [0]
_in_cache: list[bool] = []  # whether numba's cache held the walk's kernels, asked once a process


def compiled_descent(use: bool | None = True):
    """The `descent_compiled` module (the same results as this module's numpy descent, the
    reference) when numba is installed and `use` asks for it, else None (the numpy descent).

    use: True: the compiled walk (compiled now if this machine has not yet); False: the numpy
    descent; None (the detectors' default), "when it pays": the compiled walk at once when this
    process has its kernels already (compiled or loaded by an earlier `use=True`); else the numpy
    descent for the first LOADING_PAYS_AFTER_DESCENTS descents, then the compiled walk if its
    kernels are in numba's cache, or once this process has made PAYS_AFTER_DESCENTS numpy
    descents. So a short run never waits for numba (its import, its typing set-up, its compiler),
    and a long one compiles once, for itself and every later run. `discrete.overlapping_leaves`
    and `continuous.swept_leaves` take `compiled=` for it."""
    if use is False:
        return None
    if use is None and not _walk_loaded():
        _numpy_descents[0] += 1
        made = _numpy_descents[0]
        if made <= LOADING_PAYS_AFTER_DESCENTS:
            return None
        walk = _walk()
        if walk is None:
            return None
        if not _in_cache:
            _in_cache.append(walk.kernels_ready())
        if not _in_cache[0] and made <= PAYS_AFTER_DESCENTS:
            return None
    return _walk()


def _walk():
    """The descent_compiled module (importing numba), or None without numba."""
    if not _compiled:
        from orthosim.collision import descent_compiled

        _compiled.append(descent_compiled if descent_compiled.AVAILABLE else None)
    return _compiled[0]


def _walk_loaded() -> bool:
    """Whether this process holds the walk's kernels already (without importing numba to ask)."""
    module = sys.modules.get("orthosim.collision.descent_compiled")
    return module is not None and module.AVAILABLE and module.kernels_loaded()


def sphere_overlap_test(model: CollisionModel, flat: np.ndarray, radii: np.ndarray) -> Callable:
    """The descent's `may_touch` for spheres: node pairs with |c_a - c_b|^2 <= (r_a + r_b)^2.

    flat: float32 centres in the [body][axis][j] layout (`CollisionModel.world_centers`); radii:
    float32 per flat node. The compiled descent applies the same test with the same arithmetic.
    """
    X, Y, Z = model.axes(flat)

    def may_touch(pair, na, nb):
        dx = X[na] - X[nb]
        dy = Y[na] - Y[nb]
        dz = Z[na] - Z[nb]
        s = radii[na] + radii[nb]
        return dx * dx + dy * dy + dz * dz <= s * s

    return may_touch


def descend(model: CollisionModel, pair_idx: np.ndarray, may_touch: Callable, at_leaves: Callable | None = None,
            first_only: bool = False, track_pair: bool = False):
    """Run the descent; returns (pair, leaf a, leaf b, payload) of every accepted leaf pair.

    pair_idx: (p, 2) body indices. may_touch(pair, na, nb) -> (f,) bool: which node pairs may hold a
    contact (flat node indices; pair is None unless track_pair). at_leaves(pair, na, nb) -> (ok (f,)
    bool, payload dict of (f,) arrays): a final test of leaf pairs that passed may_touch (None:
    accept them). first_only stops a tooth pair's descent at its first accepted leaf pair (the
    result then holds one per pair, the least payload["t"] when there is one). Without
    track_pair, each body pair must appear at most once in pair_idx.
    """
    p = len(pair_idx)
    na, nb = model.roots(pair_idx[:, 0]), model.roots(pair_idx[:, 1])
    n = len(model.bodies)
    if not track_pair and len(np.unique(pair_idx[:, 0] * n + pair_idx[:, 1])) < p:
        track_pair = True  # a body pair listed twice: entries must carry their pair
    if track_pair:
        pair = np.arange(p, dtype=np.int64)
        lookup = None
    else:
        pair = None
        lookup = np.full(n * n, -1, np.int64)
        lookup[pair_idx[:, 0] * n + pair_idx[:, 1]] = np.arange(p)

    def pair_of(na, nb):
        return pair if track_pair else lookup[(na // model.stride) * n + nb // model.stride]

    found = np.zeros(p, bool)
    out_pair, out_a, out_b, payloads = [], [], [], []
    split_key, child_count, child_start = model.split_key, model.child_count, model.child_start
    while len(na):
        keep = np.flatnonzero(may_touch(pair, na, nb))
        na, nb = na[keep], nb[keep]
        if track_pair:
            pair = pair[keep]
        sa, sb = split_key[na], split_key[nb]  # radius of inner nodes, -1 at leaves
        split_a = sa >= sb  # descend the larger sphere; a leaf (-1) is never split
        parent = np.where(split_a, na, nb)
        count = child_count[parent]  # 0 exactly for leaf-leaf pairs
        leaf = np.flatnonzero(count == 0)
        if len(leaf):
            la, lb = na[leaf], nb[leaf]
            lp = pair[leaf] if track_pair else None
            if at_leaves is not None:
                ok, payload = at_leaves(lp, la, lb)
                la, lb = la[ok], lb[ok]
                lp = lp[ok] if track_pair else None
                payloads.append({k: v[ok] for k, v in payload.items()})
            lp = lp if track_pair else pair_of(la, lb)
            out_pair.append(lp)
            out_a.append(la)
            out_b.append(lb)
            if first_only:
                found[lp] = True
                count[found[pair if track_pair else pair_of(na, nb)]] = 0
        # every kept node pair becomes (child of the split node, the other node), children contiguous
        total = int(count.sum())
        rep = np.repeat(np.arange(len(count)), count)
        child = child_start[parent][rep] + (np.arange(total) - np.repeat(np.cumsum(count) - count, count))
        other = np.where(split_a, nb, na)[rep]
        side = split_a[rep]
        na, nb = np.where(side, child, other), np.where(side, other, child)
        if track_pair:
            pair = pair[rep]
    if not out_pair:
        empty = np.zeros(0, np.int64)
        return empty, empty, empty, {}
    pair, la, lb = np.concatenate(out_pair), np.concatenate(out_a), np.concatenate(out_b)
    payload = {k: np.concatenate([d[k] for d in payloads]) for k in payloads[0]} if payloads else {}
    if first_only and len(pair):
        key = payload.get("t")
        order = np.lexsort((key, pair)) if key is not None else np.argsort(pair, kind="stable")
        first = order[np.unique(pair[order], return_index=True)[1]]
        pair, la, lb = pair[first], la[first], lb[first]
        payload = {k: v[first] for k, v in payload.items()}
    return pair, la, lb, payload

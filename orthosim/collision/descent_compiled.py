"""The sphere-tree descent of `descent`, compiled with numba: one depth-first walk per tooth pair.

`leaf_pairs(model, flat, r, pair_idx, first_only)` returns what `descent.descend` returns for the
sphere test |c_a - c_b|^2 <= (r_a + r_b)^2 on float32 coordinates `flat` (a [body][axis][j] array,
see `CollisionModel.world_centers`) and float32 radii `r`: the same leaf pairs, in the same order,
from the same float32 arithmetic (numba keeps float32 operands float32 and, without fastmath,
neither reorders nor fuses them), chosen by the same "split the larger sphere" rule.

The numpy descent is level-synchronous: its round k holds, pair after pair, the node pairs k
splits below the roots, in the order of their child paths. A depth-first walk that takes children
in order visits each pair's node pairs in that same path order, so sorting the leaf pairs found by
(round, pair), stably, gives the numpy order; with first_only the numpy descent keeps, per pair,
the first leaf pair of its earliest round, which the walk finds as the first leaf pair of least
round (it skips node pairs that could only give later rounds).

Nothing here allocates per node pair: each walk uses one small stack; results grow a buffer.
`AVAILABLE` is False when numba is not installed (the numpy descent is then used); kernels are
compiled with cache=True: the first use on a machine compiles them (about 5 s), later processes
load them (about 0.1 s).
"""

from __future__ import annotations

import numpy as np

try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is optional
    njit = None

AVAILABLE = njit is not None  # `descent.compiled_descent` chooses this walk when True (and asked to)

if AVAILABLE:
    from orthosim.system.firstrun import announce_compiles

    announce_compiles()  # a kernel compiled (not loaded from numba's cache) says so on stderr

    @njit(cache=True, nogil=True)
    def _pack(flat, r, n, w, stride):
        """(n * w, 4) float32 rows x, y, z, r of every node, by compact index g = body * w + j."""
        out = np.empty((n * w, 4), np.float32)
        for i in range(n):
            for j in range(w):
                f = i * stride + j
                g = i * w + j
                out[g, 0] = flat[f]
                out[g, 1] = flat[f + w]
                out[g, 2] = flat[f + 2 * w]
                out[g, 3] = r[f]
        return out

    @njit(cache=True, nogil=True)
    def _swept_bounds(W0, W1, radii, rho, inflate, n, w, stride, margin):
        """One pass of the continuous detector's per-node set-up (see `continuous.swept_leaves`):
        chord midpoints (float32), radii grown by the rotation bound (float64) and the swept
        radii (float32), in the flat [body][axis][j] layout, with numpy's operation order."""
        size = n * stride
        mid = np.empty(size, np.float32)
        R = np.empty(size, np.float64)
        Rs = np.empty(size, np.float32)
        for i in range(n):
            for j in range(stride):
                f = i * stride + j
                d = W1[f] - W0[f]
                mid[f] = np.float32(W0[f] + 0.5 * d)
                R[f] = radii[f] + inflate[i] * rho[f]
                chord = 0.0
                if j < w:
                    dx = W1[f] - W0[f]
                    dy = W1[f + w] - W0[f + w]
                    dz = W1[f + 2 * w] - W0[f + 2 * w]
                    chord = np.sqrt(dx * dx + dy * dy + dz * dz)
                Rs[f] = np.float32(R[f] + 0.5 * chord + margin)
        return mid, R, Rs

    @njit(cache=True, nogil=True)
    def _grow(buf, m):
        """The result buffer at twice its size, its first m rows kept. Copied element by element: a
        slice assignment would compile numba's shape-mismatch error path (string formatting), seconds
        of a cold start for a copy that cannot mismatch."""
        out = np.empty((2 * buf.shape[0], 4), np.int64)
        for i in range(m):
            for j in range(4):
                out[i, j] = buf[i, j]
        return out

    @njit(cache=True, nogil=True)
    def _append(res, m, q, na, nb, k, w, stride):
        """Row m of the result: pair q, leaves na and nb (compact ids, stored flat), round k; the
        buffer, grown when full."""
        if m == res.shape[0]:
            res = _grow(res, m)
        res[m, 0] = q
        res[m, 1] = (na // w) * stride + na % w
        res[m, 2] = (nb // w) * stride + nb % w
        res[m, 3] = k
        return res

    @njit(cache=True, nogil=True)
    def _overlap(node, a, b):
        """Whether nodes a and b overlap: the descent's test, (x_a - x_b)^2 + ... <= (r_a + r_b)^2 in float32."""
        dx = node[a, 0] - node[b, 0]
        dy = node[a, 1] - node[b, 1]
        dz = node[a, 2] - node[b, 2]
        s = node[a, 3] + node[b, 3]
        return dx * dx + dy * dy + dz * dz <= s * s

    @njit(cache=True, nogil=True)
    def _walk(node, split_key, child_start, child_count, roots_a, roots_b, first_only, stack_size, w, stride):
        """Leaf pairs (rows pair, a, b, round) of every pair's walk; node ids are compact (body * w
        + j) inside, flat (body * stride + j) in the result.

        A node pair is tested before it is pushed (children of the split node in one loop against
        the other node), so the stack only ever holds node pairs that passed."""
        p = roots_a.shape[0]
        res = np.empty((1024, 4), np.int64)
        m = 0
        st_a = np.empty(stack_size, np.int64)
        st_b = np.empty(stack_size, np.int64)
        st_k = np.empty(stack_size, np.int64)
        big = np.int64(1) << 62
        for q in range(p):
            a0 = roots_a[q]
            b0 = roots_b[q]
            if not _overlap(node, a0, b0):
                continue
            st_a[0] = a0
            st_b[0] = b0
            st_k[0] = 0
            top = 1
            best_round = big  # first_only: round of the leaf pair kept for this pair
            best_a = -1
            best_b = -1
            while top > 0:
                top -= 1
                na = st_a[top]
                nb = st_b[top]
                k = st_k[top]
                if k >= best_round:
                    continue  # first_only: only later rounds, or later paths of this round, below
                split_a = split_key[na] >= split_key[nb]
                if split_a:
                    parent = na
                    other = nb
                else:
                    parent = nb
                    other = na
                count = child_count[parent]
                if count == 0:
                    if first_only:
                        best_round = k
                        best_a = na
                        best_b = nb
                        continue
                    res = _append(res, m, q, na, nb, k, w, stride)
                    m += 1
                    continue
                if k + 1 >= best_round:
                    continue
                ox = node[other, 0]
                oy = node[other, 1]
                oz = node[other, 2]
                orad = node[other, 3]
                start = child_start[parent]
                # children tested in reverse and pushed, so that they are walked in order; the test
                # is the numpy descent's, (x_a - x_b)^2 + ... <= (r_a + r_b)^2 in float32, whose
                # squares and sums do not depend on which node is a (negation, a + b = b + a: exact)
                for c in range(start + count - 1, start - 1, -1):
                    dx = node[c, 0] - ox
                    dy = node[c, 1] - oy
                    dz = node[c, 2] - oz
                    s = node[c, 3] + orad
                    if dx * dx + dy * dy + dz * dz <= s * s:
                        if split_a:
                            st_a[top] = c
                            st_b[top] = other
                        else:
                            st_a[top] = other
                            st_b[top] = c
                        st_k[top] = k + 1
                        top += 1
            if first_only and best_a >= 0:
                res = _append(res, m, q, best_a, best_b, best_round, w, stride)
                m += 1
        return res[:m]


_KERNELS = (_pack, _swept_bounds, _grow, _append, _overlap, _walk) if AVAILABLE else ()


def kernels_loaded() -> bool:
    """Whether every kernel of the walk is compiled or loaded in this process already (no file read)."""
    return all(kernel.signatures for kernel in _KERNELS)


def kernels_ready() -> bool:
    """Whether the walk runs without compiling: each kernel compiled in this process already, or
    in numba's cache for this source (`orthosim.system.firstrun.in_numba_cache`)."""
    from orthosim.system.firstrun import in_numba_cache

    return in_numba_cache(*_KERNELS)


def _stack_size(model) -> int:
    """Bound on a walk's stack: at most (count - 1) siblings wait per round, plus the one walked."""
    cached = getattr(model, "_compiled_stack_size", None)
    if cached is None:
        rounds = 2 * model.depth + 1
        cached = int(rounds * max(int(model.child_count.max()), 1) + 2)
        model._compiled_stack_size = cached
    return cached


def _model_arrays(model):
    """split_key, child_start, child_count by compact node index (body * width + j), kept on the model."""
    arrays = getattr(model, "_compiled_arrays", None)
    if arrays is None:
        n, w, stride = len(model.bodies), model.width, model.stride
        flat = (np.arange(n)[:, None] * stride + np.arange(w)).reshape(-1)  # compact -> flat index
        cs = model.child_start[flat]
        cs = np.where(model.child_count[flat] > 0, (cs // stride) * w + cs % stride, 0)
        arrays = (np.ascontiguousarray(model.split_key[flat], np.float32), np.ascontiguousarray(cs, np.int64),
                  np.ascontiguousarray(model.child_count[flat], np.int64))
        model._compiled_arrays = arrays
    return arrays


def leaf_pairs(model, flat: np.ndarray, r: np.ndarray, pair_idx: np.ndarray, first_only: bool = False):
    """(pair, leaf a, leaf b) as `descent.descend` returns them for the float32 sphere test of
    coordinates `flat` ([body][axis][j], float32) and radii `r` (flat node index, float32, margin
    included): the same leaf pairs in the same order, as flat node indices."""
    split_key, child_start, child_count = _model_arrays(model)
    n, w, stride = len(model.bodies), model.width, model.stride
    node = _pack(np.ascontiguousarray(flat, np.float32), np.ascontiguousarray(r, np.float32), n, w, stride)
    roots = np.ascontiguousarray(pair_idx, np.int64) * w
    res = _walk(node, split_key, child_start, child_count, np.ascontiguousarray(roots[:, 0]),
                np.ascontiguousarray(roots[:, 1]), bool(first_only), _stack_size(model), w, stride)
    rnd = res[:, 3]
    # the walk gives pair-major order; the numpy descent's is round-major, pair-minor (the same when
    # every leaf pair is found in the same round, as with trees of one depth). first_only: one per
    # pair, in pair order, as numpy's.
    if not first_only and len(rnd) > 1 and rnd.min() != rnd.max():
        res = res[np.lexsort((res[:, 0], rnd))]  # stable
    return res[:, 0].copy(), res[:, 1].copy(), res[:, 2].copy()


def swept_bounds(model, W0: np.ndarray, W1: np.ndarray, inflate: np.ndarray, margin: float):
    """(mid float32, R float64, Rs float32) flat arrays of `continuous.swept_leaves`, compiled.

    inflate: (n_bodies,) mm of radius growth per mm of a node's distance from its body's origin."""
    n = len(model.bodies)
    return _swept_bounds(np.ascontiguousarray(W0, np.float64), np.ascontiguousarray(W1, np.float64),
                         np.ascontiguousarray(model.radii, np.float64), np.ascontiguousarray(model.rho, np.float64),
                         np.ascontiguousarray(inflate, np.float64), n, model.width, model.stride, float(margin))

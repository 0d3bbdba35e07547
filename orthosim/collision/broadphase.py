"""Broad phase: which pairs of teeth a step tests at all.

For a dentition, the paper's rule: neighbours along each arch (extracted teeth skipped, so the teeth
either side of an extraction space become neighbours) and, for occlusion, the teeth of the other
arch that face each other. For any other set of bodies, a general sweep and prune over bounding
spheres along the axis of widest spread.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from orthosim.model.fdi import Arch, arch_of, arch_order, opposing_quadrant, position, quadrant


def arch_neighbour_pairs(present: Iterable[int], absent: Iterable[int] = ()) -> list[tuple[int, int]]:
    """Neighbours along each arch, right to left, skipping `absent` (extracted) teeth."""
    keep = set(present) - set(absent)
    pairs = []
    for arch in (Arch.UPPER, Arch.LOWER):
        order = arch_order(arch, keep)
        pairs += list(zip(order[:-1], order[1:]))
    return pairs


def facing_pairs(present: Iterable[int], absent: Iterable[int] = (), reach: int = 1) -> list[tuple[int, int]]:
    """(upper, lower) teeth facing each other across the occlusal plane.

    An upper tooth at position p (1 central incisor .. 8 third molar) meets the lower teeth of the
    opposing quadrant at positions p - reach .. p + reach (class I occlusion puts it on p and p + 1;
    reach 1 also covers a half-cusp class II or III shift), and the upper central incisors also
    face the lower central incisor across the midline. Where every such lower tooth is absent, the
    nearest present lower tooth of that quadrant faces it instead.
    """
    keep = set(present) - set(absent)
    pairs = []
    for u in sorted(t for t in keep if arch_of(t) is Arch.UPPER):
        q, p = opposing_quadrant(u), position(u)
        lowers = [10 * q + s for s in range(max(1, p - reach), min(8, p + reach) + 1) if 10 * q + s in keep]
        if not lowers:
            quad = sorted((t for t in keep if quadrant(t) == q), key=lambda t: abs(position(t) - p))
            lowers = quad[:1]
        if p == 1:
            other = 10 * (7 - q) + 1  # lower central incisor on the other side of the midline
            if other in keep:
                lowers.append(other)
        pairs += [(u, lo) for lo in lowers]
    return pairs


def candidate_pairs(present: Iterable[int], absent: Iterable[int] = ()) -> list[tuple[int, int]]:
    """All pairs a dentition step tests: arch neighbours, then facing teeth of the other arch."""
    present = list(present)
    return arch_neighbour_pairs(present, absent) + facing_pairs(present, absent)


def sweep_and_prune(centers: np.ndarray, radii: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """(p, 2) int64 index pairs (i < j) of spheres that overlap, for models that are not arches.

    centers: (n, 3) mm bounding-sphere centres (arch frame); radii: (n,) mm; margin: mm added to
    every radius (e.g. the largest displacement of a step, to keep pairs that may meet during it).
    Sorts the intervals along the axis of widest spread, keeps the pairs whose intervals overlap,
    then tests the spheres themselves.
    """
    centers = np.asarray(centers, float)
    r = np.asarray(radii, float) + margin
    n = len(r)
    if n < 2:
        return np.zeros((0, 2), np.int64)
    axis = int(np.argmax(centers.max(axis=0) - centers.min(axis=0)))
    lo, hi = centers[:, axis] - r, centers[:, axis] + r
    order = np.argsort(lo, kind="stable")
    # for each body, the sorted bodies whose interval starts before its interval ends
    end = np.searchsorted(lo[order], hi[order], side="right")
    counts = end - np.arange(n) - 1
    i_sorted = np.repeat(np.arange(n), counts)
    first = np.repeat(np.arange(n) + 1 - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    j_sorted = first + np.arange(counts.sum())
    i, j = order[i_sorted], order[j_sorted]
    d = centers[i] - centers[j]
    hit = np.einsum("ij,ij->i", d, d) <= (r[i] + r[j]) ** 2
    out = np.stack([np.minimum(i, j), np.maximum(i, j)], axis=1)[hit]
    return out[np.lexsort((out[:, 1], out[:, 0]))].astype(np.int64)

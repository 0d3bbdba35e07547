"""Sphere against sphere over one step: the paper's Eq. 2 and the lower bounds used to prune node pairs.

Two spheres whose centres move linearly over the step t in [0, 1] are apart by
A + t B, with A = c1 - c2 and B = (c1' - c1) - (c2' - c2) (mm). They touch when
|A + t B| <= R, R = r1 + r2. The first root of |A + t B|^2 = R^2 is Eq. 2:

    t = (-(A.B) - sqrt((A.B)^2 - |B|^2 (|A|^2 - R^2))) / |B|^2

evaluated here in the algebraically equal, cancellation-free form t = (|A|^2 - R^2) / (-(A.B) + sqrt(...)).
Every function takes (n, 3) arrays A, B (mm) and (n,) R (mm) and works on all n pairs at once.
"""

from __future__ import annotations

import numpy as np


def first_time_of_contact(A: np.ndarray, B: np.ndarray, R: np.ndarray) -> np.ndarray:
    """(n,) first time in [0, 1) at which |A + t B| <= R, NaN where the spheres do not meet in the step.

    Already overlapping at t = 0 gives 0; no relative motion, or motion parallel to the contact
    plane that never closes the gap, gives NaN; touching exactly at t = 1 is outside [0, 1): NaN.
    """
    return contact_interval(A, B, R)[0]


def contact_interval(A: np.ndarray, B: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(enter, leave), each (n,): the times the spheres start and stop overlapping.

    enter is `first_time_of_contact` (NaN when they do not meet in [0, 1)); leave is the second
    root of |A + t B| = R (inf when there is no relative motion), NaN where enter is NaN.
    """
    A = np.asarray(A, float)
    B = np.asarray(B, float)
    R = np.asarray(R, float)
    return contact_interval_from_dots(np.einsum("ij,ij->i", A, A), np.einsum("ij,ij->i", A, B),
                                      np.einsum("ij,ij->i", B, B), R * R)


def contact_interval_from_dots(aa: np.ndarray, ab: np.ndarray, bb: np.ndarray, rr: np.ndarray):
    """`contact_interval` from the dot products |A|^2, A.B, |B|^2 and R^2 (all (n,), mm^2)."""
    gap = aa - rr  # > 0: apart at t = 0
    disc = ab * ab - bb * gap
    root = np.sqrt(np.maximum(disc, 0.0))
    closing = (ab < 0) & (disc >= 0) & (gap > 0)
    # a near-zero denominator (spheres barely closing) gives inf, later read as "no contact in [0, 1)"
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        enter = gap / (-ab + root)  # Eq. 2, cancellation-free
        leave = np.where(bb > 0, (-ab + root) / bb, np.inf)
    enter = np.where(closing & (enter < 1.0), enter, np.nan)
    enter = np.where(gap <= 0, 0.0, enter)
    return enter, np.where(np.isnan(enter), np.nan, leave)


def min_distance_over_step(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """(n,) mm: the exact minimum of |A + t B| over t in [0, 1] (closed form of the quadratic).

    This is the tightest possible lower bound of the centres' distance over the step; the paper's
    interval-arithmetic bound (`interval_lower_bound`) is never larger.
    """
    A = np.asarray(A, float)
    B = np.asarray(B, float)
    ab = np.einsum("ij,ij->i", A, B)
    bb = np.einsum("ij,ij->i", B, B)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(bb > 0, np.clip(-ab / bb, 0.0, 1.0), 0.0)
    d = A + t[:, None] * B
    return np.sqrt(np.einsum("ij,ij->i", d, d))


def interval_lower_bound(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """(n,) mm^2: the paper's interval-arithmetic lower bound of |A + t B|^2 over t in [0, 1].

    Each coordinate A_i + t B_i ranges over the interval [min(A_i, A_i + B_i), max(...)]; its square
    is at least 0 when the interval holds 0, else the smaller endpoint squared. Kept for replication
    and comparison; the detectors use the tighter `min_distance_over_step`.
    """
    A = np.asarray(A, float)
    E = A + np.asarray(B, float)
    lo = np.minimum(A, E)
    hi = np.maximum(A, E)
    sq = np.where((lo <= 0) & (hi >= 0), 0.0, np.minimum(lo * lo, hi * hi))
    return sq.sum(axis=1)

"""Two teeth moving through one aligner stage: their exact distance along the motion, bounded.

Each tooth moves from its pose at one stage to its pose at the next by the motion law the
continuous detector assumes (`orthosim.geometry.motion`: the local origin on a straight line,
rotation at constant angular velocity about it). Every vertex of tooth a then moves at most
|v_a| + theta_a rho_a per unit of stage time (v_a the origin's displacement over the stage,
theta_a the angle turned, rho_a the farthest vertex from the local origin), so the distance
between the two meshes changes at most at mu = |v_a - v_b| + theta_a rho_a + theta_b rho_b mm
per unit time (`relative_speed_bound`). Two answers rest on that bound and on FCL's exact mesh
distance at chosen times:

- `min_clearance`: the least distance over the stage, by branch and bound: on [t0, t1] the
  distance is at least (d(t0) + d(t1) - mu (t1 - t0)) / 2, so intervals whose bound cannot beat
  the best sample by more than the tolerance are dropped. The answer is a sampled distance
  (an upper bound on the true minimum) and a proven lower bound within `tolerance_mm` of it.
- `first_contact_on_grid`: dense sampling for the independent check (`stage verify`): times
  spaced so that no vertex moves more than `step_mm` relative to the other tooth between two
  samples, each sample either tested with FCL's intersection test or proven apart by an FCL
  distance at an earlier sample (d > mu (t' - t)). An intersection deeper than step_mm / 2 at
  any time lies within step_mm / 2 of a sample's relative pose, so it is found there.

Both are algorithms of their own (the verifier's dense grid is independent of the planner's
advancement), asking their exact questions (intersection at a pose, distance at a pose) of the
collision package's `ExactQueries` over the teeth's meshes alone, not of FCL directly.

Units: mm, poses (4, 4) local -> arch frame; times are fractions 0..1 of the stage.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from orthosim.collision.queries import ExactQueries
from orthosim.geometry.motion import PosePath, chord_deviation_bound, relative_speed_bound, rotation_angle


@dataclass(frozen=True)
class Clearance:
    """The least distance (mm) between two teeth over a stage's motion."""

    min_mm: float  # smallest sampled distance (0.0: the meshes intersect at `time`)
    lower_bound_mm: float  # proven: the distance never falls below this during the stage
    time: float  # fraction 0..1 of the stage where min_mm was found
    samples: int  # FCL queries made


class PairMotion:
    """Teeth a and b over one stage: bodies i and j of the staged teeth's `ExactQueries` (which
    answer every exact question: FCL on the placed meshes, remembered), the farthest vertex of
    each from its local origin (mm, `rho_max`), and both motions (4, 4) T0 -> T1.

    At t = 0 and t = 1 the end poses themselves are used (bit for bit, not re-interpolated), so
    the queries' memo (kept across stages, keyed by the bodies and the two poses' bytes) answers
    again what a stage's end asked: a stage's end is the next one's start, and teeth at rest keep
    their poses. `queries` counts the FCL queries made for this motion (remembered answers and
    intersection tests that an earlier distance proves false cost none)."""

    def __init__(self, exact: ExactQueries, i: int, Ta0, Ta1, j: int, Tb0, Tb1):
        self.exact, self.i, self.j = exact, i, j
        self.path_a, self.path_b = PosePath(Ta0, Ta1), PosePath(Tb0, Tb1)
        rho = exact.model.rho_max
        self.mu = relative_speed_bound(Ta0, Ta1, rho[i], Tb0, Tb1, rho[j])  # mm per unit stage time
        self.queries = 0

    def _poses(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if t == 1.0:
            return self.path_a.T1, self.path_b.T1
        return self.path_a.at(t), self.path_b.at(t)

    def _ask(self, question, t: float):
        """One exact question (an `ExactQueries` method of two bodies' poses) at time t, its FCL calls counted."""
        before = self.exact.fcl_calls
        Ta, Tb = self._poses(t)
        answer = question(self.i, Ta, self.j, Tb)
        self.queries += self.exact.fcl_calls - before
        return answer

    def intersects(self, t: float) -> bool:
        return self._ask(self.exact.body_intersects, t)

    def distance(self, t: float) -> float:
        """mm between the meshes at time t (0.0 when they intersect)."""
        return self._ask(self.exact.body_distance, t)


def min_clearance(motion: PairMotion, tolerance_mm: float = 1e-3, reach_mm: float = math.inf) -> Clearance:
    """The least distance over the stage to within `tolerance_mm` (see the module docstring).

    reach_mm: stop as soon as the pair is proven never to come within this distance (the
    answer's lower bound then exceeds reach_mm, and min_mm is the best sample so far).
    """
    d0 = motion.distance(0.0)
    mu = motion.mu
    if mu <= 0.0:  # no relative motion: the distance is constant
        return Clearance(d0, d0, 0.0, motion.queries)
    d1 = motion.distance(1.0)
    best, best_t = (d0, 0.0) if d0 <= d1 else (d1, 1.0)
    heap = [(0.5 * (d0 + d1 - mu), 0.0, 1.0, d0, d1)]
    lower = heap[0][0]
    while heap:
        lb, a, b, da, db = heapq.heappop(heap)
        lower = lb
        if best == 0.0 or lb >= best - tolerance_mm or lb > reach_mm:
            break
        m = 0.5 * (a + b)
        dm = motion.distance(m)
        if dm < best:
            best, best_t = dm, m
        for lo, hi, dlo, dhi in ((a, m, da, dm), (m, b, dm, db)):
            heapq.heappush(heap, (0.5 * (dlo + dhi - mu * (hi - lo)), lo, hi, dlo, dhi))
    else:
        lower = best
    lower = 0.0 if best == 0.0 else min(best, max(lower, 0.0))
    return Clearance(best, lower, best_t, motion.queries)


def grid_size(mu_mm: float, step_mm: float) -> int:
    """Intervals of the sampling grid: the fewest with no vertex moving more than step_mm relative
    to the other tooth between two samples (at least 1)."""
    return max(1, math.ceil(mu_mm / step_mm))


def first_contact_on_grid(motion: PairMotion, step_mm: float) -> float | None:
    """The first sampled time (0..1) at which the meshes intersect, or None; every sample of the
    grid `grid_size(mu, step_mm)` is tested or proven apart (see the module docstring)."""
    n = grid_size(motion.mu, step_mm)
    i = 0
    while i <= n:
        t = i / n
        if motion.intersects(t):
            return t
        if i == n or motion.mu <= 0.0:
            return None
        d = motion.distance(t)
        # samples i + j with j * mu / n < d are proven apart by this distance
        i += max(1, math.ceil(d * n / motion.mu))
    return None


def closest_approach(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> float:
    """mm: the least distance between two points moving on straight lines at constant speed over
    the stage, a0 -> a1 and b0 -> b1 ((3,) mm each), at the same times."""
    d0 = np.asarray(a0, float) - np.asarray(b0, float)
    d1 = np.asarray(a1, float) - np.asarray(b1, float)
    v = d1 - d0
    vv = float(v @ v)
    t = 0.0 if vv == 0.0 else min(1.0, max(0.0, -float(d0 @ v) / vv))
    return float(np.linalg.norm(d0 + t * v))


MEMO_SIZE = 1 << 16  # exact answers remembered: every stage end of a staging (see PairMotion)


class ToothBodies:
    """The staged teeth as exact bodies: their meshes' `ExactQueries` (no sphere trees: this is
    the certificate's and the independent verifier's view, built from meshes alone) and each
    tooth's bounding sphere, for any pair's motion over any stage. Where interproximal reduction
    is planned, the meshes given are the reduced teeth (`staging.reduction`).
    """

    def __init__(self, meshes: dict):
        # whole meshes, no patches: samples across a stage move a pair too far for patches to last
        self.queries = ExactQueries.of_meshes(meshes, memo_size=MEMO_SIZE, patch_reach_mm=0.0)
        self.index = self.queries.model.index  # FDI -> body index of the queries
        # a bounding sphere per tooth about its box centre (local frame), for the pair filter
        self.centre = {n: np.asarray(m.bounds, float).mean(axis=0) for n, m in meshes.items()}
        self.radius = {n: float(np.linalg.norm(np.asarray(m.vertices, float) - self.centre[n], axis=1).max())
                       for n, m in meshes.items()}

    def motion(self, a: int, b: int, P0: dict, P1: dict) -> PairMotion:
        """Teeth a and b moving from poses P0 to P1 (FDI -> (4, 4))."""
        Ta0, Ta1, Tb0, Tb1 = (np.array(T, float) for T in (P0[a], P1[a], P0[b], P1[b]))
        return PairMotion(self.queries, self.index[a], Ta0, Ta1, self.index[b], Tb0, Tb1)

    def near_pairs(self, P0: dict, P1: dict, reach_mm: float) -> list[tuple[int, int]]:
        """(a, b) with a < b of every pair that may come within reach_mm of each other during the
        motion P0 -> P1 (FDI -> (4, 4)). Each tooth's bounding-sphere centre strays from its chord
        by at most `chord_deviation_bound` (`geometry.motion`), so a pair whose chords never come
        within the two radii, both deviations and reach_mm of each other cannot."""
        teeth = sorted(self.index)
        ends, slack = {}, {}
        for n in teeth:
            T0, T1 = np.asarray(P0[n], float), np.asarray(P1[n], float)
            c = self.centre[n]
            ends[n] = (T0[:3, :3] @ c + T0[:3, 3], T1[:3, :3] @ c + T1[:3, 3])
            slack[n] = self.radius[n] + float(chord_deviation_bound(rotation_angle(T0, T1), np.linalg.norm(c)))
        out = []
        for i, a in enumerate(teeth):
            for b in teeth[i + 1:]:
                if closest_approach(*ends[a], *ends[b]) <= slack[a] + slack[b] + reach_mm:
                    out.append((a, b))
        return out

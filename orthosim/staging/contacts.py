"""Whether one stage's motion brings any two teeth into contact: the planner's collision check.

A stage moves every tooth from its pose at the previous stage to its pose at this one with the
motion the continuous detector assumes (`orthosim.geometry.motion`). Every pair of teeth that may
meet is tested, crowns and roots, same arch and opposing arch:
  1. broad phase: each tooth's root bounding sphere grown by its sweep (sweep and prune), so any
     two teeth can be paired, not only arch neighbours;
  2. the continuous sphere-tree detector (`continuous.swept_leaves_posed`): a conservative first
     time of contact, or proof that the pair stays apart;
  3. exact meshes from that time on (python-fcl): conservative advancement, each stride the FCL
     distance over the bound on relative speed, never shorter than `tolerance_mm` of closing.
A pair is in contact when FCL finds the meshes intersecting at some time of the stage; a contact
shallower than `tolerance_mm` could slip between two strides, which is the check's resolution.

Pairs with interproximal reduction are tested with their two teeth moved apart along the contact
direction by the reduction (see `orthosim.staging.ipr`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from orthosim.collision.broadphase import sweep_and_prune
from orthosim.collision.continuous import swept_leaves_posed
from orthosim.collision.model import CollisionModel
from orthosim.geometry.motion import PosePath, chord_deviation_bound, relative_speed_bound, rotation_angle
from orthosim.collision.queries import ExactQueries

TOLERANCE_MM = 0.002  # resolution of the exact check (see the module docstring)


@dataclass(frozen=True)
class Contact:
    """Teeth `a` and `b` (FDI) touch at `time` (fraction 0..1 of the stage's motion)."""

    a: int
    b: int
    time: float


class StageChecker:
    """Contact checks of stage motions over one collision model (the teeth that take part).

    shifts: (FDI a, FDI b) -> ((3,) mm, (3,) mm) arch-frame offsets added to a's and b's positions
    when that pair (and only that pair) is tested: how interproximal reduction is modelled.
    """

    def __init__(self, model: CollisionModel, shifts: Mapping[tuple[int, int], tuple[np.ndarray, np.ndarray]] | None = None,
                 tolerance_mm: float = TOLERANCE_MM):
        self.model = model
        self.keys = model.keys
        self.tolerance_mm = tolerance_mm
        self.shifts = {}
        for (a, b), (sa, sb) in (shifts or {}).items():
            self.shifts[(a, b)] = (np.asarray(sa, float), np.asarray(sb, float))
            self.shifts[(b, a)] = (np.asarray(sb, float), np.asarray(sa, float))
        self.queries = ExactQueries(model, memo_size=8192)
        self.fcl_queries = 0

    def pose_array(self, poses: Mapping[int, np.ndarray]) -> np.ndarray:
        return self.model.pose_array(poses)

    def candidate_pairs(self, P0: np.ndarray, P1: np.ndarray, moving_only: bool = True) -> np.ndarray:
        """(p, 2) body index pairs whose swept bounding spheres overlap (and, with moving_only, of
        which at least one tooth moves relative to the other)."""
        m = self.model
        n = len(self.keys)
        roots = m.roots(np.arange(n))
        c0 = m.xyz(m.world_centers(P0), roots)
        c1 = m.xyz(m.world_centers(P1), roots)
        shift = max((float(np.linalg.norm(s[0])) for s in self.shifts.values()), default=0.0)
        r = (m.radii[roots] + 0.5 * np.linalg.norm(c1 - c0, axis=1)
             + chord_deviation_bound(rotation_angle(P0, P1), m.rho[roots]) + shift + 0.01)
        pairs = sweep_and_prune(0.5 * (c0 + c1), r)
        if moving_only and len(pairs):
            moved = np.any(np.abs(P1 - P0) > 0, axis=(1, 2))
            pairs = pairs[moved[pairs[:, 0]] | moved[pairs[:, 1]]]
        return pairs

    def contacts(self, poses0: Mapping[int, np.ndarray] | np.ndarray, poses1: Mapping[int, np.ndarray] | np.ndarray,
                 pairs: Sequence[tuple[int, int]] | None = None) -> list[Contact]:
        """Every pair of teeth in contact during the motion poses0 -> poses1 (FDI -> (4, 4), or
        (n, 4, 4) arrays in model order); `pairs` (FDI) restricts the test. poses0 == poses1 tests
        one set of poses (every pair intersecting there)."""
        P0 = poses0 if isinstance(poses0, np.ndarray) else self.pose_array(poses0)
        P1 = poses1 if isinstance(poses1, np.ndarray) else self.pose_array(poses1)
        static = bool(np.array_equal(P0, P1))
        if pairs is None:
            idx = self.candidate_pairs(P0, P1, moving_only=not static)
        else:
            idx = self.model.pair_indices(pairs)
        if len(idx) == 0:
            return []
        keys = self.keys
        Ta0, Ta1, Tb0, Tb1 = P0[idx[:, 0]].copy(), P1[idx[:, 0]].copy(), P0[idx[:, 1]].copy(), P1[idx[:, 1]].copy()
        for k, (i, j) in enumerate(idx):
            s = self.shifts.get((keys[i], keys[j]))
            if s is not None:
                for T in (Ta0, Ta1):
                    T[k, :3, 3] += s[0]
                for T in (Tb0, Tb1):
                    T[k, :3, 3] += s[1]
        pair, _, _, t, _ = swept_leaves_posed(self.model, idx, Ta0, Ta1, Tb0, Tb1, first_only=True)
        found = []
        for p, t0 in zip(pair, t):
            i, j = idx[p]
            hit = self._exact_first_contact(int(i), int(j), Ta0[p], Ta1[p], Tb0[p], Tb1[p], float(t0))
            if hit is not None:
                a, b = keys[i], keys[j]
                found.append(Contact(min(a, b), max(a, b), hit))
        return sorted(found, key=lambda c: (c.time, c.a, c.b))

    def _exact_first_contact(self, i: int, j: int, Ta0, Ta1, Tb0, Tb1, t_start: float) -> float | None:
        """Time in [t_start, 1] at which FCL finds the two meshes intersecting, or None.

        Why not `continuous.refine_time_of_contact`: that one reports a contact conservatively
        whenever the meshes end a step within its travel tolerance of each other, and aligner
        stages end with neighbours in contact within hundredths of a millimetre by design. Here
        contact means intersecting meshes, and strides never shrink below the check's resolution.
        """
        m = self.model
        path_a, path_b = PosePath(Ta0, Ta1), PosePath(Tb0, Tb1)
        mu = relative_speed_bound(Ta0, Ta1, m.rho_max[i], Tb0, Tb1, m.rho_max[j])
        t = t_start
        while True:
            pa, pb = path_a.at(t), path_b.at(t)
            self.fcl_queries += 1
            if self.queries.body_intersects(i, pa, j, pb):
                return t
            if t >= 1.0 or mu <= 0.0:
                return None
            d = self.queries.body_distance(i, pa, j, pb)
            t = min(1.0, t + max(d, self.tolerance_mm) / mu)

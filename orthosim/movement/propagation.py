"""Forces passed on between touching teeth: the paper's "part of its force passes to the tooth it hit".

For every pair of touching teeth (i, j), n_ij is the unit vector from i toward j: between the crown
centres in the occlusal (x-z) plane for neighbours along an arch, and vertical for upper-versus-lower
(occlusal) contacts, which only stop and pass on vertical movement. When the force on i pushes into
j (F_i . n_ij > 0), j receives the share s of that component along n_ij and i is blocked in that
direction: it stops. The force j receives points along the arch, from j toward its own next tooth (the
paper's director vector: the pushed tooth moves toward its next tooth, as a loaded one does); for
occlusal contacts it stays vertical. What j receives adds to its own force and may be passed on again, down the arch, while
the force on the passing tooth is still enough to move it (above the rate law's threshold). The
fixed point is found by iteration; it exists because s < 1 (forces decay geometrically along a
chain). Two chains pushing toward each other meet with opposite forces and block each other, which
is what keeps the incisors in place when both sides of an arch are loaded.

Forces in cN, arch frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from orthosim.mechanics.vec import length


@dataclass(frozen=True, eq=False)
class ForceBalance:
    """The forces of one step (cN, arch frame), per tooth FDI.

    applied: the user's loads; received: passed on by touching teeth; total = applied + received;
    free: what moves the tooth: its total force, or nothing when it pushes into a touching tooth.
    blocked_by: tooth -> the teeth it pushes into (and so cannot move toward).
    passed: (from, to) -> the force vector (cN) passed on.
    """

    applied: dict[int, np.ndarray]
    received: dict[int, np.ndarray]
    total: dict[int, np.ndarray]
    free: dict[int, np.ndarray]
    blocked_by: dict[int, list[int]]
    passed: dict[tuple[int, int], np.ndarray]


def propagate(applied: Mapping[int, np.ndarray], contacts: Sequence[tuple[int, int, np.ndarray]], share: float,
              can_pass: Callable[[int, float], bool], onward: Mapping[tuple[int, int], np.ndarray] | None = None,
              iterations: int = 200, tol_cN: float = 1e-6) -> ForceBalance:
    """Pass forces through touching teeth to a fixed point (see the module text).

    applied: FDI -> (3,) cN. contacts: (i, j, n_ij) for each touching pair, n_ij (3,) unit from i to j
    (the pair need not be listed both ways). share: fraction (0..1) of the pushing component passed
    on. can_pass(fdi, |F| cN): whether a tooth under this force passes any of it on.
    onward: (i, j) -> (3,) unit direction of the force j receives when i pushes it (the paper's
    director vector of j toward its own next tooth); n_ij where not given.
    """
    if not 0.0 <= share < 1.0:
        raise ValueError("share must be in [0, 1)")
    edges = []
    for i, j, n in contacts:
        n = np.asarray(n, float)
        edges += [(i, j, n), (j, i, -n)]
    teeth = list(set(applied) | {e[0] for e in edges} | {e[1] for e in edges})
    row = {t: k for k, t in enumerate(teeth)}
    zero = np.zeros(3)
    app = {t: np.asarray(applied.get(t, zero), float) for t in teeth}
    # per edge: source row, target row, n_ij, the direction of the force passed on
    flow = [(row[i], row[j], n, n if onward is None else np.asarray(onward.get((i, j), n), float), i, j)
            for i, j, n in edges]
    A = np.array([app[t] for t in teeth]).reshape(-1, 3)
    src = np.array([e[0] for e in flow], dtype=np.int64)
    normals = np.array([e[2] for e in flow]).reshape(-1, 3, 1)

    def pushing(total: np.ndarray) -> np.ndarray:
        """(edges,) total[i] @ n_ij of every edge: a stack of 1x3 by 3x1 products, which numpy
        computes with the very dot product `total[i] @ n_ij` is, one edge at a time."""
        return (total[src][:, None, :] @ normals).reshape(-1)

    received = np.zeros_like(A)
    passed: dict[tuple[int, int], np.ndarray] = {}
    for _ in range(iterations):
        total = A + received
        new = np.zeros_like(A)
        passed = {}
        passes: dict[int, bool] = {}  # can_pass per tooth at this iteration's totals
        push = pushing(total).tolist()
        for (a, b, n, d, i, j), c in zip(flow, push):
            if c <= 0:
                continue
            ok = passes.get(a)
            if ok is None:
                ok = passes[a] = can_pass(i, length(total[a]))
            if ok:
                passed[(i, j)] = share * c * d
                new[b] += passed[(i, j)]
        delta = float(np.abs(new - received).max()) if len(teeth) else 0.0
        received = new
        if delta < tol_cN:
            break
    total = A + received
    free, blocked_by = {}, {}
    pushes: dict[int, list[int]] = {}
    for (a, _, n, _, i, j), c in zip(flow, pushing(total).tolist()):
        if c > 0:
            pushes.setdefault(i, []).append(j)
    for t in teeth:
        # the paper: on a collision the moving tooth stops (sideways remainders of forces that meet
        # along a curved arch would otherwise slide it out of the arch)
        k = row[t]
        free[t] = np.zeros(3) if t in pushes else total[k].copy()
        if t in pushes:
            blocked_by[t] = pushes[t]
    return ForceBalance(app, {t: received[row[t]].copy() for t in teeth}, {t: total[row[t]].copy() for t in teeth},
                        free, blocked_by, passed)

"""Detector 3, continuous sphere trees: whether, and when first, two teeth touch during a step.

Motion between the step's end poses is the one defined in `motion` (linear translation, constant
angular velocity about the local origin). Each node centre is followed along its chord, its
radius inflated by the centre's largest deviation from that chord (`motion.chord_deviation_bound`).
A node pair is pruned when a lower bound of the chord distance |A + t B| over [0, 1] exceeds the
sum of the inflated radii; at leaf pairs Eq. 2 gives the first time of contact of the inflated
spheres. The least such time of a tooth pair is never later than the meshes' own first contact.

`refine_time_of_contact` then optionally advances that time on the exact meshes by conservative
advancement: at time t with mesh distance d, no point can close the gap faster than the bound mu
on relative speed, so [t, t + d / mu] is contact-free. What stops it is the caller's meaning of
contact (`contract.CollisionRequest.contact`): the simulator's, an exact test finding contact
within `tolerance` mm of travel after t; the staging planner's, the meshes intersecting, with
strides never shorter than `tolerance` mm of closing.
"""

from __future__ import annotations

import math

import numpy as np

from orthosim.collision.descent import compiled_descent, descend, sphere_overlap_test
from orthosim.collision.contract import INTERSECTING, WITHIN_TOLERANCE
from orthosim.collision.model import FLOAT32_MARGIN_MM, CollisionModel
from orthosim.geometry.motion import PosePath, chord_deviation_bound, max_speed, relative_speed_bound, rotation_angle
from orthosim.collision.queries import ExactQueries
from orthosim.collision.time_of_contact import contact_interval, contact_interval_from_dots, min_distance_over_step


def swept_leaves(model: CollisionModel, poses0: np.ndarray, poses1: np.ndarray, pair_idx: np.ndarray, first_only: bool = False,
                 world0: np.ndarray | None = None, world1: np.ndarray | None = None, compiled: bool | None = None):
    """(pair, node a, node b, t, leave): leaf pairs that may touch in the step, Eq. 2's first time.

    poses0, poses1: (n, 4, 4) poses at t = 0 and t = 1 in model body order; pair_idx (p, 2).
    t: (m,) in [0, 1), never later than the first contact of the leaves' contents; leave: (m,)
    when the (inflated) spheres stop overlapping along their chords. world0, world1:
    `model.world_centers` of poses0, poses1 when the caller has them already. compiled: the
    compiled descent when numba is installed (the same results), False for the numpy descent, None
    (default) once loading or compiling it pays (`descent.compiled_descent`).

    Every node is placed at both ends by two batched matrix products (arch frame). Node pairs are
    pruned with the swept-sphere bound: a node's chord lies in the sphere about its midpoint M of
    radius |D| / 2 (D the chord), so min_t |A + t B| >= |M_a - M_b| - (|D_a| + |D_b|) / 2, a lower
    bound like the paper's interval arithmetic, tested on float32 arrays as in `discrete`. Leaf
    pairs that pass get the exact closed-form test and Eq. 2 in float64.
    """
    W0 = model.world_centers(poses0) if world0 is None else world0  # [body][axis][j]
    W1 = model.world_centers(poses1) if world1 is None else world1
    D = W1 - W0  # chord of every node centre
    per_body = chord_deviation_bound(rotation_angle(poses0, poses1), 1.0)
    walk = compiled_descent(compiled)
    if walk is not None:  # the same arrays in one compiled pass (a third of this detector's set-up time)
        mid, R, Rs = walk.swept_bounds(model, W0, W1, per_body, FLOAT32_MARGIN_MM)
    else:
        R = model.radii + np.repeat(per_body, model.stride) * model.rho  # grown by the centre's chord deviation
        mid = (W0 + 0.5 * D).astype(np.float32)
        chord = np.sqrt(np.einsum("naj,naj->nj", *(2 * [D.reshape(len(model.bodies), 3, model.width)])))
        Rs = (R + 0.5 * model.node_values(chord) + FLOAT32_MARGIN_MM).astype(np.float32)
    x0, y0, z0 = model.axes(W0)
    dx, dy, dz = model.axes(D)

    def at_leaves(pair, na, nb):
        ax, ay, az = x0[na] - x0[nb], y0[na] - y0[nb], z0[na] - z0[nb]
        bx, by, bz = dx[na] - dx[nb], dy[na] - dy[nb], dz[na] - dz[nb]
        rr = R[na] + R[nb]
        enter, leave = contact_interval_from_dots(ax * ax + ay * ay + az * az, ax * bx + ay * by + az * bz,
                                                  bx * bx + by * by + bz * bz, rr * rr)
        ok = ~np.isnan(enter)
        return ok, {"t": enter, "leave": leave}

    if walk is not None:
        # the same leaf pairs pass the same prune, in the same order; Eq. 2 then runs on them all at once
        pair, la, lb = walk.leaf_pairs(model, mid, Rs, pair_idx)
        ok, payload = at_leaves(None, la, lb)
        pair, la, lb = pair[ok], la[ok], lb[ok]
        payload = {k: v[ok] for k, v in payload.items()}
    else:
        pair, la, lb, payload = descend(model, pair_idx, sphere_overlap_test(model, mid, Rs), at_leaves)
    return _earliest(pair, la, lb, payload.get("t", np.zeros(0)), payload.get("leave", np.zeros(0)), first_only)


def swept_leaves_posed(model: CollisionModel, pair_idx: np.ndarray, Ta0, Ta1, Tb0, Tb1, first_only: bool = False):
    """As `swept_leaves`, with each pair's own end poses (p, 4, 4) for its tooth a and tooth b.

    All chords are taken in tooth a's frame at t = 0 (an affine image of the arch-frame chords).
    """
    inv_a0 = np.linalg.inv(Ta0)
    M_a1 = inv_a0 @ Ta1  # a at t = 1, seen from a at t = 0
    M_b0 = inv_a0 @ Tb0
    M_b1 = inv_a0 @ Tb1
    wa = chord_deviation_bound(rotation_angle(Ta0, Ta1), 1.0)  # mm of deviation per mm of |centre|
    wb = chord_deviation_bound(rotation_angle(Tb0, Tb1), 1.0)
    C = model.centers_flat

    def chords(pair, na, nb):
        ca, cb = C[na], C[nb]
        ca1 = np.einsum("fij,fj->fi", M_a1[pair, :3, :3], ca) + M_a1[pair, :3, 3]
        cb0 = np.einsum("fij,fj->fi", M_b0[pair, :3, :3], cb) + M_b0[pair, :3, 3]
        cb1 = np.einsum("fij,fj->fi", M_b1[pair, :3, :3], cb) + M_b1[pair, :3, 3]
        R = model.radii[na] + model.radii[nb] + wa[pair] * model.rho[na] + wb[pair] * model.rho[nb]
        return ca - cb0, (ca1 - ca) - (cb1 - cb0), R

    return _sweep(model, pair_idx, chords, first_only, track_pair=True)


def _sweep(model, pair_idx, chords, first_only, track_pair=False):
    def may_touch(pair, na, nb):
        A, B, R = chords(pair, na, nb)
        return min_distance_over_step(A, B) <= R

    def at_leaves(pair, na, nb):
        enter, leave = contact_interval(*chords(pair, na, nb))
        ok = ~np.isnan(enter)
        return ok, {"t": enter, "leave": leave}

    pair, la, lb, payload = descend(model, pair_idx, may_touch, at_leaves, track_pair=track_pair)
    return _earliest(pair, la, lb, payload.get("t", np.zeros(0)), payload.get("leave", np.zeros(0)), first_only)


def _earliest(pair, la, lb, t, leave, first_only):
    """With first_only, the leaf pair of least time of each tooth pair. The descent itself must not
    stop at a pair's first leaf pair here: a later-found leaf pair may touch earlier."""
    if not first_only or len(pair) == 0:
        return pair, la, lb, t, leave
    order = np.lexsort((t, pair))
    first = order[np.unique(pair[order], return_index=True)[1]]
    return pair[first], la[first], lb[first], t[first], leave[first]


def refine_time_of_contact(model: CollisionModel, i_a: int, i_b: int, T0a, T1a, T0b, T1b, t_start: float,
                           tolerance: float = 0.05, max_iterations: int = 2000,
                           queries: ExactQueries | None = None, contact: str = WITHIN_TOLERANCE) -> float | None:
    """Advance a conservative first time of contact on the exact meshes of bodies i_a, i_b.

    contact = WITHIN_TOLERANCE (the simulator's): returns a time in [t_start, 1) no later than the
    meshes' first contact (up to FCL's own accuracy), within `tolerance` mm of travel of it
    whenever it returns before `max_iterations`; None when conservative advancement proves the
    meshes stay apart until t = 1. Meshes that end the step within the tolerance of each other
    count as in contact where the speed bound cannot prove them apart (a turning tooth's bound is
    loose): reported conservatively, which is what a step cut back to it wants.

    contact = INTERSECTING (the staging planner's): returns the first time in [t_start, 1] at
    which FCL finds the meshes intersecting, each stride the distance over the speed bound but
    never shorter than `tolerance` mm of closing; None when none is found. Aligner stages end with
    neighbours within hundredths of a millimetre by design: that is no contact here, and a contact
    shallower than `tolerance` can slip between two strides (the query's resolution). The strides'
    floor bounds the iterations, so `max_iterations` is raised to what it allows.

    `queries`: the run's `ExactQueries` of this model (a refinement from t = 0 often asks what the
    caller asked already about the step's start poses: the same answers, fewer FCL queries); one
    is made for this call when None.
    """
    if queries is None:
        queries = ExactQueries(model, memo_size=16)
    # Strides use the bound on how fast the gap can close (relative motion); the tolerance is
    # travel of the teeth themselves, so teeth moving together are still stopped precisely.
    angles = rotation_angle(T0a, T1a), rotation_angle(T0b, T1b)
    mu = relative_speed_bound(T0a, T1a, model.rho_max[i_a], T0b, T1b, model.rho_max[i_b], angles)
    path_a, path_b = PosePath(T0a, T1a), PosePath(T0b, T1b)

    def collide_at(t) -> bool:
        return queries.body_intersects(i_a, path_a.at(t), i_b, path_b.at(t))

    t = float(t_start)
    if mu <= 0:
        return t if collide_at(t) else None
    intersecting = contact == INTERSECTING
    if intersecting:
        max_iterations = max(max_iterations, math.ceil(mu / tolerance) + 2)
    else:
        travel = max_speed(T0a, T1a, model.rho_max[i_a], angles[0]) + max_speed(T0b, T1b, model.rho_max[i_b], angles[1])
    for _ in range(max_iterations):
        if intersecting and collide_at(t):
            return t
        if t >= 1.0:
            return None
        d = queries.body_distance(i_a, path_a.at(t), i_b, path_b.at(t))
        if d <= 0.0:
            return t
        if intersecting:  # on to the next stride, t = 1 (the end poses) tested last
            t = min(1.0, t + max(d, tolerance) / mu)
            continue
        if t + d / mu >= 1.0:  # the gap cannot close within the step: no contact, by the speed bound
            return None
        if d <= tolerance:
            t_probe = t + tolerance / travel
            if t_probe >= 1.0:
                return t  # contact, if any, lies within tolerance of travel: report conservatively
            if collide_at(t_probe):
                return t
        t += d / mu
    return t

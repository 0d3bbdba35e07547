"""Detector 3, continuous sphere trees: whether, and when first, two teeth touch during a step.

Motion between the step's end poses is the one defined in `motion` (linear translation, constant
angular velocity about the local origin). All node centres are expressed in tooth a's frame at
t = 0, where their chords are affine images of the world chords. A node pair is pruned when the
exact minimum over [0, 1] of the chord distance |A + t B| exceeds the sum of the radii, each
inflated by its centre's largest deviation from its chord (`motion.chord_deviation_bound`); at
leaf pairs Eq. 2 gives the first time of contact of the inflated spheres. The least such time of
a tooth pair is never later than the meshes' own first contact.

`refine_time_of_contact` then optionally advances that time on the exact meshes by conservative
advancement: at time t with mesh distance d, no point can close the gap faster than the bound mu
on relative speed, so [t, t + d / mu] is contact-free; it stops when an exact test finds contact
within `tolerance` mm of travel after t.
"""

from __future__ import annotations

import numpy as np

from . import exact
from .descent import descend
from .model import CollisionModel
from .motion import chord_deviation_bound, interpolate_pose, max_speed, rotation_angle
from .time_of_contact import contact_interval, min_distance_over_step


def swept_leaves(model: CollisionModel, poses0: np.ndarray, poses1: np.ndarray, pair_idx: np.ndarray, first_only: bool = False):
    """(pair, leaf a, leaf b, t, leave): leaf pairs that may touch in the step, Eq. 2's first time.

    poses0, poses1: (n, 4, 4) poses at t = 0 and t = 1 in model body order; pair_idx (p, 2).
    t: (m,) in [0, 1), never later than the first contact of the leaves' contents; leave: (m,)
    when the (inflated) spheres stop overlapping along their chords.
    """
    ia, ib = pair_idx[:, 0], pair_idx[:, 1]
    return swept_leaves_posed(model, pair_idx, poses0[ia], poses1[ia], poses0[ib], poses1[ib], first_only)


def swept_leaves_posed(model: CollisionModel, pair_idx: np.ndarray, Ta0, Ta1, Tb0, Tb1, first_only: bool = False):
    """As `swept_leaves`, with each pair's own end poses (p, 4, 4) for its tooth a and tooth b."""
    inv_a0 = np.linalg.inv(Ta0)
    M_a1 = inv_a0 @ Ta1  # a at t = 1, seen from a at t = 0
    M_b = np.concatenate([inv_a0 @ Tb0, inv_a0 @ Tb1], axis=1)  # (p, 8, 4): b at 0, 1
    Rb = np.concatenate([M_b[:, 0:3, :3], M_b[:, 4:7, :3]], axis=1)  # (p, 6, 3)
    tb = np.concatenate([M_b[:, 0:3, 3], M_b[:, 4:7, 3]], axis=1)  # (p, 6)
    wa = chord_deviation_bound(rotation_angle(Ta0, Ta1), 1.0)  # mm of deviation per mm of |centre|
    wb = chord_deviation_bound(rotation_angle(Tb0, Tb1), 1.0)
    last = model.depth - 1
    toc = {}

    def keep(level, pair, na, nb):
        ca = model.centers[level][na]
        ca1 = np.einsum("fij,fj->fi", M_a1[pair, :3, :3], ca) + M_a1[pair, :3, 3]
        cb = np.einsum("fij,fj->fi", Rb[pair], model.centers[level][nb]) + tb[pair]
        A = ca - cb[:, :3]
        B = (ca1 - ca) - (cb[:, 3:] - cb[:, :3])
        R = (model.radii[level][na] + model.radii[level][nb]
             + wa[pair] * model.rho[level][na] + wb[pair] * model.rho[level][nb])
        if level < last:
            return min_distance_over_step(A, B) <= R
        enter, leave = contact_interval(A, B, R)
        ok = ~np.isnan(enter)
        toc["t"], toc["leave"] = enter[ok], leave[ok]
        return ok

    pair, la, lb = descend(model, pair_idx, keep, first_only=False)
    t = toc.get("t", np.zeros(0)) if len(pair) else np.zeros(0)
    leave = toc.get("leave", np.zeros(0)) if len(pair) else np.zeros(0)
    if first_only and len(pair):
        order = np.lexsort((t, pair))
        pair, la, lb, t, leave = pair[order], la[order], lb[order], t[order], leave[order]
        _, first = np.unique(pair, return_index=True)
        pair, la, lb, t, leave = pair[first], la[first], lb[first], t[first], leave[first]
    return pair, la, lb, t, leave


def refine_time_of_contact(model: CollisionModel, i_a: int, i_b: int, T0a, T1a, T0b, T1b, t_start: float,
                           tolerance: float = 0.05, max_iterations: int = 200) -> float | None:
    """Advance a conservative first time of contact on the exact meshes of bodies i_a, i_b.

    Returns a time in [t_start, 1) no later than the meshes' first contact (up to FCL's own
    accuracy), within `tolerance` mm of travel of it whenever it returns before `max_iterations`;
    None when conservative advancement proves the meshes stay apart until t = 1.
    """
    oa, ob = model.fcl_object(i_a), model.fcl_object(i_b)
    mu = max_speed(T0a, T1a, model.rho_max[i_a]) + max_speed(T0b, T1b, model.rho_max[i_b])

    def at(t):
        exact.set_pose(oa, interpolate_pose(T0a, T1a, t))
        exact.set_pose(ob, interpolate_pose(T0b, T1b, t))

    t = float(t_start)
    if mu <= 0:
        at(t)
        return t if exact.collide(oa, ob)[0] else None
    for _ in range(max_iterations):
        if t >= 1.0:
            return None
        at(t)
        d = exact.distance(oa, ob)
        if d <= 0.0:
            return t
        if d <= tolerance:
            t_probe = t + tolerance / mu
            if t_probe >= 1.0:
                return t  # contact, if any, lies within tolerance of travel: report conservatively
            at(t_probe)
            if exact.collide(oa, ob)[0]:
                return t
        t += d / mu
    return t

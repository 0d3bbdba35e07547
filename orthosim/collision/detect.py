"""One entry point for every detector: a whole-arch step in, a `StepResult` out.

The simulator and the renderer call `detect_step`; which detector runs is a parameter. Discrete
detectors (circles, discrete, exact) test the poses at the end of the step (`poses_end`, or
`poses_start` when there is no end); the continuous detector sweeps from `poses_start` to
`poses_end` with the motion of `orthosim.geometry.motion`.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from orthosim.model import fdi as fdi_mod
from orthosim.geometry import meshquery
from orthosim.collision.broadphase import candidate_pairs, sweep_and_prune
from orthosim.collision.circles import bounding_circles, circles_overlap, overlap_spheres
from orthosim.collision.continuous import refine_time_of_contact, swept_leaves
from orthosim.collision.detectors import DETECTORS
from orthosim.collision.contract import CollisionError, CollisionRequest, Contacts, StepResult, empty_leaves
from orthosim.collision.detectors import CIRCLES, DISCRETE, Detector, detector_named
from orthosim.collision.discrete import overlapping_leaves
from orthosim.collision.model import CollisionModel
from orthosim.geometry.motion import chord_deviation_bound, interpolate_poses, rotation_angle
from orthosim.collision.queries import ExactQueries


DRAW_TOLERANCE_MM = 1e-3  # leaf centres drawn on their chords when the true path strays less


def default_pairs(model: CollisionModel, poses: np.ndarray | None = None, absent: Sequence[int] = (),
                  poses_end: np.ndarray | None = None) -> list[tuple[int, int]]:
    """The broad phase: arch neighbours and facing teeth when every body is an FDI tooth, else
    `swept_sphere_pairs` at `poses` (rest poses by default), over the motion to `poses_end` when
    given ((n, 4, 4) arrays in body order)."""
    keys = model.keys
    if all(fdi_mod.is_fdi(k) for k in keys):
        return candidate_pairs(keys, absent)
    P0 = np.stack([b.rest_pose for b in model.bodies]) if poses is None else poses
    return swept_sphere_pairs(model, P0, P0 if poses_end is None else poses_end)


def swept_sphere_pairs(model: CollisionModel, poses: np.ndarray, poses_end: np.ndarray, margin_mm: float = 0.0,
                       moving_only: bool = False) -> list[tuple[int, int]]:
    """The broad phase for any bodies (teeth of either arch, crowns and roots, any distance apart
    along the arch): (key a, key b) of every pair whose root spheres, each grown to hold its whole
    sweep from `poses` to `poses_end` ((n, 4, 4) in body order) and by `margin_mm`, overlap (sweep
    and prune). Each root sphere's centre is followed along its chord, so the sphere about the
    chord's midpoint is grown by half the chord and by the centre's deviation from it
    (`motion.chord_deviation_bound`). moving_only: keep only pairs of which at least one body
    moves (a pair at rest cannot come into contact during the motion)."""
    keys = model.keys
    P0, P1 = poses, poses_end
    roots = model.roots(np.arange(len(keys)))
    c0 = model.xyz(model.world_centers(P0), roots)
    c1 = model.xyz(model.world_centers(P1), roots)
    r = (model.radii[roots] + 0.5 * np.linalg.norm(c1 - c0, axis=1)
         + chord_deviation_bound(rotation_angle(P0, P1), model.rho[roots]))
    idx = sweep_and_prune(0.5 * (c0 + c1), r, margin_mm)
    if moving_only and len(idx):
        moved = np.any(np.abs(P1 - P0) > 0, axis=(1, 2))
        idx = idx[moved[idx[:, 0]] | moved[idx[:, 1]]]
    return [(keys[i], keys[j]) for i, j in idx]


def resolve_detector(detector: str | Detector) -> Detector:
    """The Detector for a name (or the Detector given); CollisionError naming the choices otherwise."""
    found = detector_named(detector)
    if found is None:
        raise CollisionError(None, "detector", f"unknown detector {detector!r}", f"use one of {', '.join(DETECTORS)}")
    return found


def detect_step(model: CollisionModel, poses_start: Mapping[int, np.ndarray], poses_end: Mapping[int, np.ndarray] | None = None,
                pairs: Sequence[tuple[int, int]] | None = None, detector: str | Detector = "discrete",
                request: CollisionRequest = CollisionRequest(), queries: ExactQueries | None = None) -> StepResult:
    """Test every candidate pair of one step with one detector.

    poses_start, poses_end: FDI -> (4, 4) local -> arch frame (mm); teeth not given keep their rest pose.
    pairs: (FDI a, FDI b) to test; the broad phase (`default_pairs`) when None.
    detector: a `Detector` (`orthosim.collision.detectors`) or its name: "circles", "discrete",
        "continuous" or "exact".
    queries: the run's `ExactQueries` of this model, for the exact detector and the refinement of
        the continuous detector's time of contact (one is made for this call when None); the sphere
        trees' node centres are then placed through its memo (a step places the same poses twice).
    """
    d = resolve_detector(detector)
    P0 = model.pose_array(poses_start)
    P1 = model.pose_array(poses_end) if poses_end is not None else P0
    if pairs is None:
        pairs = default_pairs(model, P0, poses_end=P1) if d.sweeps else default_pairs(model, P1)
    pairs_arr = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    pair_idx = model.pair_indices(pairs_arr)
    return _STEP[d.name](model, P0, P1, pairs_arr, pair_idx, request, queries)


def _circles_step(model, P0, P1, pairs_arr, pair_idx, request, queries) -> StepResult:
    """Detector 1 at the end poses: overlapping bounding circles. No tree leaves: each touching
    pair's contact is the lens of its two circles, one sphere given for both teeth (leaf index -1),
    so that the renderer draws circles contacts too."""
    c, r = bounding_circles(model, P1)
    touching = circles_overlap(c, r, pair_idx)
    hit = np.flatnonzero(touching)
    centers, radii = overlap_spheres(model, P1, pair_idx[hit])
    leaves = dict(pair_of_leaf=hit.astype(np.int64), leaf_pairs=np.full((len(hit), 2), -1, np.int64),
                  centers_a=centers, centers_b=centers.copy(), radii_a=radii, radii_b=radii.copy())
    return StepResult("circles", pairs_arr, touching, np.full(len(pair_idx), np.nan), **leaves)


def _discrete_step(model, P0, P1, pairs_arr, pair_idx, request, queries) -> StepResult:
    """Detector 2 at the end poses: overlapping leaf spheres of the two trees."""
    p = len(pair_idx)
    W = queries.world_centers(P1) if queries is not None else model.world_centers(P1)
    pair, la, lb = overlapping_leaves(model, P1, pair_idx, not request.all_leaf_pairs, world=W)
    touching = np.zeros(p, bool)
    touching[pair] = True
    return StepResult("discrete", pairs_arr, touching, np.full(p, np.nan),
                      **_leaf_arrays(model, pair_idx, pair, la, lb, P1, P1, W=W))


def _continuous_step(model, P0, P1, pairs_arr, pair_idx, request, queries) -> StepResult:
    """Detector 3 over the motion P0 -> P1: each pair's time of first contact (refined on the exact
    meshes on request), and the leaves overlapping when it first touches, drawn where they are then."""
    p = len(pair_idx)
    place = queries.world_centers if queries is not None else model.world_centers
    W0, W1 = place(P0), place(P1)
    pair, la, lb, t, leave = swept_leaves(model, P0, P1, pair_idx, not request.all_leaf_pairs, world0=W0, world1=W1)
    toc = np.full(p, np.inf)
    np.minimum.at(toc, pair, t)
    toc[np.isinf(toc)] = np.nan
    if request.refine_time_of_contact:
        queries = queries or ExactQueries(model)
        for i in np.flatnonzero(~np.isnan(toc)):
            a, b = pair_idx[i]
            r = refine_time_of_contact(model, a, b, P0[a], P1[a], P0[b], P1[b], toc[i], request.contact_tolerance_mm,
                                       queries=queries, contact=request.contact)
            toc[i] = np.nan if r is None else r
    if not request.drawn_leaves:
        return StepResult("continuous", pairs_arr, ~np.isnan(toc), toc, **empty_leaves())
    # the contact regions drawn are the leaf pairs overlapping when their pair first touches
    at = toc[pair]
    live = (t <= at) & (at <= leave)
    pair, la, lb = pair[live], la[live], lb[live]
    leaves = _leaf_arrays(model, pair_idx, pair, la, lb, P0, P0, W=W0)
    _place_drawn_leaves(model, leaves, pair_idx, pair, la, lb, toc, P0, P1, W0, W1)
    return StepResult("continuous", pairs_arr, ~np.isnan(toc), toc, **leaves)


def _place_drawn_leaves(model, leaves, pair_idx, pair, la, lb, toc, P0, P1, W0, W1) -> None:
    """Pairs first touching after t = 0: their leaves drawn where they are at that time: on their
    chords when those stray less than DRAW_TOLERANCE_MM from the true paths, else at the poses."""
    p = len(pair_idx)
    touching = ~np.isnan(toc)
    sel = np.flatnonzero(toc[pair] > 0)
    if len(sel):
        ts = toc[pair[sel]][:, None]
        for key, nodes in (("centers_a", la[sel]), ("centers_b", lb[sel])):
            leaves[key][sel] = model.xyz(W0, nodes) + ts * (model.xyz(W1, nodes) - model.xyz(W0, nodes))
    stray = chord_deviation_bound(rotation_angle(P0, P1), model.rho_max)  # (n,) mm per body
    moved = np.flatnonzero(touching & (toc > 0) & (np.maximum(stray[pair_idx[:, 0]], stray[pair_idx[:, 1]]) > DRAW_TOLERANCE_MM))
    if len(moved):
        ia, ib = pair_idx[moved, 0], pair_idx[moved, 1]
        Ta = np.repeat(P0[:1], p, axis=0)
        Tb = Ta.copy()
        Ta[moved] = interpolate_poses(P0[ia], P1[ia], toc[moved])
        Tb[moved] = interpolate_poses(P0[ib], P1[ib], toc[moved])
        sel = np.flatnonzero(np.isin(pair, moved))
        redo = _leaf_arrays(model, pair_idx, pair[sel], la[sel], lb[sel], Ta, Tb, per_pair=True)
        leaves["centers_a"][sel] = redo["centers_a"]
        leaves["centers_b"][sel] = redo["centers_b"]


def _leaf_arrays(model, pair_idx, pair, la, lb, Pa, Pb, per_pair=False, W=None):
    """Leaf-pair arrays of a StepResult from flat leaf nodes; Pa, Pb are per-body poses, or per
    tooth pair (per_pair) when each pair is drawn at its own time; W: world centres if known."""
    ia, ib = pair_idx[pair, 0], pair_idx[pair, 1]
    if W is not None:
        ca, cb = model.xyz(W, la), model.xyz(W, lb)
    else:
        A = Pa[pair] if per_pair else Pa[ia]
        B = Pb[pair] if per_pair else Pb[ib]
        C = model.centers_flat
        ca = np.einsum("mij,mj->mi", A[:, :3, :3], C[la]) + A[:, :3, 3]
        cb = np.einsum("mij,mj->mi", B[:, :3, :3], C[lb]) + B[:, :3, 3]
    return dict(
        pair_of_leaf=pair.astype(np.int64),
        leaf_pairs=np.stack([model.leaf_index[la], model.leaf_index[lb]], axis=1).astype(np.int64).reshape(-1, 2),
        centers_a=ca.reshape(-1, 3),
        centers_b=cb.reshape(-1, 3),
        radii_a=model.radii[la],
        radii_b=model.radii[lb],
    )


def _exact_step(model, P0, P, pairs_arr, pair_idx, request, queries: ExactQueries | None) -> StepResult:
    """The exact reference at the end poses `P`: FCL on every pair: touching, distance; with
    all_leaf_pairs, contact points as zero-radius 'leaves' and the intersecting face index pairs in
    `leaf_pairs`."""
    queries = queries or ExactQueries(model)
    p = len(pair_idx)
    touching = np.zeros(p, bool)
    dist = np.zeros(p)
    pts, faces, owner = [], [], []
    for i, (a, b) in enumerate(pair_idx):
        hit, contacts = meshquery.collide(queries.placed(a, P[a]), queries.placed(b, P[b]), all_contacts=request.all_leaf_pairs)
        touching[i] = hit
        dist[i] = 0.0 if hit else queries.body_distance(a, P[a], b, P[b])
        if contacts is not None and len(contacts[0]):
            pts.append(contacts[0])
            faces.append(contacts[1])
            owner.append(np.full(len(contacts[0]), i))
    leaves = empty_leaves()
    if pts:
        c = np.concatenate(pts)
        leaves.update(pair_of_leaf=np.concatenate(owner).astype(np.int64), leaf_pairs=np.concatenate(faces),
                      centers_a=c, centers_b=c.copy(), radii_a=np.zeros(len(c)), radii_b=np.zeros(len(c)))
    return StepResult("exact", pairs_arr, touching, np.full(p, np.nan), distance=dist, **leaves)


# each detector's step, by its name (`detect_step` dispatches through it)
_STEP = {"circles": _circles_step, "discrete": _discrete_step, "continuous": _continuous_step,
         "exact": _exact_step}


def contacts(model: CollisionModel, poses: Mapping[int, np.ndarray], request: CollisionRequest, queries: ExactQueries,
             pairs: Sequence[tuple[int, int]] | None = None, detector: str | Detector = "continuous") -> Contacts:
    """The contacts of the bodies at `poses` as `detector` sees them: touching pairs, what is drawn
    as contact, and the exact interpenetration (and, where it decided contact, distance) of the pairs.

    Touching: circles: overlapping bounding circles; discrete: overlapping leaf spheres; continuous:
    overlapping leaf spheres whose exact meshes are also within `request.touch_tolerance_mm`; exact:
    exact meshes within that tolerance. pairs: FDI pairs to look at (the broad phase when None).
    """
    d = resolve_detector(detector)
    if pairs is None:
        pairs = default_pairs(model, model.pose_array(poses))
    pairs = [tuple(map(int, p)) for p in pairs]
    tol = request.touch_tolerance_mm
    distance: dict[tuple[int, int], float] = {}
    # the pairs whose meshes may intersect: FCL is asked their interpenetration, the rest are apart
    # (exact: a distance above 0; sphere trees: no overlapping leaf pair, the trees being conservative)
    may_meet = pairs
    if d.bounds == "meshes":
        distance = {p: queries.distance(p, poses) for p in pairs}
        touching = [p for p in pairs if distance[p] <= tol]
        may_meet = [p for p in pairs if distance[p] <= 0.0]
        centers, radii = np.zeros((0, 3)), np.zeros(0)
    else:
        # the contacts at one set of poses: the detector's bounds tested there (sweeping needs no motion)
        res = detect_step(model, poses, None, pairs, CIRCLES if d.bounds == "circles" else DISCRETE,
                          CollisionRequest(all_leaf_pairs=True), queries=queries)
        touching = res.touching_pairs()
        if d.bounds != "circles":
            may_meet = touching
        if d.exact_touch:
            distance = {p: queries.distance(p, poses) for p in touching}
            touching = [p for p in touching if distance[p] <= tol]
        kept = set(touching)
        keep = np.isin(res.pair_of_leaf, [i for i, p in enumerate(map(tuple, res.pairs.tolist())) if p in kept])
        if d.bounds == "circles":  # one lens per pair, given for both teeth
            centers, radii = res.centers_a[keep], res.radii_a[keep]
        else:
            centers = np.concatenate([res.centers_a[keep], res.centers_b[keep]])
            radii = np.concatenate([res.radii_a[keep], res.radii_b[keep]])
    return Contacts(tuple(touching), centers, radii, queries.penetrations(may_meet, poses), distance)

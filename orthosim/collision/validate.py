"""Accuracy studies of the sphere-tree detectors against the exact mesh test (the report behind
the issue's "no false negatives" and "never misses a contact" claims).

Discrete study: random relative poses of two teeth near contact. For a random orientation of
each tooth and a random direction u, tooth b slides along u toward tooth a until the meshes just
touch (line search with exact FCL distances), then moves by a signed offset (mm; negative =
pushed in). Every pose is labelled by FCL (intersecting or not, distance) and tested by the
discrete sphere-tree detector, all poses of a batch in one vectorised call.

Continuous study: random motions over one step (the motion of `orthosim.geometry.motion`) passing
near a contact pose: linear, rotational (up to half a turn) and "tunnelling" (a thin root crossing
a tooth so fast that neither end pose touches). Ground truth: FCL collide at `samples` equally
spaced times, the first hit refined by bisection (resolution 1/samples of the step before
bisection: contacts that begin and end between two samples are invisible to it).
"""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import fcl
import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from orthosim.geometry import meshquery as exact
from orthosim.collision.continuous import refine_time_of_contact, swept_leaves_posed
from orthosim.collision.discrete import overlapping_leaves_posed
from orthosim.storage.atomic import write_json
from orthosim.collision.model import Body, CollisionModel, default_tree_builder
from orthosim.geometry.motion import interpolate_pose, max_speed
from orthosim.collision.queries import ExactQueries

OFFSET_MM = 0.5  # near contact: signed offset from first contact within +/- this
FP_THRESHOLDS_MM = (0.1, 0.25, 0.5, 1.0, 2.0)
# Separation bands (mm, lower bound exclusive, upper inclusive) of the false-positive table: a loose
# leaf sphere shows as a contact claimed at a small separation, which a cumulative "> x mm" rate
# dilutes with the many far poses no tree calls touching.
FP_BANDS_MM = ((0.0, 0.1), (0.1, 0.25), (0.25, 0.5), (0.5, 1.0), (1.0, 2.0), (2.0, np.inf))


_QUERIES: "weakref.WeakKeyDictionary[CollisionModel, ExactQueries]" = weakref.WeakKeyDictionary()


def _object(model: CollisionModel, i: int):
    """Body i's FCL object, owned by this module's `ExactQueries` of the model (one per model)."""
    queries = _QUERIES.get(model)
    if queries is None:
        queries = _QUERIES[model] = ExactQueries(model)
    return queries.object(i)


def band_name(lo: float, hi: float) -> str:
    """JSON key of a separation band, e.g. "0.1-0.25mm" (">2.0mm" for the open last band)."""
    return f">{lo}mm" if np.isinf(hi) else f"{lo}-{hi}mm"


def false_positive_bands(distance_mm: np.ndarray, found: np.ndarray) -> dict:
    """Per separation band (`FP_BANDS_MM`): poses whose exact distance lies in it and the share of
    them the detector calls touching (None for an empty band). Intersecting poses (distance 0)
    fall in no band."""
    out = {}
    for lo, hi in FP_BANDS_MM:
        sel = (distance_mm > lo) & (distance_mm <= hi)
        out[band_name(lo, hi)] = {"poses": int(sel.sum()), "rate": float(found[sel].mean()) if sel.any() else None}
    return out


@dataclass(frozen=True)
class ToothSet:
    """A named group of meshes studied together (pairs are drawn within the group)."""

    name: str
    meshes: tuple[trimesh.Trimesh, ...]
    pairs: tuple[tuple[int, int], ...] = ()  # which meshes to pair; all pairs of distinct meshes when empty


def _raw_distance(oa, ob) -> float:
    res = fcl.DistanceResult()
    return float(fcl.distance(oa, ob, fcl.DistanceRequest(), res))


def _pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def contact_offset(oa, ob, Ta: np.ndarray, Rb: np.ndarray, u: np.ndarray, s_far: float, tol: float = 1e-4) -> float | None:
    """mm along u at which tooth b (orientation Rb) first touches tooth a coming from s_far.

    Conservative line search: moving b by the current distance d along -u cannot make the meshes
    cross, so the first contact is approached from outside. None when b passes a without touching.
    """
    exact.set_pose(oa, Ta)
    s = s_far
    for _ in range(400):
        exact.set_pose(ob, _pose(Rb, s * u))
        d = _raw_distance(oa, ob)
        if d <= tol:
            return s
        s -= d
        if s < -s_far:
            return None
    return s


def _model(tooth_sets: Sequence[ToothSet], tree_builder) -> tuple[CollisionModel, list[list[int]]]:
    bodies, index = [], []
    for ts in tooth_sets:
        idx = []
        for m in ts.meshes:
            idx.append(len(bodies))
            bodies.append(Body(len(bodies), m, tree_builder(m), np.eye(4)))
        index.append(idx)
    return CollisionModel(bodies), index


def _pairs_of(ts: ToothSet) -> list[tuple[int, int]]:
    if ts.pairs:
        return list(ts.pairs)
    n = len(ts.meshes)
    return [(i, j) for i in range(n) for j in range(n) if i != j]


def _near_contact_pose(model, rng, i, j, lo, hi):
    """(Ta, Tb, offset, u) with b at a random signed offset in [lo, hi] mm from first contact."""
    oa, ob = _object(model, i), _object(model, j)
    s_far = model.rho_max[i] + model.rho_max[j] + 1.0
    while True:
        Ra, Rb = Rotation.random(2, random_state=rng).as_matrix()
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        s_c = contact_offset(oa, ob, _pose(Ra, np.zeros(3)), Rb, u, s_far)
        if s_c is not None:
            off = rng.uniform(lo, hi)
            return _pose(Ra, np.zeros(3)), _pose(Rb, (s_c + off) * u), off, u


@dataclass(frozen=True)
class DiscretePoses:
    """Near-contact poses of tooth pairs, labelled by the exact mesh test (one tooth set's draw).

    pair (p, 2) body indices into the model the poses were drawn with; Ta, Tb (p, 4, 4) poses;
    offset (p,) mm from first contact; hit (p,) exact intersection; distance (p,) mm, exact (0
    where intersecting)."""

    pair: np.ndarray
    Ta: np.ndarray
    Tb: np.ndarray
    offset: np.ndarray
    hit: np.ndarray
    distance: np.ndarray
    seconds: float


def draw_discrete_poses(model: CollisionModel, ts: ToothSet, idx: Sequence[int], n_poses: int, rng,
                        offset_range=(-OFFSET_MM, OFFSET_MM)) -> DiscretePoses:
    """n_poses random near-contact poses of pairs of `ts` (bodies `idx` of `model`), labelled by FCL.

    The draw depends on the meshes only (never on the sphere trees), so trees built differently can be
    compared on the very same poses (`paired_false_positives`)."""
    pairs = _pairs_of(ts)
    t0 = time.perf_counter()
    recs = []
    for k in range(n_poses):
        i, j = pairs[rng.integers(len(pairs))]
        Ta, Tb, off, _ = _near_contact_pose(model, rng, idx[i], idx[j], *offset_range)
        oa, ob = _object(model, idx[i]), _object(model, idx[j])
        exact.set_pose(oa, Ta)
        exact.set_pose(ob, Tb)
        hit = exact.collide(oa, ob)[0]
        dist = 0.0 if hit else exact.distance(oa, ob)
        recs.append((idx[i], idx[j], Ta, Tb, off, hit, dist))
    return DiscretePoses(pair=np.array([[r[0], r[1]] for r in recs], dtype=np.int64).reshape(-1, 2),
                         Ta=np.stack([r[2] for r in recs]), Tb=np.stack([r[3] for r in recs]),
                         offset=np.array([r[4] for r in recs]), hit=np.array([r[5] for r in recs], dtype=bool),
                         distance=np.array([r[6] for r in recs]), seconds=time.perf_counter() - t0)


def detect_discrete(model: CollisionModel, poses: DiscretePoses, batch: int = 2000) -> np.ndarray:
    """(p,) bool: the poses the discrete sphere-tree detector calls touching (the model's trees)."""
    found = np.zeros(len(poses.pair), bool)
    for s in range(0, len(found), batch):
        sl = slice(s, s + batch)
        pair, _, _ = overlapping_leaves_posed(model, poses.pair[sl], poses.Ta[sl], poses.Tb[sl], first_only=True)
        found[s + pair] = True
    return found


def discrete_study(tooth_sets: Sequence[ToothSet], n_poses: int, tree_builder=None, seed: int = 0,
                   offset_range=(-OFFSET_MM, OFFSET_MM), batch: int = 2000) -> dict:
    """False negatives and false-positive rates of the discrete sphere-tree detector vs FCL.

    n_poses poses per tooth set, offsets uniform in offset_range (mm). Returns a JSON-able dict.
    """
    tree_builder = tree_builder or default_tree_builder()
    model, index = _model(tooth_sets, tree_builder)
    rng = np.random.default_rng(seed)
    out = {"offset_range_mm": list(offset_range), "sets": {}}
    for ts, idx in zip(tooth_sets, index):
        poses = draw_discrete_poses(model, ts, idx, n_poses, rng, offset_range)
        hit, dist, offset, pair_idx = poses.hit, poses.distance, poses.offset, poses.pair
        t0 = time.perf_counter()
        found = detect_discrete(model, poses, batch)
        t_det = time.perf_counter() - t0
        fn = hit & ~found
        out["sets"][ts.name] = {
            "poses": int(len(hit)),
            "exact_intersecting": int(hit.sum()),
            "false_negatives": int(fn.sum()),
            "false_negative_examples": [
                {"pair": [int(pair_idx[k, 0]), int(pair_idx[k, 1])], "offset_mm": float(offset[k])} for k in np.flatnonzero(fn)[:5]
            ],
            "false_positive_rate": {
                f">{x}mm": {"poses": int((dist > x).sum()),
                            "rate": float(found[dist > x].mean()) if (dist > x).any() else None}
                for x in FP_THRESHOLDS_MM
            },
            "false_positive_rate_by_band": false_positive_bands(dist, found),
            "detector_seconds": t_det,
            "exact_labelling_seconds": poses.seconds,
        }
    return out


def paired_false_positives(tooth_sets: Sequence[ToothSet], tree_builders: dict, n_poses: int,
                           seeds: Sequence[int] = (0,), offset_range=(-OFFSET_MM, OFFSET_MM),
                           band=(0.1, 0.25)) -> dict:
    """Several tree builders on the very same poses: per seed and pooled (over the seeds, and per
    tooth set), each builder's false negatives and false-positive rate in `band` (mm), and against
    the first builder (the baseline) how many poses in the band flip from false positive to true
    negative and back.

    tree_builders: name -> (mesh -> SphereTree), the baseline first. n_poses per tooth set and seed.
    Poses are drawn with the meshes alone (`draw_discrete_poses`); the trees only answer them."""
    names = list(tree_builders)
    models = {}
    for name in names:
        models[name], index = _model(tooth_sets, tree_builders[name])
    lo, hi = band
    per_seed, pooled = {}, {name: {"in_band": 0, "false_positives": 0, "false_negatives": 0} for name in names}
    per_set = {ts.name: {name: {"in_band": 0, "false_positives": 0} for name in names} for ts in tooth_sets}
    flips = {name: {"fp_to_tn": 0, "tn_to_fp": 0} for name in names[1:]}
    for seed in seeds:
        rng = np.random.default_rng(seed)
        rows = {name: {"in_band": 0, "false_positives": 0, "false_negatives": 0} for name in names}
        seed_flips = {name: {"fp_to_tn": 0, "tn_to_fp": 0} for name in names[1:]}
        for ts, idx in zip(tooth_sets, index):
            poses = draw_discrete_poses(models[names[0]], ts, idx, n_poses, rng, offset_range)
            sel = (poses.distance > lo) & (poses.distance <= hi)
            found = {name: detect_discrete(models[name], poses) for name in names}
            for name in names:
                per_set[ts.name][name]["in_band"] += int(sel.sum())
                per_set[ts.name][name]["false_positives"] += int((found[name] & sel).sum())
                rows[name]["in_band"] += int(sel.sum())
                rows[name]["false_positives"] += int((found[name] & sel).sum())
                rows[name]["false_negatives"] += int((poses.hit & ~found[name]).sum())
            for name in names[1:]:
                seed_flips[name]["fp_to_tn"] += int((sel & found[names[0]] & ~found[name]).sum())
                seed_flips[name]["tn_to_fp"] += int((sel & ~found[names[0]] & found[name]).sum())
        for name in names:
            rows[name]["rate"] = _rate(rows[name])
            for key in ("in_band", "false_positives", "false_negatives"):
                pooled[name][key] += rows[name][key]
        for name in names[1:]:
            for key in ("fp_to_tn", "tn_to_fp"):
                flips[name][key] += seed_flips[name][key]
        per_seed[str(seed)] = {"builders": rows, "flips_against_baseline": seed_flips}
    for name in names:
        n, k = pooled[name]["in_band"], pooled[name]["false_positives"]
        pooled[name]["rate"] = _rate(pooled[name])
        pooled[name]["rate_standard_error"] = float(np.sqrt(k / n * (1 - k / n) / n)) if n else None
    for rows in per_set.values():
        for row in rows.values():
            row["rate"] = _rate(row)
    return {"band_mm": [lo, hi], "poses_per_set_and_seed": n_poses, "baseline": names[0],
            "seeds": per_seed, "pooled": pooled, "pooled_per_set": per_set, "flips_against_baseline": flips}


def _rate(row: dict) -> float | None:
    """False positives over the poses in the band, None when the band holds none."""
    return row["false_positives"] / row["in_band"] if row["in_band"] else None


def dense_first_contact(oa, ob, T0a, T1a, T0b, T1b, samples: int = 400, bisections: int = 30):
    """(t_lo, t_hi) bracketing the first contact found by FCL at `samples` equally spaced times,
    refined by bisection; None when no sample touches."""
    ts = np.arange(samples + 1) / samples
    ts = ts[ts < 1.0]
    Pa = interpolate_pose(T0a, T1a, ts)
    Pb = interpolate_pose(T0b, T1b, ts)
    hit_k = None
    for k in range(len(ts)):
        exact.set_pose(oa, Pa[k])
        exact.set_pose(ob, Pb[k])
        if exact.collide(oa, ob)[0]:
            hit_k = k
            break
    if hit_k is None:
        return None
    if hit_k == 0:
        return 0.0, 0.0
    return _bisect_contact(oa, ob, T0a, T1a, T0b, T1b, ts[hit_k - 1], ts[hit_k], bisections)


def _bisect_contact(oa, ob, T0a, T1a, T0b, T1b, lo: float, hi: float, bisections: int) -> tuple[float, float]:
    """Narrow [lo, hi] (apart at lo, intersecting at hi) around the meshes' first contact."""
    for _ in range(bisections):
        mid = 0.5 * (lo + hi)
        exact.set_pose(oa, interpolate_pose(T0a, T1a, mid))
        exact.set_pose(ob, interpolate_pose(T0b, T1b, mid))
        if exact.collide(oa, ob)[0]:
            hi = mid
        else:
            lo = mid
    return float(lo), float(hi)


def _random_rotvec(rng, max_angle):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return axis * rng.uniform(0, max_angle)


def _motion_through(T_mid: np.ndarray, tau: float, dp: np.ndarray, w: np.ndarray):
    """(T0, T1): the step, in orthosim's motion, that passes T_mid at time tau with displacement dp, turn w."""
    R_mid, p_mid = T_mid[:3, :3], T_mid[:3, 3]
    R0 = Rotation.from_rotvec(-tau * w).as_matrix() @ R_mid
    R1 = Rotation.from_rotvec((1 - tau) * w).as_matrix() @ R_mid
    return _pose(R0, p_mid - tau * dp), _pose(R1, p_mid + (1 - tau) * dp)


MOTION_KINDS = ("linear", "rotational", "tunnelling")


def _random_motion(model, rng, ia, ib, kind):
    """(T0a, T1a, T0b, T1b) of one random step of the given kind near a contact of bodies ia, ib."""
    if kind == "tunnelling":
        # b (a thin root) crosses a at high speed: both ends of the step far apart
        Ta, Tb, _, u = _near_contact_pose(model, rng, ia, ib, -3.0, -0.5)
        L = rng.uniform(2.5, 4.0) * (model.rho_max[ia] + model.rho_max[ib])
        dp = -u * L + rng.normal(scale=0.05 * L, size=3)
        w = _random_rotvec(rng, 0.3)
    else:
        Ta, Tb, _, u = _near_contact_pose(model, rng, ia, ib, -0.6, 0.3)
        if kind == "linear":
            L = rng.uniform(0.05, 5.0)
            dp = -u * L + rng.normal(scale=0.3 * L, size=3)
            w = np.zeros(3)
        else:
            dp = rng.normal(scale=rng.uniform(0.0, 1.0), size=3)
            w = _random_rotvec(rng, np.pi)  # up to half a turn in one step
    tau = rng.uniform(0.1, 0.9)
    T0b, T1b = _motion_through(Tb, tau, dp, w)
    if rng.random() < 0.5:  # tooth a moves a little too
        T0a, T1a = _motion_through(Ta, tau, rng.normal(scale=0.2, size=3), _random_rotvec(rng, 0.1))
    else:
        T0a = T1a = Ta
    return T0a, T1a, T0b, T1b


def continuous_study(tooth_sets: Sequence[ToothSet], n_motions: int, tree_builder=None, seed: int = 0,
                     samples: int = 400, tolerance_mm: float = 0.05, kinds=MOTION_KINDS,
                     tunnelling_sets: Sequence[str] = ()) -> dict:
    """Misses and time-of-contact errors of the continuous detector vs dense exact sampling.

    n_motions per tooth set, kinds cycled; "tunnelling" motions only for sets named in
    tunnelling_sets (thin roots). Returns a JSON-able dict.
    """
    tree_builder = tree_builder or default_tree_builder()
    model, index = _model(tooth_sets, tree_builder)
    rng = np.random.default_rng(seed)
    out = {"samples_per_step": samples, "tolerance_mm": tolerance_mm, "sets": {}}
    for ts, idx in zip(tooth_sets, index):
        set_kinds = [k for k in kinds if k != "tunnelling" or ts.name in tunnelling_sets]
        pairs = _pairs_of(ts)
        recs = []
        for k in range(n_motions):
            kind = set_kinds[k % len(set_kinds)]
            i, j = pairs[rng.integers(len(pairs))]
            recs.append((idx[i], idx[j], kind, *_random_motion(model, rng, idx[i], idx[j], kind)))
        pair_idx = np.array([[r[0], r[1]] for r in recs])
        T = [np.stack([r[c] for r in recs]) for c in range(3, 7)]
        t0 = time.perf_counter()
        pair, _, _, tl, _ = swept_leaves_posed(model, pair_idx, *T, first_only=True)
        t_sweep = time.perf_counter() - t0
        sphere_toc = np.full(len(recs), np.nan)
        sphere_toc[pair] = tl
        rows = []
        t_refine = 0.0
        for k, (ia, ib, kind, T0a, T1a, T0b, T1b) in enumerate(recs):
            oa, ob = _object(model, ia), _object(model, ib)
            truth = dense_first_contact(oa, ob, T0a, T1a, T0b, T1b, samples)
            ends = []
            for Pa, Pb in ((T0a, T0b), (T1a, T1b)):
                exact.set_pose(oa, Pa)
                exact.set_pose(ob, Pb)
                ends.append(exact.collide(oa, ob)[0])
            refined = None
            if not np.isnan(sphere_toc[k]):
                s = time.perf_counter()
                refined = refine_time_of_contact(model, ia, ib, T0a, T1a, T0b, T1b, sphere_toc[k], tolerance_mm)
                t_refine += time.perf_counter() - s
            mu = max_speed(T0a, T1a, model.rho_max[ia]) + max_speed(T0b, T1b, model.rho_max[ib])
            rechecked = False
            if truth is not None and refined is not None and (truth[0] - refined) * mu > tolerance_mm:
                # the sampled ground truth may have stepped over a brief earlier contact: sample the
                # window between the detector's time and the sampled one 20x more finely
                early = _first_contact_in_window(oa, ob, T0a, T1a, T0b, T1b, refined, truth[0], 20 * samples)
                if early is not None:
                    truth, rechecked = early, True
            rows.append((kind, truth, sphere_toc[k], refined, mu, not any(ends), rechecked, (ia, ib)))
        out["sets"][ts.name] = _summarise_motions(rows, tolerance_mm)
        out["sets"][ts.name]["sweep_seconds"] = t_sweep
        out["sets"][ts.name]["refine_seconds"] = t_refine
    return out


def _first_contact_in_window(oa, ob, T0a, T1a, T0b, T1b, t0: float, t1: float, samples: int, bisections: int = 30):
    """(lo, hi) bracket of the first exact contact sampled in [t0, t1], or None."""
    ts = np.linspace(t0, t1, samples + 1)
    Pa = interpolate_pose(T0a, T1a, ts)
    Pb = interpolate_pose(T0b, T1b, ts)
    for k in range(len(ts)):
        exact.set_pose(oa, Pa[k])
        exact.set_pose(ob, Pb[k])
        if exact.collide(oa, ob)[0]:
            if k == 0:
                return float(ts[0]), float(ts[0])
            return _bisect_contact(oa, ob, T0a, T1a, T0b, T1b, ts[k - 1], ts[k], bisections)
    return None


def _summarise_motions(rows, tolerance_mm) -> dict:
    res = {"motions": len(rows), "by_kind": {}}
    for kind in sorted({r[0] for r in rows}) + ["all"]:
        sel = [r for r in rows if kind == "all" or r[0] == kind]
        hits = [r for r in sel if r[1] is not None]
        miss_sphere = sum(1 for r in hits if np.isnan(r[2]))
        miss_refined = sum(1 for r in hits if r[3] is None)
        late_sphere = sum(1 for r in hits if not np.isnan(r[2]) and r[2] > r[1][1] + 1e-9)
        late_refined = sum(1 for r in hits if r[3] is not None and r[3] > r[1][1] + 1e-9)
        err_sphere = np.array([(r[1][0] - r[2]) * r[4] for r in hits if not np.isnan(r[2])])
        err_refined = np.array([(r[1][0] - r[3]) * r[4] for r in hits if r[3] is not None])
        no_contact = [r for r in sel if r[1] is None]
        res["by_kind"][kind] = {
            "motions": len(sel),
            "exact_contacts": len(hits),
            "exact_contacts_unseen_at_both_ends": sum(1 for r in hits if r[5]),
            "missed_by_sphere_trees": miss_sphere,
            "missed_after_refinement": miss_refined,
            "later_than_exact_sphere_trees": late_sphere,
            "later_than_exact_refined": late_refined,
            "toc_travel_error_mm_sphere_trees": _stats(err_sphere),
            "toc_travel_error_mm_refined": _stats(err_refined),
            "refined_within_tolerance": int((err_refined <= tolerance_mm + 1e-9).sum()),
            "ground_truth_corrected_by_finer_sampling": sum(1 for r in hits if r[6]),
            "outside_tolerance_examples": [
                {"bodies": [int(r[7][0]), int(r[7][1])], "exact_bracket": list(r[1]), "refined": r[3],
                 "sphere_tree": None if np.isnan(r[2]) else float(r[2]), "speed_bound_mm_per_step": r[4],
                 "travel_error_mm": (r[1][0] - r[3]) * r[4]}
                for r in hits if r[3] is not None and (r[1][0] - r[3]) * r[4] > tolerance_mm + 1e-9][:5],
            "false_positive_rate_no_exact_contact": {
                "motions": len(no_contact),
                "sphere_trees": float(np.mean([not np.isnan(r[2]) for r in no_contact])) if no_contact else None,
                "refined": float(np.mean([r[3] is not None for r in no_contact])) if no_contact else None,
            },
        }
    return res


def _stats(x: np.ndarray) -> dict:
    if x.size == 0:
        return {"n": 0}
    return {"n": int(x.size), "median": float(np.median(x)), "p95": float(np.percentile(x, 95)),
            "max": float(x.max()), "min": float(x.min())}


def thin_root_mesh(length: float = 14.0, radius: float = 0.4, sections: int = 12) -> trimesh.Trimesh:
    """A thin cylinder along local y (a thin root, mm) centred on the origin."""
    m = trimesh.creation.cylinder(radius=radius, height=length, sections=sections)
    m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    return m


def default_tooth_sets(real_folder: str | Path | None = None, real_numbers=(3, 4, 5, 6, 7, 8, 9),
                       resolutions=("smooth", "coarse")) -> list[ToothSet]:
    """Parametric teeth at each resolution (adjacent pairs of one quadrant plus facing pairs), thin
    roots against coarse parametric crowns, and, when the folder exists, real Open-Full-Jaw upper
    teeth (neighbours along the arch)."""
    from orthosim.model.parametric import parametric_dentition

    fdis = [11, 12, 13, 14, 15, 16, 17, 41, 46]
    adj = tuple((k, k + 1) for k in range(6)) + ((0, 7), (5, 8))
    sets, coarse = [], None
    for res in resolutions:
        d = parametric_dentition(resolution=res)
        meshes = tuple(d.teeth[n].mesh for n in fdis)
        sets.append(ToothSet(f"parametric_{res}", meshes, adj))
        if res == "coarse":
            coarse = meshes
    crowns = coarse if coarse is not None else sets[0].meshes
    roots = (thin_root_mesh(14.0, 0.4), thin_root_mesh(10.0, 0.25))
    sets.append(ToothSet("thin_root", roots + crowns[:3], ((0, 2), (0, 3), (1, 4), (0, 1), (1, 2))))
    if real_folder is not None and Path(real_folder).exists():
        real = []
        for n in real_numbers:
            m = trimesh.load(Path(real_folder) / f"tooth_{n}.stl")
            m.apply_translation(-m.bounds.mean(axis=0))
            real.append(m)
        sets.append(ToothSet("real_open_full_jaw", tuple(real), tuple((k, k + 1) for k in range(len(real) - 1))))
    return sets


def run_validation(out: str | Path, n_poses: int = 10000, n_motions: int = 2000, seed: int = 0,
                   real_folder: str | Path | None = None,
                   tree_builder: Callable | None = None, samples: int = 400, tree_label: str | None = None) -> dict:
    """Both studies, written to `out` as JSON. n_poses / n_motions are split across the tooth sets.

    tree_builder: mesh -> SphereTree (the project's cached "fit" builder by default); tree_label
    names it in the report.
    """
    sets = default_tooth_sets(real_folder)
    per_pose = -(-n_poses // len(sets))
    per_motion = -(-n_motions // len(sets))
    t0 = time.perf_counter()
    report = {
        "discrete": discrete_study(sets, per_pose, tree_builder, seed),
        "discrete_far": discrete_study(sets, max(per_pose // 4, 1), tree_builder, seed + 1, offset_range=(0.5, 3.0)),
        "continuous": continuous_study(sets, per_motion, tree_builder, seed + 2, samples=samples,
                                       tunnelling_sets=("thin_root",)),
        "real_teeth_folder": str(real_folder) if real_folder is not None and Path(real_folder).is_dir() else None,
        "tree_builder": tree_label or getattr(tree_builder, "__name__", None) or "orthosim.spheretree cached_sphere_tree (fit)",
        "tooth_sets": {ts.name: {"meshes": len(ts.meshes), "faces": [len(m.faces) for m in ts.meshes],
                                 "pairs": [list(p) for p in _pairs_of(ts)]} for ts in sets},
        "definitions": {
            "discrete": "random orientations; tooth b slid along a random direction to first contact, then offset "
                        "uniformly in offset_range_mm (negative = pushed in); labelled by FCL collide/distance",
            "false_positive_rate": "share of poses with FCL distance above the threshold that the sphere trees call touching",
            "false_positive_rate_by_band": "share of poses with FCL distance in (lo, hi] mm that the sphere trees call touching",
            "continuous": "random steps (motion.interpolate_pose) through a near-contact pose; ground truth = FCL collide at "
                          "samples_per_step times + bisection, re-sampled 20x finer where the detector is earlier than tolerance",
            "toc_travel_error_mm": "(exact first contact - detector time) x speed bound of the fastest point of either tooth (mm/step)",
        },
    }
    report["seconds"] = time.perf_counter() - t0
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    write_json(out, report)
    return report

"""The bite closes after every step: the mandible turns about its hinge axis until its teeth meet the upper ones.

Teeth of the two arches do not pass through each other, and they do not lock either: the jaw
opens as far as the cusps require and closes again (maximum intercuspation, what a dental CAD's
virtual articulator does). After each step's tooth movements `close_bite` opens the mandible (all
lower teeth together, each keeping its own pose in it) about the condylar axis until every facing
pair is clear, then closes it to first contact:

- the closing motion is swept in hinge turns of at most `ClosureSettings.sweep_deg`, each given to
  the continuous detector (`collision.detect_step`, time of first contact refined on the exact
  meshes to the run's contact tolerance). Its motion law (`geometry.motion`) moves a tooth's origin
  along the chord of the hinge's arc; over 0.5 degrees a point 110 mm from the axis leaves the arc
  by at most 110 * (0.5 pi / 180)^2 / 8 = 0.001 mm, far below the contact tolerance;
- facing pairs that interpenetrate at rest (the scan's segmentation overlap, the rest state) may
  come back to that overlap but no deeper: every crown vertex's depth inside the other tooth
  (`geometry.signeddistance`, the report's measure) at most its rest value plus the
  tolerance; the angle where that limit is met is bisected. The step's pair depth
  (`ExactQueries.penetration`) also sees edges, whose interior can lie deeper than both ends by
  the sagitta of an edge over a cusp: 0.3 mm edges over a 2 mm cusp radius, 0.3^2 / 16 = 0.006 mm.
  Checking it as well would cost ten times as much (0.14 s a pair on patient 26).

A contact the closure cannot resolve is one still beyond its limit with the mandible opened by
`max_opening_deg` (an upper tooth driven into the side of a lower one, which opening the jaw does
not clear within a mouth's range): the simulation then stops the teeth that moved into it.

The condylar axis, unless the case gives it (`[occlusion] condylar_axis`), is estimated from the
lower arch with Bonwill's triangle: the two condyles and the lower central incisors' contact
point form an equilateral triangle of 4 inches (about 100 mm) a side (Bonwill 1899, "The
scientific articulation of the human teeth as founded on geometrical, mathematical and mechanical
laws", Dental Items of Interest, 1899), tilted by Balkwill's angle (about 26 degrees, the
mean he measured, Balkwill 1866, "The best form and arrangement of artificial teeth for
mastication", Transactions of the Odontological Society of Great Britain, 1866) to the occlusal plane. So the
intercondylar distance is 100 mm, and the midpoint of the condyles lies 100 cos 30 = 86.6 mm from
the incisal point, 86.6 cos 26 = 77.8 mm behind it and 86.6 sin 26 = 38.0 mm above the occlusal
plane. Units: mm, degrees (positive opening: the incisors go down).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from orthosim.model import fdi as F

BONWILL_SIDE_MM = 100.0  # Bonwill 1899: the equilateral triangle's side (4 inches)
BALKWILL_DEG = 26.0  # Balkwill 1866: mean angle between Bonwill's triangle and the occlusal plane


@dataclass(frozen=True)
class ClosureSettings:
    """How the bite closes ([occlusion] table of a case file).

    mode: "hinge" (the mandible closes about its condylar axis after every step) or "none" (the
        occlusal slide allowance of `MovementSettings` decides, as without closure).
    condylar_axis_mm: ((3,), (3,)) right and left condyle centres (arch frame, mm) for a known
        patient; None: estimated from the arch (`estimate_hinge_axis`).
    tolerance_mm: how much deeper than at rest a pair may end (mm), and the travel within which the
        closure stops short of first contact.
    open_deg: first trial opening (degrees) beyond the current bite, doubled until every pair clears.
    max_opening_deg: the widest the mandible opens (degrees from rest); a pair still beyond its
        limit there is a contact the closure cannot resolve.
    sweep_deg: the largest hinge turn given to the continuous detector at once (degrees).
    """

    mode: str = "none"
    condylar_axis_mm: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    tolerance_mm: float = 0.02
    open_deg: float = 0.25
    max_opening_deg: float = 8.0
    sweep_deg: float = 0.5


@dataclass(frozen=True, eq=False)
class HingeAxis:
    """The terminal hinge axis through the two condyles (arch frame, mm); `method` says where it came from."""

    right_mm: np.ndarray
    left_mm: np.ndarray
    method: str

    def transform(self, angle_deg: float) -> np.ndarray:
        """(4, 4) the mandible's turn by `angle_deg` about the axis; positive opens (incisors down)."""
        u = self.left_mm - self.right_mm
        u = u / np.linalg.norm(u)
        a = np.radians(angle_deg)
        K = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
        R = np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * (K @ K)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = self.right_mm - R @ self.right_mm
        return T


def _incisal_point(dentition, lower: list[int]) -> np.ndarray:
    """(3,) mm: the lower central incisors' contact point, taken as the mean of the highest crown
    vertex of the two lower teeth nearest the midline (at rest)."""
    mid = sorted(lower, key=lambda n: F.position(n))[:2]
    tips = []
    for n in mid:
        t = dentition.teeth[n]
        w = t.to_world(t.crown_vertices)
        tips.append(w[np.argmax(w[:, 1])])
    return np.mean(tips, axis=0)


def estimate_hinge_axis(dentition, absent=frozenset()) -> HingeAxis:
    """The condylar axis from the lower arch at rest by Bonwill's triangle and Balkwill's angle (module
    doc): the occlusal plane is the arch frame's x-z plane (y up); forward is from the mean crown
    centre of the lower arch's two distal-most teeth toward the incisal point."""
    lower = [n for n in dentition.fdis if F.arch_of(n) is F.Arch.LOWER and n not in absent]
    if len(lower) < 3:
        raise ValueError("a hinge axis needs at least three lower teeth")
    order = F.arch_order(F.Arch.LOWER, set(lower))
    centers = dentition.crown_centers(dentition.rest_poses())
    incisal = _incisal_point(dentition, lower)
    back = 0.5 * (centers[order[0]] + centers[order[-1]])
    up = np.array([0.0, 1.0, 0.0])
    forward = incisal - back
    forward = forward - (forward @ up) * up
    forward /= np.linalg.norm(forward)
    left = np.cross(up, forward)
    left_side = [centers[n] for n in lower if F.quadrant(n) == 3]
    if left_side and (np.mean(left_side, axis=0) - incisal) @ left < 0:
        left = -left
    reach = BONWILL_SIDE_MM * np.cos(np.radians(30.0))  # incisal point to the middle of the condyles
    mid = incisal - reach * np.cos(np.radians(BALKWILL_DEG)) * forward + reach * np.sin(np.radians(BALKWILL_DEG)) * up
    half = 0.5 * BONWILL_SIDE_MM * left
    return HingeAxis(mid - half, mid + half, "Bonwill's triangle (100 mm) at Balkwill's angle (26 deg)")


@dataclass(frozen=True, eq=False)
class RestOverlap:
    """A facing pair that interpenetrates at rest: each crown vertex's depth inside the other tooth at
    rest ((k,) mm, 0 outside), for the upper and the lower tooth."""

    upper_vertex_depths_mm: np.ndarray
    lower_vertex_depths_mm: np.ndarray


@dataclass(frozen=True, eq=False)
class ClosureModel:  # eq=False and no slots: `_boxes` is cached in the instance's __dict__
    """What the closure needs and never changes during a run: the settings, the hinge axis, the facing
    pairs (upper, lower), the pairs overlapping at rest, the crown vertices and surface indexes of
    their teeth, and the mandible's landmarks (incisal point, mean lower first-molar crown centre,
    at rest, mm) where the bite opening is measured."""

    settings: ClosureSettings
    axis: HingeAxis
    facing: tuple[tuple[int, int], ...]
    overlaps: dict[tuple[int, int], RestOverlap]
    crowns: dict[int, np.ndarray] = field(repr=False)
    surfaces: dict[int, object] = field(repr=False)
    incisal_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    molar_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def build(cls, settings: ClosureSettings, dentition, facing, absent=frozenset()) -> "ClosureModel":
        """From the dentition at rest and the simulation's facing pairs (upper, lower)."""
        from orthosim.geometry import meshquery
        from orthosim.geometry.signeddistance import mesh_surface

        if settings.condylar_axis_mm is not None:
            r, l = (np.asarray(p, float) for p in settings.condylar_axis_mm)
            axis = HingeAxis(r, l, "given in the case file")
        else:
            axis = estimate_hinge_axis(dentition, absent)
        facing = tuple((u, lo) if F.arch_of(u) is F.Arch.UPPER else (lo, u) for u, lo in facing)
        rest = dentition.rest_poses()
        objects = {}
        for n in {t for p in facing for t in p}:
            objects[n] = meshquery.fcl_object(dentition.teeth[n].mesh)
            meshquery.set_pose(objects[n], rest[n])
        touched = [p for p in facing if meshquery.collide(objects[p[0]], objects[p[1]])[0]]
        crowns = {n: np.asarray(dentition.teeth[n].crown_vertices, float) for p in touched for n in p}
        surfaces = {n: mesh_surface(dentition.teeth[n].mesh) for n in crowns}
        model = cls(settings, axis, facing, {}, crowns, surfaces)
        for u, lo in touched:
            model.overlaps[(u, lo)] = RestOverlap(model.vertex_depths(u, lo, rest), model.vertex_depths(lo, u, rest))
        lower = [n for n in dentition.fdis if F.arch_of(n) is F.Arch.LOWER and n not in absent]
        molars = [n for n in lower if F.position(n) == 6] or lower
        centers = dentition.crown_centers(rest)
        object.__setattr__(model, "incisal_mm", _incisal_point(dentition, lower))
        object.__setattr__(model, "molar_mm", np.mean([centers[n] for n in molars], axis=0))
        return model

    def vertex_depths(self, a: int, b: int, poses: Mapping[int, np.ndarray]) -> np.ndarray:
        """(k,) mm each crown vertex of tooth a lies inside tooth b at `poses` (0 outside)."""
        V = self.crowns[a]
        Ta, Tb = np.asarray(poses[a], float), np.asarray(poses[b], float)
        M = np.linalg.inv(Tb) @ Ta
        local = V @ M[:3, :3].T + M[:3, 3]
        surface = self.surfaces[b]
        out = np.zeros(len(V))
        lo, hi = surface.bounds
        near = np.flatnonzero(np.all((local >= lo) & (local <= hi), axis=1))  # only these can be inside
        if len(near):
            d, _ = surface.signed_distance(local[near], 5.0)
            out[near] = np.where(np.isfinite(d), np.maximum(-d, 0.0), 0.0)
        return out

    def opening_mm(self, angle_deg: float) -> tuple[float, float]:
        """(incisors, molars) mm the bite stands open at `angle_deg` from rest: how far the mandible's
        incisal point and first-molar point have dropped along the occlusal normal (y)."""
        T = self.axis.transform(angle_deg)
        out = []
        for p in (self.incisal_mm, self.molar_mm):
            out.append(float(p[1] - (T[:3, :3] @ p + T[:3, 3])[1]))
        return out[0], out[1]


@dataclass(frozen=True, eq=False)
class Closure:
    """The bite after closing: the mandible's hinge angle from rest (degrees, positive open), every
    tooth's pose (FDI -> (4, 4), lower teeth turned with the mandible), and the facing pairs still
    beyond their limit at the widest opening (contacts the closure cannot resolve)."""

    angle_deg: float
    poses: dict[int, np.ndarray]
    unresolved: tuple[tuple[int, int], ...]


class _Sweep:
    """The closing of one set of tooth poses: lower teeth turned by `delta` degrees about the axis
    from where they stand (the mandible at `start_deg`)."""

    def __init__(self, cm: ClosureModel, collision, queries, poses: Mapping[int, np.ndarray], start_deg: float):
        self.cm, self.collision, self.queries = cm, collision, queries
        self.poses, self.start_deg = poses, start_deg
        self.lower = [n for n in poses if F.arch_of(n) is F.Arch.LOWER]

    def posed(self, delta_deg: float) -> dict[int, np.ndarray]:
        if delta_deg == 0.0:
            return dict(self.poses)
        T = self.cm.axis.transform(delta_deg)
        out = dict(self.poses)
        for n in self.lower:
            out[n] = T @ self.poses[n]
        return out

    def excess_mm(self, pair, poses) -> float:
        """mm the pair lies beyond its limit at `poses`: for a pair apart at rest, infinite when its
        meshes intersect at all; for a pair the scan left overlapping, how much deeper than at rest
        any crown vertex of either tooth lies inside the other (module doc)."""
        q = self.queries
        if not q.intersects(pair, poses):
            return 0.0
        rest = self.cm.overlaps.get(pair)
        if rest is None:
            return np.inf
        u, lo = pair
        return max(float(np.max(self.cm.vertex_depths(u, lo, poses) - rest.upper_vertex_depths_mm, initial=0.0)),
                   float(np.max(self.cm.vertex_depths(lo, u, poses) - rest.lower_vertex_depths_mm, initial=0.0)))

    def beyond(self, delta_deg: float, pairs, first: bool = False) -> list[tuple[int, int]]:
        """The pairs beyond their limit with the mandible turned by `delta_deg` (with `first`, at most one)."""
        P = self.posed(delta_deg)
        tol = self.cm.settings.tolerance_mm
        out = []
        for p in pairs:
            if self.excess_mm(p, P) > tol:
                out.append(p)
                if first:
                    break
        return out

    def open(self) -> tuple[float, tuple[tuple[int, int], ...]]:
        """(delta degrees, unresolved pairs): the least trial opening (doubling from `open_deg`, up to
        `max_opening_deg` from rest) at which every facing pair is within its limit."""
        s = self.cm.settings
        widest = s.max_opening_deg - self.start_deg
        delta = min(s.open_deg, widest)
        while True:
            left = self.beyond(delta, self.cm.facing)
            if not left:
                return delta, ()
            if delta >= widest:
                return delta, tuple(left)
            delta = min(2.0 * delta, widest)

    def close(self, top_deg: float, floor_deg: float) -> float:
        """delta degrees where closing from `top_deg` toward `floor_deg` first meets a limit."""
        s = self.cm.settings
        a = top_deg
        engaged = {p for p in self.cm.overlaps if self.queries.intersects(p, self.posed(a))}
        while a > floor_deg:
            b = max(a - s.sweep_deg, floor_deg)
            free = [p for p in self.cm.facing if p not in engaged]
            t = self._first_contact(free, a, b, engaged) if free else None
            stop = None if t is None else a - t * (a - b)
            end = b if stop is None else stop
            if engaged and self.beyond(end, engaged, first=True):
                return self._bisect(a, end, engaged)
            if stop is not None:
                return stop
            a = b
        return floor_deg

    def _first_contact(self, pairs, a_deg: float, b_deg: float, engaged: set) -> float | None:
        """The continuous detector's first time of contact (fraction of the turn from `a_deg` to
        `b_deg`) of the pairs apart at rest, None if none meets; pairs overlapping at rest that come
        into contact join `engaged`. The sphere trees' times are conservative, so pairs are refined
        on the exact meshes earliest first, and one whose sphere-tree time is not before the best
        refined time cannot be first (its refinement is skipped)."""
        from orthosim.collision import CollisionRequest, detect_step
        from orthosim.collision.continuous import refine_time_of_contact

        P0, P1 = self.posed(a_deg), self.posed(b_deg)
        request = CollisionRequest(all_leaf_pairs=False, refine_time_of_contact=False, drawn_leaves=False)
        res = detect_step(self.collision, P0, P1, pairs, "continuous", request, queries=self.queries)
        hits = sorted((t, tuple(pr)) for pr, t in zip(res.pairs.tolist(), res.time_of_first_contact.tolist())
                      if not np.isnan(t))
        best = None
        for t, (u, lo) in hits:
            if (u, lo) in self.cm.overlaps:
                engaged.add((u, lo))
                continue
            if best is not None and t >= best:
                continue
            iu, il = self.collision.index[u], self.collision.index[lo]
            r = refine_time_of_contact(self.collision, iu, il, P0[u], P1[u], P0[lo], P1[lo], t,
                                       self.cm.settings.tolerance_mm, queries=self.queries)
            if r is not None:
                best = r if best is None else min(best, r)
        return best

    def _bisect(self, ok_deg: float, bad_deg: float, pairs) -> float:
        """The angle within the tolerance's travel above the first where a pair passes its limit."""
        span = max(np.linalg.norm(self.cm.incisal_mm - self.cm.axis.right_mm),
                   np.linalg.norm(self.cm.incisal_mm - self.cm.axis.left_mm))
        step = np.degrees(self.cm.settings.tolerance_mm / span)
        while ok_deg - bad_deg > step:
            mid = 0.5 * (ok_deg + bad_deg)
            if self.beyond(mid, pairs, first=True):
                bad_deg = mid
            else:
                ok_deg = mid
        return ok_deg


def close_bite(cm: ClosureModel, collision, queries, poses: Mapping[int, np.ndarray], angle_deg: float) -> Closure:
    """Open the mandible standing at `angle_deg` (degrees from rest) until every facing pair is within
    its limit, then close it to first contact (module doc). poses: FDI -> (4, 4) of every tooth, the
    lower ones as they stand in the mandible at `angle_deg`; collision, queries: the run's
    `CollisionModel` and `ExactQueries`."""
    sweep = _Sweep(cm, collision, queries, poses, angle_deg)
    top, unresolved = sweep.open()
    if unresolved:
        return Closure(angle_deg + top, sweep.posed(top), unresolved)
    # closing may go below where the bite stood (teeth moved out of each other's way), down to the rest
    # angle less the widest opening's worth
    floor = -cm.settings.max_opening_deg - angle_deg
    delta = sweep.close(top, floor)
    return Closure(angle_deg + delta, sweep.posed(delta), ())


def closure_settings(case, tolerance_mm: float = 0.02) -> ClosureSettings:
    """The case's [occlusion] settings; a closure the case leaves unsaid is "hinge" for mesh models
    (real teeth, whose cusps interdigitate) and "none" for the parametric paper models."""
    occ = getattr(case, "occlusion", None)
    mode = getattr(occ, "closure", None)
    if mode is None:
        mode = "none" if case.model.kind == "parametric" else "hinge"
    axis = getattr(occ, "condylar_axis", None)
    widest = getattr(occ, "max_opening_deg", ClosureSettings.max_opening_deg)
    return ClosureSettings(mode, axis, tolerance_mm, max_opening_deg=widest)


def settle_bite(cm: ClosureModel, collision, queries, start: Mapping[int, np.ndarray], poses: Mapping[int, np.ndarray],
                angle_deg: float, rounds: int = 3) -> tuple[Closure, dict[int, np.ndarray]]:
    """`close_bite` after a step that took the teeth from `start` to `poses` (the mandible at
    `angle_deg` in both); a tooth that moved into a contact the closure cannot resolve goes back to
    its start pose and the bite closes again. Returns the closure (its `unresolved`: the pairs that
    stopped a tooth) and the poses it closed (in the mandible at `angle_deg`, stopped teeth back)."""
    poses = dict(poses)
    stopped: list[tuple[int, int]] = []
    for _ in range(rounds + 1):
        closed = close_bite(cm, collision, queries, poses, angle_deg)
        if not closed.unresolved:
            return replace(closed, unresolved=tuple(stopped)), poses
        movers = {n for p in closed.unresolved for n in p if not np.array_equal(poses[n], start[n])}
        if not movers:
            break
        stopped += [p for p in closed.unresolved if p not in stopped]
        for n in movers:
            poses[n] = start[n]
    # nothing left to stop: the bite stays where it stood
    return Closure(angle_deg, dict(poses), tuple(stopped) or closed.unresolved), poses

"""Exact answers on the teeth's meshes for one run: every geometric question a step asks.

    queries = ExactQueries(collision_model)        # one per run: it owns FCL objects and their poses
    queries.intersects((13, 14), poses)            # pair = FDI keys; poses = FDI -> (4, 4)
    queries.distance((13, 14), poses)              # mm between the meshes, 0.0 when they intersect
    queries.penetration((13, 14), poses)           # mm the meshes interpenetrate, 0.0 when apart

The `CollisionModel` never changes during a run; the FCL objects that exact queries re-pose are
state, so they live here, one set per run (a second run, or a thread, makes its own).

Every answer is a function of the two meshes and the two poses alone, so distances and depths are
kept under the bodies and the poses' exact bytes (a pose one ulp off is a new query) and each is
the very number FCL (or the depth measure) gave: a step asks for the same distance several times
(a touching pair before and after its motion, in each detection round, when a time of contact is
refined from t = 0, when the step's contacts are listed). The `memo_size` least recently used
answers of each kind are kept.

An intersection test is skipped when the pair's last exact distance proves the meshes apart: a
point of body i moves, in body j's frame, by at most |dR|_F rho_i + |dt| between two relative
poses (dR, dt the change of the relative rotation and translation, rho_i the farthest vertex of
i from its origin), so the distance cannot have shrunk by more; when it stays above
`APART_MARGIN_MM` the meshes do not intersect and FCL's collide would say so. A step asks this of
every pair it moves a little (a touching pair's distance before its move, then after it).

Units: mm; poses local -> arch frame.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Iterable, Mapping

import numpy as np
import trimesh

from ..geometry import meshquery
from .model import CollisionModel

APART_MARGIN_MM = 1e-6  # a pair proved apart by less than this is tested with FCL all the same
PATCH_REACH_MM = 0.5  # a pair's patches hold every face within this of the other tooth when cut


class _Patch:
    """The faces of two teeth near each other, cut at one relative pose, as two FCL objects.

    rel_ij / rel_ji: (3, 4) pose of i in j's frame and of j in i's, when cut. obj_i / obj_j: FCL
    objects of the kept faces (the whole vertex arrays, so triangle for triangle FCL computes the
    very numbers it computes on the whole meshes), None when either side kept none (`empty`).
    shift: mm, how far either tooth's vertices have moved relative to the other since the cut, at
    the poses last asked about.
    """

    def __init__(self, rel_ij, rel_ji, obj_i, obj_j):
        self.rel_ij, self.rel_ji, self.obj_i, self.obj_j = rel_ij, rel_ji, obj_i, obj_j
        self.shift = 0.0

    @property
    def empty(self) -> bool:
        return self.obj_i is None

    def placed(self, pose_i: np.ndarray, pose_j: np.ndarray):
        meshquery.set_pose(self.obj_i, pose_i)
        meshquery.set_pose(self.obj_j, pose_j)
        return self.obj_i, self.obj_j


class ExactQueries:
    """Exact intersection, distance and interpenetration depth between the model's meshes."""

    def __init__(self, model: CollisionModel, memo_size: int = 4096, patch_reach_mm: float = PATCH_REACH_MM):
        self.model = model
        self._objects: dict[int, object] = {}
        self._memo_size = memo_size
        self._distances: OrderedDict[tuple, float] = OrderedDict()
        self._depths: OrderedDict[tuple, tuple[bool, float]] = OrderedDict()
        self._last_apart: dict[tuple[int, int], tuple[np.ndarray, float]] = {}  # (i, j) -> (pose of i in j, mm)
        self.queries = 0  # distance queries asked of FCL (the rest were remembered)
        self.collides = 0  # intersection tests asked of FCL (the rest were remembered or proved apart)
        self.patch_reach_mm = patch_reach_mm
        self._patches: dict[tuple[int, int], _Patch] = {}
        self._edges: dict[int, float] = {}
        self._trees: dict[int, object] = {}

    # ------------------------------------------------------------------ by FDI pair and poses
    def intersects(self, pair: tuple[int, int], poses: Mapping[int, np.ndarray]) -> bool:
        """Whether the two meshes' surfaces intersect at `poses`."""
        i, j = self._pair(pair)
        return self.body_intersects(i, poses[pair[0]], j, poses[pair[1]])

    def distance(self, pair: tuple[int, int], poses: Mapping[int, np.ndarray]) -> float:
        """mm between the two meshes at `poses`; 0.0 when they intersect."""
        i, j = self._pair(pair)
        return self.body_distance(i, poses[pair[0]], j, poses[pair[1]])

    def penetration(self, pair: tuple[int, int], poses: Mapping[int, np.ndarray]) -> float:
        """mm the two meshes interpenetrate at `poses` (`meshquery.penetration_depth`, measured when
        FCL finds them intersecting); 0.0 when apart."""
        i, j = self._pair(pair)
        return self.body_penetration(i, poses[pair[0]], j, poses[pair[1]])

    def penetrations(self, pairs: Iterable[tuple[int, int]], poses: Mapping[int, np.ndarray]) -> dict[tuple[int, int], float]:
        """mm per pair of `pairs` whose meshes intersect at `poses`, in `pairs` order (pairs apart are
        left out; an intersecting pair whose depth the vertex-based measure puts at 0 is kept, at 0)."""
        out = {}
        for a, b in pairs:
            hit, depth = self._intersection(self.model.index[a], poses[a], self.model.index[b], poses[b])
            if hit:
                out[(a, b)] = depth
        return out

    # ------------------------------------------------------------------ by body index and pose
    def object(self, i: int):
        """Body i's python-fcl BVH object (built on first use, then kept); its pose is whatever was
        set last: place it with `placed` before a query."""
        obj = self._objects.get(i)
        if obj is None:
            obj = self._objects[i] = meshquery.fcl_object(self.model.bodies[i].mesh)
        return obj

    def placed(self, i: int, pose: np.ndarray):
        """Body i's FCL object placed at `pose` (4, 4)."""
        obj = self.object(i)
        meshquery.set_pose(obj, pose)
        return obj

    def prepare(self, keys: Iterable[int]) -> None:
        """Build the FCL objects of these bodies (keys) now rather than at their first query."""
        for k in keys:
            self.object(self.model.index[int(k)])

    def body_intersects(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray) -> bool:
        if self.proved_apart(i, pose_i, j, pose_j):
            return False
        self.collides += 1
        patch = self._patch(i, pose_i, j, pose_j, build=False)
        if patch is not None:
            return patch.empty is False and meshquery.collide(*patch.placed(pose_i, pose_j))[0]
        return meshquery.collide(self.placed(i, pose_i), self.placed(j, pose_j))[0]

    def body_distance(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray) -> float:
        key = (i, j, _bytes(pose_i), _bytes(pose_j))
        d = self._distances.get(key)
        if d is not None:
            self._distances.move_to_end(key)
            return d
        apart = self.proved_apart(i, pose_i, j, pose_j)
        if not apart:
            self.collides += 1
        d = None
        patch = self._patch(i, pose_i, j, pose_j, build=True)
        if patch is not None and not patch.empty:
            d = meshquery.distance(*patch.placed(pose_i, pose_j), apart=apart)
            if d + patch.shift > self.patch_reach_mm:
                d = None  # the closest faces may lie outside the patches
        if d is None:
            d = meshquery.distance(self.placed(i, pose_i), self.placed(j, pose_j), apart=apart)
        self._remember(self._distances, key, d)
        if d > APART_MARGIN_MM:
            self._last_apart[(i, j)] = (_relative(pose_i, pose_j), d)
        self.queries += 1
        return d

    def proved_apart(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray) -> bool:
        """Whether the pair's last exact distance, less how far body i can have moved relative to
        body j since, leaves the meshes more than `APART_MARGIN_MM` apart at these poses."""
        last = self._last_apart.get((i, j))
        if last is None:
            return False
        M0, d0 = last
        return bool(d0 - self._shift(i, M0, _relative(pose_i, pose_j)) > APART_MARGIN_MM)

    def _shift(self, i: int, M0: np.ndarray, M: np.ndarray) -> float:
        """mm: how far any vertex of body i can lie between relative poses M0 and M (3, 4)."""
        return float(np.linalg.norm(M[:, :3] - M0[:, :3]) * self.model.rho_max[i] + np.linalg.norm(M[:, 3] - M0[:, 3]))

    def _patch(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray, build: bool) -> "_Patch | None":
        """The pair's patches with `shift` set for these poses: kept while the teeth have moved
        relative to each other by at most half the reach since they were cut, cut afresh (build)
        otherwise; None when there are none and build is False."""
        M, N = _relative(pose_i, pose_j), _relative(pose_j, pose_i)
        patch = self._patches.get((i, j))
        if patch is not None:
            patch.shift = max(self._shift(i, patch.rel_ij, M), self._shift(j, patch.rel_ji, N))
            if patch.shift <= 0.5 * self.patch_reach_mm:
                return patch
        if not build:
            return None
        patch = self._patches[(i, j)] = self._cut_patch(i, j, M, N)
        return patch

    def _cut_patch(self, i: int, j: int, M: np.ndarray, N: np.ndarray) -> "_Patch":
        """The faces of bodies i and j that lie within the reach of the other at relative poses M
        (i in j's frame) and N (j in i's frame).

        A point of a triangle lies within the triangle's longest edge of one of its corners, so a
        face within the reach of the other mesh has a corner within reach + both meshes' longest
        edges of one of the other's vertices: every face with such a corner is kept."""
        bi, bj = self.model.bodies[i], self.model.bodies[j]
        radius = self.patch_reach_mm + self._longest_edge(i) + self._longest_edge(j)
        keep = []
        for body, other, R in ((bi, j, M), (bj, i, N)):
            v = np.asarray(body.mesh.vertices, float) @ R[:, :3].T + R[:, 3]  # in the other's frame
            near = np.isfinite(self._vertex_tree(other).query(v, distance_upper_bound=radius)[0])
            keep.append(np.flatnonzero(near[np.asarray(body.mesh.faces)].any(axis=1)))
        if not len(keep[0]) or not len(keep[1]):
            return _Patch(M, N, None, None)
        objects = [meshquery.fcl_object(trimesh.Trimesh(b.mesh.vertices, np.asarray(b.mesh.faces)[f], process=False))
                   for b, f in ((bi, keep[0]), (bj, keep[1]))]
        return _Patch(M, N, *objects)

    def _longest_edge(self, i: int) -> float:
        if i not in self._edges:
            self._edges[i] = float(self.model.bodies[i].mesh.edges_unique_length.max())
        return self._edges[i]

    def _vertex_tree(self, i: int):
        tree = self._trees.get(i)
        if tree is None:
            from scipy.spatial import cKDTree

            tree = self._trees[i] = cKDTree(np.asarray(self.model.bodies[i].mesh.vertices, float))
        return tree

    def body_penetration(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray) -> float:
        return self._intersection(i, pose_i, j, pose_j)[1]

    def _intersection(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray) -> tuple[bool, float]:
        """(whether the meshes intersect, mm deep), remembered."""
        key = (i, j, _bytes(pose_i), _bytes(pose_j))
        known = self._depths.get(key)
        if known is not None:
            self._depths.move_to_end(key)
            return known
        hit, depth = self.body_intersects(i, pose_i, j, pose_j), 0.0
        if hit:
            depth = meshquery.penetration_depth(self.model.bodies[i].mesh, pose_i, self.model.bodies[j].mesh, pose_j)
        return self._remember(self._depths, key, (hit, depth))

    # ------------------------------------------------------------------
    def _pair(self, pair) -> tuple[int, int]:
        return self.model.index[pair[0]], self.model.index[pair[1]]

    def _remember(self, memo: OrderedDict, key, value):
        memo[key] = value
        if len(memo) > self._memo_size:
            memo.popitem(last=False)
        return value


def _relative(pose_i: np.ndarray, pose_j: np.ndarray) -> np.ndarray:
    """(3, 4): body i's pose in body j's local frame (rigid poses: the inverse is the transpose)."""
    Rj = pose_j[:3, :3]
    return np.concatenate([Rj.T @ pose_i[:3, :3], (Rj.T @ (pose_i[:3, 3] - pose_j[:3, 3]))[:, None]], axis=1)


def _bytes(T: np.ndarray) -> bytes:
    return np.ascontiguousarray(T, dtype=float).tobytes()

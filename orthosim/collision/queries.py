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

Units: mm; poses local -> arch frame.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Iterable, Mapping

import numpy as np

from ..geometry import meshquery
from .model import CollisionModel


class ExactQueries:
    """Exact intersection, distance and interpenetration depth between the model's meshes."""

    def __init__(self, model: CollisionModel, memo_size: int = 4096):
        self.model = model
        self._objects: dict[int, object] = {}
        self._memo_size = memo_size
        self._distances: OrderedDict[tuple, float] = OrderedDict()
        self._depths: OrderedDict[tuple, tuple[bool, float]] = OrderedDict()
        self.queries = 0  # distance queries asked of FCL (the rest were remembered)

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
        return meshquery.collide(self.placed(i, pose_i), self.placed(j, pose_j))[0]

    def body_distance(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray) -> float:
        key = (i, j, _bytes(pose_i), _bytes(pose_j))
        d = self._distances.get(key)
        if d is not None:
            self._distances.move_to_end(key)
            return d
        d = self._remember(self._distances, key, meshquery.distance(self.placed(i, pose_i), self.placed(j, pose_j)))
        self.queries += 1
        return d

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


def _bytes(T: np.ndarray) -> bytes:
    return np.ascontiguousarray(T, dtype=float).tobytes()

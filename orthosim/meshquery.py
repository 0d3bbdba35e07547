"""Exact queries between posed tooth meshes through FCL: do they intersect, how far apart are they.

Used where the model must be exact rather than fast: placing parametric teeth so that neighbours
just touch, and checking a model in tests. FCL tests surfaces only, so a mesh wholly inside
another reads as separate; for teeth placed side by side that cannot happen.
"""

from __future__ import annotations

import fcl
import numpy as np
import trimesh


class MeshQuery:
    """FCL bounding-volume hierarchies for a set of meshes, built once, queried under any poses."""

    def __init__(self, meshes: dict[int, trimesh.Trimesh]):
        self._models = {}
        for key, mesh in meshes.items():
            model = fcl.BVHModel()
            model.beginModel(len(mesh.vertices), len(mesh.faces))
            model.addSubModel(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int32))
            model.endModel()
            self._models[key] = model

    def _object(self, key: int, pose: np.ndarray) -> fcl.CollisionObject:
        return fcl.CollisionObject(self._models[key], fcl.Transform(pose[:3, :3], pose[:3, 3]))

    def intersects(self, a: int, pose_a: np.ndarray, b: int, pose_b: np.ndarray) -> bool:
        result = fcl.CollisionResult()
        return fcl.collide(self._object(a, pose_a), self._object(b, pose_b), fcl.CollisionRequest(), result) > 0

    def distance(self, a: int, pose_a: np.ndarray, b: int, pose_b: np.ndarray) -> float:
        """mm between the surfaces; 0.0 when they intersect."""
        if self.intersects(a, pose_a, b, pose_b):
            return 0.0
        result = fcl.DistanceResult()
        return float(fcl.distance(self._object(a, pose_a), self._object(b, pose_b), fcl.DistanceRequest(), result))

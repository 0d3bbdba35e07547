"""The collision model of a dentition: everything detectors need that never changes during a run.

Built once (MuJoCo's mjModel in our STYLE): per tooth its sphere tree, its bounding circle data and,
on first use, its exact FCL mesh model. The sphere trees of all teeth are concatenated level by
level into global arrays, so a descent can handle the node pairs of every tooth pair at once with
numpy. A step's state is just the poses (dict FDI -> (4, 4) local -> arch frame, mm).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np
import trimesh

from ..spheretree.tree import SphereTree
from .contract import CollisionError


@dataclass(frozen=True, eq=False)
class Body:
    """One rigid body of the collision model (a tooth): local mesh, sphere tree, rest pose."""

    key: int  # FDI number for teeth (any int for generic models)
    mesh: trimesh.Trimesh  # local frame, mm
    tree: SphereTree
    rest_pose: np.ndarray  # (4, 4)


@dataclass(eq=False)
class CollisionModel:
    """Sphere trees, bounding circles and exact meshes of every body, built once.

    Global level arrays (k = 0 .. depth-1):
      centers[k] (N_k, 3) mm local frame of the owning body, radii[k] (N_k,), rho[k] (N_k,) mm =
      |centre| (distance from the body's local origin, for the rotation bound), owner[k] (N_k,)
      body index, child_start[k] / child_count[k] (N_k,) global index range of the children in
      level k+1, start[k] (n_bodies + 1,) first global node of each body.
    """

    bodies: list[Body]
    centers: list[np.ndarray] = field(init=False)
    radii: list[np.ndarray] = field(init=False)
    rho: list[np.ndarray] = field(init=False)
    child_start: list[np.ndarray] = field(init=False)
    child_count: list[np.ndarray] = field(init=False)
    start: list[np.ndarray] = field(init=False)
    index: dict[int, int] = field(init=False)

    def __post_init__(self):
        if not self.bodies:
            raise CollisionError(None, "collision model", "no teeth given", "pass at least two teeth")
        depths = {b.tree.depth for b in self.bodies}
        if len(depths) != 1:
            raise CollisionError(
                None, "sphere trees", f"trees of different depths {sorted(depths)}", "build every tree with the same depth"
            )
        depth = depths.pop()
        self.index = {b.key: i for i, b in enumerate(self.bodies)}
        self.centers, self.radii, self.rho, self.start = [], [], [], []
        for k in range(depth):
            counts = np.array([len(b.tree.radii[k]) for b in self.bodies])
            self.start.append(np.concatenate([[0], np.cumsum(counts)]).astype(np.int64))
            c = np.concatenate([b.tree.centers[k] for b in self.bodies]).astype(float)
            self.centers.append(np.ascontiguousarray(c))
            self.radii.append(np.concatenate([b.tree.radii[k] for b in self.bodies]).astype(float))
            self.rho.append(np.linalg.norm(c, axis=1))
        self.child_start, self.child_count = [], []
        for k in range(depth - 1):
            starts, counts = [], []
            for i, b in enumerate(self.bodies):
                off = b.tree.child_offsets(k + 1)
                starts.append(off[:-1] + self.start[k + 1][i])
                counts.append(np.diff(off))
            self.child_start.append(np.concatenate(starts).astype(np.int64))
            self.child_count.append(np.concatenate(counts).astype(np.int64))
        self._circle = _circle_data(self.bodies)
        self.rho_max = np.array([np.linalg.norm(b.mesh.vertices, axis=1).max() for b in self.bodies])
        self._fcl: dict[int, object] = {}

    @property
    def depth(self) -> int:
        return len(self.centers)

    @property
    def keys(self) -> list[int]:
        return [b.key for b in self.bodies]

    def body(self, key: int) -> Body:
        return self.bodies[self._idx(key)]

    def _idx(self, key: int) -> int:
        try:
            return self.index[int(key)]
        except KeyError:
            raise CollisionError(None, f"tooth {key}", "is not in the collision model", "add it or drop it from the pairs") from None

    def pair_indices(self, pairs) -> np.ndarray:
        """(p, 2) body indices of (p, 2) keys."""
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        return np.array([[self._idx(a), self._idx(b)] for a, b in pairs], dtype=np.int64).reshape(-1, 2)

    def pose_array(self, poses: Mapping[int, np.ndarray], keys=None) -> np.ndarray:
        """(n_bodies, 4, 4) poses in body order; bodies missing from `poses` keep their rest pose."""
        out = np.stack([b.rest_pose for b in self.bodies]).astype(float)
        for k, T in poses.items():
            i = self.index.get(int(k))
            if i is not None:
                out[i] = T
        return out

    def leaf_local(self, body_idx: np.ndarray, global_leaf: np.ndarray) -> np.ndarray:
        """Leaf index within its own tree of global leaf indices."""
        return global_leaf - self.start[-1][body_idx]

    def fcl_object(self, i: int):
        """The body's python-fcl BVH collision object (built on first use, then kept)."""
        obj = self._fcl.get(i)
        if obj is None:
            from .exact import fcl_object

            obj = fcl_object(self.bodies[i].mesh)
            self._fcl[i] = obj
        return obj

    @classmethod
    def from_dentition(cls, dentition, tree_builder: Callable[[trimesh.Trimesh], SphereTree] | None = None,
                       trees: Mapping[int, SphereTree] | None = None) -> "CollisionModel":
        """Model of every present tooth; trees from `trees` when given, else `tree_builder(tooth.mesh)`.

        With neither, the project's builder `orthosim.spheretree.cached_sphere_tree` is used.
        """
        if tree_builder is None and trees is None:
            tree_builder = default_tree_builder()
        bodies = []
        for n in dentition.fdis:
            tooth = dentition.teeth[n]
            tree = trees[n] if trees is not None and n in trees else tree_builder(tooth.mesh)
            bodies.append(Body(n, tooth.mesh, tree, np.asarray(tooth.rest_pose, float)))
        return cls(bodies)


def default_tree_builder() -> Callable[[trimesh.Trimesh], SphereTree]:
    try:
        from ..spheretree import cached_sphere_tree
    except ImportError:
        try:
            from ..spheretree import build_sphere_tree as cached_sphere_tree
        except ImportError:
            raise CollisionError(
                None, "tree_builder", "orthosim.spheretree has no builder yet", "pass tree_builder= or trees="
            ) from None
    return lambda mesh: cached_sphere_tree(mesh)


@dataclass(frozen=True, eq=False)
class _CircleData:
    center_local: np.ndarray  # (n, 3) mm: the point whose projection is the circle centre
    r_plane: np.ndarray  # (n,) mm: radius of the projection at the rest orientation
    half_height: np.ndarray  # (n,) mm: largest vertical offset from the centre at rest


def _circle_data(bodies: list[Body]) -> _CircleData:
    centers, r_plane, half_height = [], [], []
    for b in bodies:
        R, p = b.rest_pose[:3, :3], b.rest_pose[:3, 3]
        world = b.mesh.vertices @ R.T + p
        lo, hi = world.min(axis=0), world.max(axis=0)
        c = 0.5 * (lo + hi)
        u = world - c
        r_plane.append(np.sqrt(u[:, 0] ** 2 + u[:, 2] ** 2).max())
        half_height.append(np.abs(u[:, 1]).max())
        centers.append(R.T @ (c - p))
    return _CircleData(np.array(centers), np.array(r_plane), np.array(half_height))

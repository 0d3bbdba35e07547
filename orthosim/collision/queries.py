"""Exact answers on the teeth's meshes for one run: every geometric question a step asks.

    queries = ExactQueries(collision_model)        # one per run: it owns FCL objects and their poses
    queries.intersects((13, 14), poses)            # pair = FDI keys; poses = FDI -> (4, 4)
    queries.distance((13, 14), poses)              # mm between the meshes, 0.0 when they intersect
    queries.penetration((13, 14), poses)           # mm the meshes interpenetrate, 0.0 when apart
    ExactQueries.of_meshes({13: mesh_a, 14: mesh_b})   # meshes alone, no sphere trees

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

Distances and intersection tests of a close pair go to its patches (`_Patch`): FCL objects of
only the faces of each tooth within `PATCH_REACH_MM` of the other, cut once and kept while the
two have moved (by the bound above) at most half that relative to each other. Any face within
reach - shift of the other tooth now was within reach at the cut, so an intersection, and a
distance d with d + shift <= reach, found on the patches is the whole meshes' own; a larger one
is asked of the whole meshes. Each kept triangle keeps its corners' coordinates, so FCL computes
the same numbers as on the whole meshes, in a tenth of the faces.

How deep an intersecting pair interpenetrates: the deepest point of either mesh's vertices and
edges inside the other (`geometry.penetration.edge_penetration_depth`, within 0.01 mm), so that
edges crossing edges or faces with no vertex inside read their real depth; meshes that are not
closed and consistently oriented have no reliable inside for it and get the vertex-based measure
(`geometry.meshquery.penetration_depth`).

Units: mm; poses local -> arch frame.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable, Mapping

import numpy as np

from orthosim.collision import patchcache
from orthosim.geometry import meshquery
from orthosim.geometry.lazymesh import LazyMesh
from orthosim.collision.model import CollisionModel

if TYPE_CHECKING:  # the queries read the meshes' arrays; trimesh loads only for a depth (meshquery, penetration)
    import trimesh

APART_MARGIN_MM = 1e-6  # a pair proved apart by less than this is tested with FCL all the same
PATCH_REACH_MM = 0.5  # a pair's patches hold every face within this of the other tooth when cut
WORLD_MEMO = 4  # pose sets whose sphere-tree node centres `world_centers` keeps


class _Patch:
    """The faces of two teeth near each other, cut at one relative pose, as two FCL objects.

    rel_ij / rel_ji: (3, 4) pose of i in j's frame and of j in i's, when cut. faces_i / faces_j: the
    kept faces' indices, nearest the other tooth first. obj_i / obj_j: FCL
    objects of the kept faces (each triangle with its corners' own coordinates, so triangle for
    triangle FCL computes the very numbers it computes on the whole meshes), None when either side
    kept none (`empty`).
    shift: mm, how far either tooth's vertices have moved relative to the other since the cut, at
    the poses last asked about.
    """

    def __init__(self, rel_ij, rel_ji, faces_i, faces_j, obj_i=None, obj_j=None):
        self.rel_ij, self.rel_ji, self.obj_i, self.obj_j = rel_ij, rel_ji, obj_i, obj_j
        self.faces_i, self.faces_j = faces_i, faces_j
        self.shift = 0.0

    @property
    def empty(self) -> bool:
        return self.obj_i is None

    def placed(self, pose_i: np.ndarray, pose_j: np.ndarray):
        meshquery.set_pose(self.obj_i, pose_i)
        meshquery.set_pose(self.obj_j, pose_j)
        return self.obj_i, self.obj_j


@dataclass(frozen=True, eq=False)
class MeshBody:
    """A body known by its mesh alone (local frame, mm)."""

    key: int
    mesh: trimesh.Trimesh


class MeshBodies:
    """Bodies known by their meshes alone, with no sphere trees: what exact queries read of a
    `CollisionModel` (`bodies[i].mesh`, `index`, `rho_max`), for callers that build no trees (the
    staging certificate and its independent verifier). Body i is the i-th mesh given."""

    def __init__(self, meshes: Mapping[int, trimesh.Trimesh]):
        self.bodies = [MeshBody(int(k), m) for k, m in meshes.items()]
        self.index = {b.key: i for i, b in enumerate(self.bodies)}
        # mm: each body's farthest vertex from its local origin, as `CollisionModel.rho_max`
        self.rho_max = np.array([np.linalg.norm(b.mesh.vertices, axis=1).max() for b in self.bodies])

    @property
    def keys(self) -> list[int]:
        return [b.key for b in self.bodies]


class ExactQueries:
    """Exact intersection, distance and interpenetration depth between the model's meshes.

    model: a `CollisionModel`, or `MeshBodies` for meshes alone (`of_meshes`; everything but
    `world_centers`, which places sphere-tree nodes). patch_reach_mm: the patches' reach (module
    docstring); 0 asks every question of the whole meshes, for a caller whose pairs move far
    between questions (the staging certificate's samples across a whole stage), where patches
    would be cut afresh for nearly every answer.
    """

    @classmethod
    def of_meshes(cls, meshes: Mapping[int, trimesh.Trimesh], **options) -> "ExactQueries":
        """Exact queries between meshes alone (key -> local-frame mesh, mm), no sphere trees built;
        options as for the constructor."""
        return cls(MeshBodies(meshes), **options)

    def __init__(self, model: "CollisionModel | MeshBodies", memo_size: int = 4096, patch_reach_mm: float = PATCH_REACH_MM):
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
        self._faces: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._trees: dict[int, object] = {}
        self._digests: dict[int, str] = {}
        # where cuts are read from and kept (`orthosim.collision.patchcache`); None: each is cut here.
        # A run keeps its first step's (`orthosim.runtime.stream`).
        self.patch_cache: patchcache.PatchCache | None = None
        self._world: OrderedDict[bytes, np.ndarray] = OrderedDict()

    @property
    def fcl_calls(self) -> int:
        """FCL queries asked so far: distances and intersection tests (remembered answers, and
        intersections an earlier distance proves false, cost none)."""
        return self.queries + self.collides

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
        """mm the two meshes interpenetrate at `poses` (on their vertices and edges, module doc;
        measured when FCL finds them intersecting); 0.0 when apart."""
        i, j = self._pair(pair)
        return self.body_penetration(i, poses[pair[0]], j, poses[pair[1]])

    def penetrations(self, pairs: Iterable[tuple[int, int]], poses: Mapping[int, np.ndarray]) -> dict[tuple[int, int], float]:
        """mm per pair of `pairs` whose meshes intersect at `poses`, in `pairs` order (pairs apart are
        left out; an intersecting pair whose depth reads 0, surfaces that only touch, is kept, at 0)."""
        out = {}
        for a, b in pairs:
            hit, depth = self._intersection(self.model.index[a], poses[a], self.model.index[b], poses[b])
            if hit:
                out[(a, b)] = depth
        return out

    def world_centers(self, poses: np.ndarray) -> np.ndarray:
        """`CollisionModel.world_centers(poses)` ((n, 4, 4) in body order), read-only, the last
        `WORLD_MEMO` pose sets remembered by their bytes: a step places its end poses for its
        detection and again for its contacts, and the next step starts from them."""
        key = _bytes(poses)
        W = self._world.get(key)
        if W is None:
            W = self.model.world_centers(poses)
            W.flags.writeable = False
            self._world[key] = W
            if len(self._world) > WORLD_MEMO:
                self._world.popitem(last=False)
        else:
            self._world.move_to_end(key)
        return W

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

    def body_intersects(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray) -> bool:
        M = _relative(pose_i, pose_j)
        if self._apart(i, j, M):
            return False
        self.collides += 1
        patch = self._patch(i, pose_i, j, pose_j, M, build=False)
        if patch is not None:
            return patch.empty is False and meshquery.collide(*patch.placed(pose_i, pose_j))[0]
        return meshquery.collide(self.placed(i, pose_i), self.placed(j, pose_j))[0]

    def body_distance(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray) -> float:
        key = (i, j, _bytes(pose_i), _bytes(pose_j))
        d = self._distances.get(key)
        if d is not None:
            self._distances.move_to_end(key)
            return d
        M = _relative(pose_i, pose_j)
        apart = self._apart(i, j, M)
        if not apart:
            self.collides += 1
        d = None
        patch = self._patch(i, pose_i, j, pose_j, M, build=True)
        if patch is not None and not patch.empty:
            d = meshquery.distance(*patch.placed(pose_i, pose_j), apart=apart)
            if d + patch.shift > self.patch_reach_mm:
                d = None  # the closest faces may lie outside the patches
        if d is None:
            d = meshquery.distance(self.placed(i, pose_i), self.placed(j, pose_j), apart=apart)
        self._remember(self._distances, key, d)
        if d > APART_MARGIN_MM:
            self._last_apart[(i, j)] = (M, d)
        self.queries += 1
        return d

    def proved_apart(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray) -> bool:
        """Whether the pair's last exact distance, less how far body i can have moved relative to
        body j since, leaves the meshes more than `APART_MARGIN_MM` apart at these poses."""
        return self._apart(i, j, _relative(pose_i, pose_j))

    def _apart(self, i: int, j: int, M: np.ndarray) -> bool:
        """`proved_apart` given body i's pose in body j's frame (3, 4)."""
        last = self._last_apart.get((i, j))
        if last is None:
            return False
        M0, d0 = last
        return bool(d0 - self._shift(i, M0, M) > APART_MARGIN_MM)

    def _shift(self, i: int, M0: np.ndarray, M: np.ndarray) -> float:
        """mm: how far any vertex of body i can lie between relative poses M0 and M (3, 4)."""
        dR, dt = (M[:, :3] - M0[:, :3]).ravel(), M[:, 3] - M0[:, 3]
        return math.sqrt(dR @ dR) * float(self.model.rho_max[i]) + math.sqrt(dt @ dt)

    def _patch(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray, M: np.ndarray, build: bool) -> "_Patch | None":
        """The pair's patches with `shift` set for these poses: kept while the teeth have moved
        relative to each other by at most half the reach since they were cut, cut afresh (build)
        otherwise; None when there are none and build is False, or without patches (reach 0). M:
        body i's pose in body j's frame."""
        if self.patch_reach_mm <= 0.0:
            return None
        N = _relative(pose_j, pose_i)
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

        Every point of a triangle lies within its corner radius (the farthest corner from its
        centroid) of the centroid, so a face within the reach of a face of the other mesh has its
        centroid within reach + its own corner radius + the other mesh's largest corner radius of
        that face's centroid: every face whose centroid is that close to one of the other's is kept."""
        faces = self._kept_faces(i, j, M, N)
        if not len(faces[0]) or not len(faces[1]):
            return _Patch(M, N, *faces)
        objects = [meshquery.fcl_object(_submesh(self.model.bodies[k].mesh, f), memo=False) for k, f in ((i, faces[0]), (j, faces[1]))]
        return _Patch(M, N, *faces, *objects)

    def _kept_faces(self, i: int, j: int, M: np.ndarray, N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The faces `_cut_patch` keeps, read from the patch cache when it holds this cut (and kept
        there when it does not), else cut here."""
        store = self.patch_cache
        if store is None:
            return self._faces_within_reach(i, j, M, N)
        key = store.key(self._mesh_digest(i), self._mesh_digest(j), M, N, self.patch_reach_mm)
        faces = store.get(key, *(len(self.model.bodies[k].mesh.faces) for k in (i, j)))
        if faces is None:
            faces = self._faces_within_reach(i, j, M, N)
            store.put(key, *faces)
        return faces

    def _faces_within_reach(self, i: int, j: int, M: np.ndarray, N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The cut itself (`_cut_patch`): each side's faces whose centroid lies within reach of a
        centroid of the other's, through a k-d tree of the other's centroids."""
        faces = []
        for a, b, R in ((i, j, M), (j, i, N)):
            centroids, radii = self._face_spheres(a)
            reach = self.patch_reach_mm + radii + self._face_spheres(b)[1].max()
            gap = self._centroid_tree(b).query(centroids @ R[:, :3].T + R[:, 3], distance_upper_bound=float(reach.max()))[0]
            kept = np.flatnonzero(gap <= reach)
            faces.append(kept[np.argsort(gap[kept], kind="stable")])  # nearest first: FCL's distance starts from faces 0
        return faces[0], faces[1]

    def _mesh_digest(self, i: int) -> str:
        known = self._digests.get(i)
        if known is None:
            mesh = self.model.bodies[i].mesh
            known = self._digests[i] = patchcache.mesh_digest(np.asarray(mesh.vertices), np.asarray(mesh.faces))
        return known

    def _face_spheres(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Body i's face centroids (f, 3) and corner radii (f,), mm, local frame."""
        known = self._faces.get(i)
        if known is None:
            mesh = self.model.bodies[i].mesh  # its arrays, as trimesh's `triangles` takes them (no trimesh made for it)
            corners = np.asarray(mesh.vertices, float)[np.asarray(mesh.faces)]  # (f, 3, 3)
            centroids = corners.mean(axis=1)
            radii = np.linalg.norm(corners - centroids[:, None, :], axis=2).max(axis=1)
            known = self._faces[i] = (centroids, radii * (1 + 1e-9) + 1e-9)  # outward rounding
        return known

    def _centroid_tree(self, i: int):
        tree = self._trees.get(i)
        if tree is None:
            from scipy.spatial import cKDTree

            tree = self._trees[i] = cKDTree(self._face_spheres(i)[0])
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
            depth = self._depth(i, pose_i, j, pose_j)
        return self._remember(self._depths, key, (hit, depth))

    def _depth(self, i: int, pose_i: np.ndarray, j: int, pose_j: np.ndarray) -> float:
        from orthosim.geometry.penetration import edge_penetration_depth  # numba: loaded on first use
        from orthosim.geometry.signeddistance import mesh_surface

        mesh_i, mesh_j = self.model.bodies[i].mesh, self.model.bodies[j].mesh
        if mesh_surface(mesh_i).closed and mesh_surface(mesh_j).closed:  # both have an inside
            return edge_penetration_depth(mesh_i, pose_i, mesh_j, pose_j)
        return meshquery.penetration_depth(mesh_i, pose_i, mesh_j, pose_j)

    # ------------------------------------------------------------------
    def _pair(self, pair) -> tuple[int, int]:
        return self.model.index[pair[0]], self.model.index[pair[1]]

    def _remember(self, memo: OrderedDict, key, value):
        memo[key] = value
        if len(memo) > self._memo_size:
            memo.popitem(last=False)
        return value


def _submesh(mesh: trimesh.Trimesh, faces: np.ndarray) -> LazyMesh:
    """The given faces of `mesh`, in that order, over only the vertices they use (each triangle
    keeps its corners' coordinates and order, so FCL computes the same numbers on it); only its
    arrays are read (FCL's BVH), so no trimesh is made."""
    used, corners = np.unique(np.asarray(mesh.faces)[faces], return_inverse=True)
    return LazyMesh(np.asarray(mesh.vertices)[used], corners.reshape(-1, 3))


def _relative(pose_i: np.ndarray, pose_j: np.ndarray) -> np.ndarray:
    """(3, 4): body i's pose in body j's local frame (rigid poses: the inverse is the transpose)."""
    Rj = pose_j[:3, :3]
    return np.concatenate([Rj.T @ pose_i[:3, :3], (Rj.T @ (pose_i[:3, 3] - pose_j[:3, 3]))[:, None]], axis=1)


def _bytes(T: np.ndarray) -> bytes:
    return np.ascontiguousarray(T, dtype=float).tobytes()

"""Exact queries on triangle meshes: python-fcl BVH objects, their poses, intersection and distance.

Geometry only, with no detector behind it: the dental model places parametric teeth with it
(`MeshQuery`), and collision detection answers a run's exact questions through it
(`orthosim.collision.queries.ExactQueries`, which owns one FCL object per tooth and its pose).
FCL tests surfaces only: a mesh wholly inside another is reported as not colliding.
"""

from __future__ import annotations

import hashlib
import threading
import weakref
from collections import OrderedDict
from typing import TYPE_CHECKING

import fcl
import numpy as np

if TYPE_CHECKING:  # FCL takes a mesh's two arrays: a run's first steps never import trimesh (orthosim.geometry.lazymesh)
    import trimesh

# BVHs kept per process, by mesh content, for the next object of the same mesh (least recently
# used dropped beyond this many): a batch worker runs model after model, mostly the same teeth.
# One full dentition: a run holds its teeth's BVHs anyway (about 570 bytes a triangle, 9-26 MB
# for a 16,000-45,000-triangle real tooth), so the memo adds little to a run's peak memory.
BVH_MEMO_SIZE = 32
_BVHS: OrderedDict[tuple, fcl.BVHModel] = OrderedDict()
_BVHS_LOCK = threading.Lock()
bvh_builds = 0  # BVHs built by this process for the memo (the rest came from it; patches are not counted)


def fcl_object(mesh: trimesh.Trimesh, memo: bool = True) -> fcl.CollisionObject:
    """A python-fcl BVH (OBB-RSS) collision object of a mesh in its local frame (mm).

    Each call gives an object of its own (its pose is its state), around a BVH shared with every
    other object of a mesh with the same vertices and faces (bit for bit): building it is most of
    a run's set-up. Sharing is safe in python-fcl: after `endModel` nothing changes the geometry
    but the local bounding box each new object computes (to the same values), an object keeps a
    reference to its Python geometry and frees only its own C++ object, and the C++ BVH is freed
    by the Python geometry alone, once no object or memo entry holds it.
    memo=False: a throw-away mesh (a patch of a tooth) whose BVH is built afresh and kept out of
    the memo, so it neither costs a digest nor pushes a whole tooth's BVH out."""
    return fcl.CollisionObject(bvh(mesh) if memo else _build_bvh(mesh), fcl.Transform())


def bvh(mesh: trimesh.Trimesh) -> fcl.BVHModel:
    """The mesh's python-fcl BVH (OBB-RSS), from this process's memo when one of the same content was built."""
    global bvh_builds
    vertices = np.ascontiguousarray(mesh.vertices, dtype=float)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int32)
    digest = hashlib.blake2b(vertices.tobytes(), digest_size=20)
    digest.update(faces.tobytes())
    key = (vertices.shape, faces.shape, digest.digest())
    with _BVHS_LOCK:
        g = _BVHS.get(key)
        if g is not None:
            _BVHS.move_to_end(key)
            return g
        g = _build_bvh(mesh)
        bvh_builds += 1
        _BVHS[key] = g
        while len(_BVHS) > BVH_MEMO_SIZE:
            _BVHS.popitem(last=False)
        return g


def _build_bvh(mesh: trimesh.Trimesh) -> fcl.BVHModel:
    vertices = np.ascontiguousarray(mesh.vertices, dtype=float)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int32)
    g = fcl.BVHModel()
    g.beginModel(len(vertices), len(faces))
    g.addSubModel(vertices, faces)
    g.endModel()
    return g


def forget_bvhs() -> None:
    """Empty this process's BVH memo (objects made already keep theirs)."""
    with _BVHS_LOCK:
        _BVHS.clear()


def set_pose(obj: fcl.CollisionObject, T: np.ndarray) -> None:
    """Place an FCL object by a (4, 4) local -> arch frame pose (mm)."""
    T = np.asarray(T, float)
    obj.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))


def collide(a: fcl.CollisionObject, b: fcl.CollisionObject, all_contacts: bool = False):
    """(touching, contacts): whether the placed meshes' surfaces intersect; with all_contacts, the
    (k, 3) contact points (mm, arch frame) and (k, 2) face index pairs of every intersecting
    triangle pair."""
    if not all_contacts:
        res = fcl.CollisionResult()
        fcl.collide(a, b, fcl.CollisionRequest(), res)
        return bool(res.is_collision), None
    res = fcl.CollisionResult()
    fcl.collide(a, b, fcl.CollisionRequest(num_max_contacts=10**7, enable_contact=True), res)
    pts = np.array([c.pos for c in res.contacts], float).reshape(-1, 3)
    faces = np.array([(c.b1, c.b2) for c in res.contacts], np.int64).reshape(-1, 2)
    return bool(res.is_collision), (pts, faces)


def distance(a: fcl.CollisionObject, b: fcl.CollisionObject, apart: bool = False) -> float:
    """mm between the placed meshes' surfaces; 0 when they intersect. apart: the caller has proved
    the surfaces apart, so the intersection test that otherwise comes first is skipped."""
    if not apart and collide(a, b)[0]:
        return 0.0
    res = fcl.DistanceResult()
    return max(float(fcl.distance(a, b, fcl.DistanceRequest(), res)), 0.0)


def penetration_depth(mesh_a: trimesh.Trimesh, pose_a: np.ndarray, mesh_b: trimesh.Trimesh, pose_b: np.ndarray) -> float:
    """mm, vertex-based estimate of how deep two posed meshes interpenetrate.

    The largest depth of any vertex of one mesh inside the other (trimesh signed distance, both
    ways), 0 when no vertex is inside. Vertex-based: it underestimates edge-edge interpenetration
    between coarse meshes, and it sees a mesh wholly inside the other (unlike FCL).
    """
    worst = 0.0
    for m1, T1, m2, T2 in ((mesh_a, pose_a, mesh_b, pose_b), (mesh_b, pose_b, mesh_a, pose_a)):
        # m1's vertices in m2's local frame
        M = np.linalg.inv(np.asarray(T2, float)) @ np.asarray(T1, float)
        v = m1.vertices @ M[:3, :3].T + M[:3, 3]
        lo, hi = m2.bounds
        near = np.all((v >= lo) & (v <= hi), axis=1)
        if near.any():
            worst = max(worst, _deepest_inside(m2, v[near]))
    return worst


# Signed distance (a ray-cast inside test per point) costs ~1 ms a point without embree; two dense
# real teeth side by side put thousands of vertices in each other's bounding boxes. A vertex d mm
# inside a mesh lies within d + (longest edge) of one of its vertices, so only vertices that close
# to the other mesh's vertices are measured; when the deepest found comes near the search radius a
# deeper vertex could have been left out, and every vertex is measured instead.
_NEAR_MM = 1.0
_FRESH: dict[int, tuple] = {}  # id(mesh) -> (weak reference to it, fresh copy)


def _deepest_inside(mesh: trimesh.Trimesh, points: np.ndarray) -> float:
    """mm, the largest depth of `points` inside `mesh` (0 when none is inside)."""
    import trimesh
    from scipy.spatial import cKDTree

    # A mesh that came through pickle (a child process's dentition) can carry a stale spatial
    # index that trimesh's closest-point query trips on (IndexError); a copy built from its arrays
    # in this process has none. Made once per mesh object, kept beside it (not on it, so it is
    # never pickled with it).
    entry = _FRESH.get(id(mesh))
    if entry is None or entry[0]() is not mesh:
        entry = _FRESH[id(mesh)] = (weakref.ref(mesh), trimesh.Trimesh(mesh.vertices, mesh.faces, process=False))
    mesh = entry[1]
    reach = _NEAR_MM + float(mesh.edges_unique_length.max())
    gap, _ = cKDTree(mesh.vertices).query(points, distance_upper_bound=reach)
    close = points[np.isfinite(gap)]
    deepest = float(trimesh.proximity.signed_distance(mesh, close).max(initial=0.0)) if len(close) else 0.0
    if deepest >= _NEAR_MM and len(close) < len(points):
        deepest = float(trimesh.proximity.signed_distance(mesh, points).max(initial=0.0))  # positive inside
    return deepest


class MeshQuery:
    """Exact queries between any two of a set of meshes under any poses, FCL objects built once.

    Used where the model itself must be exact rather than fast: placing parametric teeth so that
    neighbours just touch, and checking a model in tests.
    """

    def __init__(self, meshes: dict[int, trimesh.Trimesh]):
        self._objects = {key: fcl_object(mesh) for key, mesh in meshes.items()}

    def _placed(self, key: int, pose: np.ndarray) -> fcl.CollisionObject:
        obj = self._objects[key]
        set_pose(obj, pose)
        return obj

    def intersects(self, a: int, pose_a: np.ndarray, b: int, pose_b: np.ndarray) -> bool:
        return collide(self._placed(a, pose_a), self._placed(b, pose_b))[0]

    def distance(self, a: int, pose_a: np.ndarray, b: int, pose_b: np.ndarray) -> float:
        """mm between the surfaces; 0.0 when they intersect."""
        return distance(self._placed(a, pose_a), self._placed(b, pose_b))

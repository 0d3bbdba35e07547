"""The collision model of a dentition: everything detectors need that never changes during a run.

Built once (MuJoCo's mjModel in our STYLE): per tooth its sphere tree, its bounding circle data and
its mesh. Exact queries on the meshes re-pose FCL objects: that is a run's state, kept by
`queries.ExactQueries`, not here. The sphere trees of all teeth are concatenated level by
level into global arrays, so a descent can handle the node pairs of every tooth pair at once with
numpy. A step's state is just the poses (dict FDI -> (4, 4) local -> arch frame, mm).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Callable, Mapping

import numpy as np

from orthosim.spheretree.tree import SphereTree
from orthosim.collision.contract import CollisionError

if TYPE_CHECKING:  # a run's first step reads only the meshes' arrays: trimesh and scipy load when the circles ask
    import trimesh


# mm added to radii in float32 tests: float32 rounding of arch-frame coordinates (|x| < 100 mm)
# is below 1e-5 mm, so this keeps every test conservative.
FLOAT32_MARGIN_MM = 1e-4


@dataclass(frozen=True, eq=False)
class Body:
    """One rigid body of the collision model (a tooth): local mesh, sphere tree, rest pose."""

    key: int  # FDI number for teeth (any int for generic models)
    mesh: trimesh.Trimesh  # local frame, mm
    tree: SphereTree
    rest_pose: np.ndarray  # (4, 4)
    # (k, 3) local points the bounding circle must hold: the crown, as in the paper (its circles
    # "do not take into account the shape of the teeth's root"); None: every mesh vertex
    circle_points: np.ndarray | None = None


@dataclass(eq=False)
class CollisionModel:
    """Sphere trees, bounding circles and meshes of every body, built once; never changed by a query.

    The trees are flattened body-major into padded arrays so that one batched matrix product
    places every node of every tooth, and the placed coordinates need no transposing: body i owns
    the flat slots [i * stride, i * stride + width), stride = 3 * width, node `f = i * stride + j`
    with j the node's position in its own tree counted level by level from the root (root j = 0,
    leaves last). World coordinates (`world_centers`) are laid out [body][axis][j], so the x, y, z
    of node f sit at f, f + width, f + 2 width of one flat array: three views of it
    (`axes`) gather like contiguous per-axis arrays. Unused slots are never reached.
      centers (n_bodies, width, 3) mm, local frame of the body; centers_flat (n * stride, 3);
      radii, rho (n * stride,) mm: radius, and |centre| (distance from the local origin, for the
        rotation bound);
      child_start, child_count (n * stride,): flat index range of a node's children (0 at leaves);
      leaf_index (n * stride,): index of a leaf in its tree's leaf level, -1 for inner nodes.
    """

    bodies: list[Body]
    centers: np.ndarray = field(init=False)
    radii: np.ndarray = field(init=False)
    rho: np.ndarray = field(init=False)
    child_start: np.ndarray = field(init=False)
    child_count: np.ndarray = field(init=False)
    leaf_index: np.ndarray = field(init=False)
    width: int = field(init=False)
    stride: int = field(init=False)
    index: dict[int, int] = field(init=False)

    def __post_init__(self):
        if not self.bodies:
            raise CollisionError(None, "collision model", "no teeth given", "pass at least two teeth")
        self.index = {b.key: i for i, b in enumerate(self.bodies)}
        sizes = [sum(len(r) for r in b.tree.radii) for b in self.bodies]
        n, w = len(self.bodies), max(sizes)
        self.width, self.stride = w, 3 * w
        N = n * self.stride
        self.centers = np.zeros((n, w, 3))
        self.centers_flat = np.zeros((N, 3))
        self.radii = np.zeros(N)
        self.child_start = np.zeros(N, np.int64)
        self.child_count = np.zeros(N, np.int64)
        self.leaf_index = np.full(N, -1, np.int64)
        for i, b in enumerate(self.bodies):
            tree = b.tree
            level_start = np.concatenate([[0], np.cumsum([len(r) for r in tree.radii])])
            base = i * self.stride
            c = np.concatenate(tree.centers)
            self.centers[i, : sizes[i]] = c
            self.centers_flat[base : base + sizes[i]] = c
            self.radii[base : base + sizes[i]] = np.concatenate(tree.radii)
            for k in range(tree.depth - 1):
                off = tree.child_offsets(k + 1)
                sl = slice(base + level_start[k], base + level_start[k + 1])
                self.child_start[sl] = base + level_start[k + 1] + off[:-1]
                self.child_count[sl] = np.diff(off)
            self.leaf_index[base + level_start[-2] : base + level_start[-1]] = np.arange(tree.n_leaves)
            # an inner node without children holds no face (faces live in last-level leaves):
            # it can never hold a contact, so give it a radius no test accepts
            used = np.arange(base, base + level_start[-2])
            self.radii[used[self.child_count[used] == 0]] = -1e6
        self.rho = np.linalg.norm(self.centers_flat, axis=1)
        self._centers_T = np.ascontiguousarray(np.transpose(self.centers, (0, 2, 1)))  # (n, 3, width)
        self.radii32 = (self.radii + FLOAT32_MARGIN_MM).astype(np.float32)
        # what the descent compares to choose which node to split: the radius, -1 for leaves
        self.split_key = np.where(self.child_count > 0, self.radii, -1.0).astype(np.float32)
        self.rho_max = np.array([np.linalg.norm(b.mesh.vertices, axis=1).max() for b in self.bodies])
        self._rest = np.stack([b.rest_pose for b in self.bodies]).astype(float)  # (n, 4, 4)
        self._keys = np.array([b.key for b in self.bodies], dtype=np.int64)
        self._key_order = np.argsort(self._keys)

    @cached_property
    def _circle(self) -> "_CircleData":
        """The bounding circles' data (`circles`, detector 1), worked out when that detector first
        asks: a convex hull and a smallest circle per tooth that no other detector needs, so a run
        with another detector does not wait for them before its first step."""
        return _circle_data(self.bodies)

    def roots(self, body_idx: np.ndarray) -> np.ndarray:
        """Flat node index of the root of each body."""
        return np.asarray(body_idx, np.int64) * self.stride

    def body_of(self, nodes: np.ndarray) -> np.ndarray:
        return nodes // self.stride

    def world_centers(self, poses: np.ndarray) -> np.ndarray:
        """(n_bodies * stride,) mm: every node centre in the arch frame under poses (n, 4, 4), laid
        out [body][axis][j] (see the class docstring; `axes` and `xyz` read it)."""
        out = np.matmul(poses[:, :3, :3], self._centers_T)
        out += poses[:, :3, 3, None]
        return out.reshape(-1)

    def axes(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x, y, z views of a [body][axis][j] flat array, each indexed by flat node index."""
        w = self.width
        return flat, flat[w:], flat[2 * w :]

    def xyz(self, flat: np.ndarray, nodes: np.ndarray) -> np.ndarray:
        """(m, 3) coordinates of the given flat nodes from a [body][axis][j] flat array."""
        x, y, z = self.axes(flat)
        return np.stack([x[nodes], y[nodes], z[nodes]], axis=1)

    def node_values(self, per_node: np.ndarray) -> np.ndarray:
        """(n * stride,) flat array of an (n, width) per-node quantity (zeros in unused slots)."""
        out = np.zeros((len(self.bodies), self.stride))
        out[:, : self.width] = per_node
        return out.reshape(-1)

    @property
    def depth(self) -> int:
        """Levels of the deepest tree."""
        return max(b.tree.depth for b in self.bodies)

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
        rows = pairs.tolist() if isinstance(pairs, np.ndarray) and pairs.ndim == 2 else pairs
        if isinstance(rows, (list, tuple)):  # the usual case, a few dozen pairs: dictionary look-ups
            index = self.index
            try:
                idx = [(index[a], index[b]) for a, b in rows if a != b]
            except (KeyError, TypeError, ValueError):
                idx = None
            if idx is not None and len(idx) == len(rows):
                return np.array(idx, dtype=np.int64).reshape(-1, 2)
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        same = pairs[:, 0] == pairs[:, 1]
        if same.any():
            raise CollisionError(None, f"pair ({pairs[same][0, 0]}, {pairs[same][0, 0]})", "pairs a tooth with itself",
                                 "list pairs of two different teeth")
        keys, order = self._keys, self._key_order
        pos = np.clip(np.searchsorted(keys[order], pairs), 0, len(keys) - 1)
        idx = order[pos]
        missing = keys[idx] != pairs
        if missing.any():
            self._idx(int(pairs[missing][0]))  # raises, naming the tooth
        return idx.astype(np.int64).reshape(-1, 2)

    def pose_array(self, poses: Mapping[int, np.ndarray], keys=None) -> np.ndarray:
        """(n_bodies, 4, 4) poses in body order; bodies missing from `poses` keep their rest pose."""
        out = self._rest.copy()
        for k, T in poses.items():
            i = self.index.get(int(k))
            if i is not None:
                out[i] = T
        return out

    @classmethod
    def from_dentition(cls, dentition, tree_builder: Callable[[trimesh.Trimesh], SphereTree] | None = None,
                       trees: Mapping[int, SphereTree] | None = None) -> "CollisionModel":
        """Model of every present tooth; trees from `trees` when given, else `tree_builder(tooth.mesh)`.

        With neither, the project's cached builder (`orthosim.spheretree.cached_sphere_trees`, method
        "fit", its default branching x 4 levels) builds or loads them all at once, over every core.
        """
        given = dict(trees or {})
        todo = [n for n in dentition.fdis if n not in given]
        with _tree_bar(len(todo)) as bar:
            if tree_builder is None:
                from orthosim.spheretree import cached_sphere_trees

                built = cached_sphere_trees([dentition.teeth[n].mesh for n in todo], progress=bar.update)
            else:
                built = []
                for n in todo:
                    built.append(tree_builder(dentition.teeth[n].mesh))
                    bar.update(1)
        given.update(zip(todo, built))
        bodies = [Body(n, dentition.teeth[n].mesh, given[n], np.asarray(dentition.teeth[n].rest_pose, float),
                       dentition.teeth[n].crown_vertices) for n in dentition.fdis]
        return cls(bodies)


def _tree_bar(total: int):
    """A bar over the teeth whose trees are built, on a terminal; a first run on a machine builds
    them (seconds for 28 smooth teeth, on every core), cached ones load in milliseconds, and the
    bar only appears once the work has lasted a second. Elsewhere nothing, and tqdm is not imported."""
    import sys

    if not sys.stderr.isatty():
        return contextlib.nullcontext(_NoBar())
    from tqdm import tqdm

    return tqdm(total=total, desc="sphere trees", unit="tooth", delay=1.0, leave=False)


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass


def default_tree_builder() -> Callable[[trimesh.Trimesh], SphereTree]:
    """The project's cached sphere-tree builder (`orthosim.spheretree`, method "fit", its default branching x 4 levels)."""
    from orthosim.spheretree import cached_sphere_tree

    return lambda mesh: cached_sphere_tree(mesh)


@dataclass(frozen=True, eq=False)
class _CircleData:
    center_local: np.ndarray  # (n, 3) mm: the point whose projection is the circle centre
    r_plane: np.ndarray  # (n,) mm: radius of the projection at the rest orientation
    half_height: np.ndarray  # (n,) mm: largest vertical offset from the centre at rest


def _circle_data(bodies: list[Body]) -> _CircleData:
    """Per body, the smallest circle holding the x-z projection of its circle points at rest."""
    from scipy.spatial import ConvexHull
    from trimesh.nsphere import minimum_nsphere

    centers, r_plane, half_height = [], [], []
    for b in bodies:
        R, p = b.rest_pose[:3, :3], b.rest_pose[:3, 3]
        points = b.mesh.vertices if b.circle_points is None else b.circle_points
        world = np.asarray(points, float) @ R.T + p
        hull = world[np.unique(ConvexHull(world[:, [0, 2]]).vertices)]
        centre_xz, _ = minimum_nsphere(hull[:, [0, 2]])
        c = np.array([centre_xz[0], 0.5 * (world[:, 1].min() + world[:, 1].max()), centre_xz[1]])
        u = world - c
        r_plane.append(np.sqrt(u[:, 0] ** 2 + u[:, 2] ** 2).max())
        half_height.append(np.abs(u[:, 1]).max())
        centers.append(R.T @ (c - p))
    return _CircleData(np.array(centers), np.array(r_plane), np.array(half_height))

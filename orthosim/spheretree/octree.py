"""The octree sphere-tree builder: equal spheres per level around the cells of an octree (Hubbard's).

The tooth's bounding cube is split in 8 level after level; a node is a cell that holds surface
triangles, and its sphere is centred on the cell. All spheres of a level have one radius, which is
what the paper wants for showing contact areas (equal spheres read as an even grid of dots).
Each triangle belongs to the leaf cell that holds its centroid; a node's radius is its cell's half
diagonal (one value per level), grown only for the few cells where a triangle of the node pokes out
of that sphere (triangles larger than the cell, on coarse meshes), so coverage is exact. Cells that hold only
interior, no surface, are not nodes: a descent needs the surface, and the paper's octree trees
approximate the surface too. Coordinates in mm, in the mesh's frame.
"""

from __future__ import annotations

import numpy as np

from orthosim.spheretree.tree import SphereTree

MAX_OCTREE_DEPTH = 12  # 2**11 cells per axis at the leaves: far below any triangle's size


def _morton(ijk: np.ndarray, bits: int) -> np.ndarray:
    """(n, 3) non-negative int cell indices -> (n,) int64 Morton codes (x, y, z bits interleaved)."""
    code = np.zeros(len(ijk), dtype=np.int64)
    for b in range(bits):
        for axis in range(3):
            code |= ((ijk[:, axis] >> b) & 1).astype(np.int64) << (3 * b + (2 - axis))
    return code


def _unmorton(code: np.ndarray, bits: int) -> np.ndarray:
    ijk = np.zeros((len(code), 3), dtype=np.int64)
    for b in range(bits):
        for axis in range(3):
            ijk[:, axis] |= ((code >> (3 * b + (2 - axis))) & 1) << b
    return ijk


def build_octree_tree(vertices: np.ndarray, faces: np.ndarray, depth: int = 6) -> SphereTree:
    """Octree sphere tree of a mesh ((n, 3) float64 mm, (m, 3) int), `depth` levels with the root.

    Level k has up to 8**k spheres centred on occupied cells of side side / 2**k (side: the
    bounding cube's edge), of radius the cell's half diagonal unless a triangle needs more.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    side = float((hi - lo).max()) * (1 + 1e-9) or 1.0
    origin = 0.5 * (lo + hi) - 0.5 * side
    bits = depth - 1
    n_cells = 1 << bits
    tri = vertices[faces]  # (F, 3, 3)
    cell = np.floor((tri.mean(axis=1) - origin) / (side / n_cells)).astype(np.int64).clip(0, n_cells - 1)
    leaf_code = _morton(cell, bits)
    codes, node_of_face = [], []
    for k in range(depth):
        # Morton order sorts every level by parent: a parent's code is its child's shifted by 3.
        level_codes, inverse = np.unique(leaf_code >> (3 * (bits - k)), return_inverse=True)
        codes.append(level_codes)
        node_of_face.append(inverse.astype(np.int64))
    centers, radii, parents = [], [], []
    for k in range(depth):
        size = side / (1 << k)
        c = origin + (_unmorton(codes[k], k) + 0.5) * size
        far = np.sqrt(((tri - c[node_of_face[k]][:, None, :]) ** 2).sum(axis=2).max(axis=1))
        need = np.zeros(len(c))
        np.maximum.at(need, node_of_face[k], far)
        centers.append(c)
        radii.append(np.maximum(0.5 * np.sqrt(3.0) * size, need))
        parents.append(np.searchsorted(codes[k - 1], codes[k] >> 3) if k else np.array([-1], dtype=np.int64))
    return SphereTree(
        branching=8,
        centers=tuple(centers),
        radii=tuple(radii),
        parents=tuple(np.asarray(p, dtype=np.int64) for p in parents),
        leaf_of_face=node_of_face[-1],
        method="octree",
    )

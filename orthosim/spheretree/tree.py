"""The sphere tree of one tooth: a hierarchy of bounding spheres stored level by level as arrays.

Level 0 holds the root sphere; level k holds up to branching**k spheres. Nodes of a level are
sorted by parent, so the children of node i of level k-1 are the slice
`child_offsets[k][i] : child_offsets[k][i + 1]` of level k: a descent can gather the children of
many nodes at once with numpy, without Python loops over nodes.

Coordinates are in the tooth's local frame (mm, see `orthosim.model.tooth`); a pose maps them to the arch
frame. Invariants every builder must keep (checked by `validate`):
  - conservative: every surface triangle of the tooth lies inside its leaf sphere, and inside that
    leaf's parent, and so on up to the root, so a descent that prunes a node never loses a
    contact below it;
  - `leaf_of_face[f]` names the leaf that holds all three vertices of face f.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class SphereTree:
    """A tooth's bounding-sphere hierarchy in its own frame (mm): each level's sphere centres
    ((n_k, 3) float64) and radii ((n_k,) float64), each sphere's parent in the level above, and
    which leaf sphere covers each mesh face. Every sphere encloses the part of the mesh its
    leaves cover, so two trees that do not overlap mean two teeth that do not touch; `branching`
    children per sphere (the paper's octree: 1, 8, 64, 512 spheres by level); `method`: how the
    spheres were fitted.
    """

    branching: int
    centers: tuple[np.ndarray, ...]  # per level: (n_k, 3) float64, mm, local frame
    radii: tuple[np.ndarray, ...]  # per level: (n_k,) float64, mm
    parents: tuple[np.ndarray, ...]  # per level: (n_k,) int64 index into level k-1; level 0: [-1]
    leaf_of_face: np.ndarray  # (n_faces,) int64: index into the leaf level
    method: str = ""

    @property
    def depth(self) -> int:
        """Number of levels, the root included (the paper's depth 4: 1, 8, 64, 512)."""
        return len(self.centers)

    @property
    def leaf_centers(self) -> np.ndarray:
        return self.centers[-1]

    @property
    def leaf_radii(self) -> np.ndarray:
        return self.radii[-1]

    @property
    def n_leaves(self) -> int:
        return len(self.radii[-1])

    def child_offsets(self, level: int) -> np.ndarray:
        """(n_{level-1} + 1,) CSR offsets: children of node i of level-1 are offsets[i]:offsets[i+1]."""
        n_parents = len(self.radii[level - 1])
        counts = np.bincount(self.parents[level], minlength=n_parents)
        return np.concatenate([[0], np.cumsum(counts)])

    def validate(self, vertices: np.ndarray | None = None, faces: np.ndarray | None = None, tol: float = 1e-9) -> None:
        """Raise ValueError when the layout or (given the mesh) the coverage invariant is broken."""
        if len(self.radii[0]) != 1:
            raise ValueError("level 0 must hold exactly one root sphere")
        for k in range(1, self.depth):
            p = self.parents[k]
            if len(p) and (np.any(np.diff(p) < 0) or p.min() < 0 or p.max() >= len(self.radii[k - 1])):
                raise ValueError(f"level {k}: nodes must be sorted by a valid parent index")
            if np.any(np.bincount(p, minlength=len(self.radii[k - 1])) > self.branching):
                raise ValueError(f"level {k}: a node has more than {self.branching} children")
        if vertices is None or faces is None:
            return
        # Each face inside its leaf, and inside every ancestor of that leaf.
        vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        faces = np.ascontiguousarray(faces, dtype=np.int64)
        node = np.asarray(self.leaf_of_face, dtype=np.int64)
        if len(node) != len(faces) or (len(node) and (node.max() >= self.n_leaves or node.min() < -self.n_leaves)):
            raise ValueError("leaf_of_face must name one existing leaf per face")
        if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
            raise ValueError("faces refer to vertices that do not exist")
        for k in range(self.depth - 1, -1, -1):
            outside = _faces_outside(vertices, faces, node, np.ascontiguousarray(self.centers[k], dtype=np.float64),
                                     np.ascontiguousarray(self.radii[k], dtype=np.float64), float(tol))
            if outside:
                raise ValueError(f"level {k}: {outside} faces not inside their covering sphere")
            if k:
                node = self.parents[k][node]


_FACE_BLOCK = 65_536  # faces checked at once: (b, 3, 3) float64 temporaries of a few MB


def _faces_outside(vertices, faces, node, centers, radii, tol) -> int:
    """How many faces have a vertex farther than radius + tol from the centre of their node (NaN
    counts as outside). In numpy, a block of faces at a time: the sphere-tree cache checks every
    tree it loads this way (`spheretree.cache`), and a first run should not wait for numba's
    compiler for a yes/no check. Squared distances are summed x, then y, then z."""
    count = 0
    for lo in range(0, faces.shape[0], _FACE_BLOCK):
        f = faces[lo:lo + _FACE_BLOCK]
        n = node[lo:lo + _FACE_BLOCK]
        e = vertices[f] - centers[n][:, None, :]  # (b, 3 corners, 3 axes)
        d = e[:, :, 0] * e[:, :, 0] + e[:, :, 1] * e[:, :, 1] + e[:, :, 2] * e[:, :, 2]
        limit = (radii[n] + tol) * (radii[n] + tol)
        count += int(np.count_nonzero(~np.all(d <= limit[:, None], axis=1)))
    return count


"""Choosing and running a sphere-tree builder: one entry point for every caller, with checked options.

`build_sphere_tree(mesh, method, branching, depth)` builds a tree with the octree builder
(`orthosim.spheretree.octree`, equal spheres per level, the paper's comparison) or the optimising
builder (`orthosim.spheretree.fit`, the default: tight, deep-set spheres). Requests a user can get
wrong (unknown method, a branching the octree cannot have, a depth that makes no sense) raise
`SphereTreeError` naming the option and the fix.
"""

from __future__ import annotations

import numpy as np

from orthosim.errors import SphereTreeError
from orthosim.spheretree.defaults import FIT_BRANCHING
from orthosim.spheretree.octree import MAX_OCTREE_DEPTH, build_octree_tree
from orthosim.spheretree.tree import SphereTree

METHODS = ("fit", "octree")
MAX_FIT_DEPTH = 8
DEPTH = 4  # levels with the root, as the paper's trees


def default_branching(method: str, branching: int | None = None) -> int:
    """`branching` when one is asked, else the one `method` builds by default (an octree splits
    every cell in 8; the optimising builder `FIT_BRANCHING`)."""
    if branching is not None:
        return branching
    return 8 if method == "octree" else FIT_BRANCHING


def mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3) float64 mm, faces (m, 3) int64) of a trimesh mesh or a (vertices, faces) pair."""
    if isinstance(mesh, tuple):
        vertices, faces = mesh
    else:
        vertices, faces = mesh.vertices, mesh.faces
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise SphereTreeError(None, "mesh", "needs (n, 3) vertices and at least one (3,) triangle", "pass a triangle mesh")
    return vertices, faces


def check_request(method: str, branching: int, depth: int, where: str | None = None) -> None:
    """Raise `SphereTreeError` unless the builder can honour (method, branching, depth)."""
    if method not in METHODS:
        raise SphereTreeError(where, "method", f"unknown sphere-tree method {method!r}", f"use one of {', '.join(METHODS)}")
    if method == "octree" and branching != 8:
        raise SphereTreeError(where, "branch", f"an octree splits every cell in 8, not {branching}", "use --branch 8 with --method octree")
    if not 2 <= branching <= 64:
        raise SphereTreeError(where, "branch", f"branching factor {branching} is out of range", "use 2 to 64 (the paper: 8)")
    top = MAX_OCTREE_DEPTH if method == "octree" else MAX_FIT_DEPTH
    if not 1 <= depth <= top:
        raise SphereTreeError(where, "depth", f"depth {depth} is out of range for {method}", f"use 1 to {top} levels, the root included (the paper: 4)")


def build_sphere_tree(mesh, method: str = "fit", branching: int | None = None, depth: int = DEPTH) -> SphereTree:
    """The sphere tree of a closed tooth mesh (trimesh or (vertices, faces), mm), in the mesh's frame.

    `depth` counts levels with the root (4: 1, 9, 81, up to 729 leaves for branching 9);
    `branching` defaults to `default_branching(method)`.
    """
    branching = default_branching(method, branching)
    check_request(method, branching, depth)
    vertices, faces = mesh_arrays(mesh)
    if method == "octree":
        return build_octree_tree(vertices, faces, depth)
    # imported here: the optimising builder pulls numba and scipy, which a process that only loads
    # cached trees (spheretree.cache, through this module's checks) does without
    from orthosim.spheretree.fit import build_fit_tree

    return build_fit_tree(vertices, faces, branching, depth)

"""On-disk cache of sphere trees, keyed by the mesh's content and the build request.

A tree depends only on the mesh's vertices and faces, the method, branching, depth and the builder's
code, so the key is a SHA-256 of exactly those (plus `BUILDER_VERSION`, bumped whenever a builder
changes its output). A hit loads one small .npz in milliseconds; a miss builds and writes the file
atomically, so two processes racing on the same tree both end with a whole file. The folder is
`$ORTHOSIM_CACHE` if set, else `~/.cache/orthosim/spheretrees`.

Left and right teeth are mirror images (x -> -x in the local frame, see `orthosim.tooth`), and a
mirror maps a conservative tree to a conservative tree exactly (negating a float is exact), so a
mesh and its mirror share one entry: the tree is built and stored for whichever of the two has the
smaller key, and mirrored on the way out for the other. A full dentition costs half the builds.
"""

from __future__ import annotations

import hashlib
import os
import zipfile
from pathlib import Path

import numpy as np

from ..atomic import atomic_path
from .build import build_sphere_tree, check_request, mesh_arrays
from .tree import SphereTree

BUILDER_VERSION = 5


def default_cache_dir() -> Path:
    env = os.environ.get("ORTHOSIM_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "orthosim" / "spheretrees"


def cache_key(vertices: np.ndarray, faces: np.ndarray, method: str, branching: int, depth: int) -> str:
    """Hex SHA-256 of the mesh's bytes (float64 vertices, int64 faces) and the build request."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
    h.update(f"|{method}|{branching}|{depth}|v{BUILDER_VERSION}|{len(vertices)}|{len(faces)}".encode())
    return h.hexdigest()


def save_tree(tree: SphereTree, path: str | Path) -> None:
    """Write a tree as .npz (atomically): per level c{k}, r{k}, p{k}, plus leaf_of_face."""
    arrays = {"branching": np.int64(tree.branching), "method": np.str_(tree.method), "leaf_of_face": tree.leaf_of_face}
    for k in range(tree.depth):
        arrays[f"c{k}"], arrays[f"r{k}"], arrays[f"p{k}"] = tree.centers[k], tree.radii[k], tree.parents[k]
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)


def load_tree(path: str | Path) -> SphereTree:
    """Read a tree written by `save_tree`."""
    with np.load(path, allow_pickle=False) as z:
        depth = sum(1 for name in z.files if name.startswith("c"))
        return SphereTree(
            branching=int(z["branching"]),
            centers=tuple(z[f"c{k}"] for k in range(depth)),
            radii=tuple(z[f"r{k}"] for k in range(depth)),
            parents=tuple(z[f"p{k}"] for k in range(depth)),
            leaf_of_face=z["leaf_of_face"],
            method=str(z["method"]),
        )


_MIRROR = np.array([-1.0, 1.0, 1.0])


def mirror_mesh(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh reflected in the y-z plane (x -> -x), faces re-wound to keep normals outward."""
    return vertices * _MIRROR, np.ascontiguousarray(faces[:, ::-1])


def mirror_tree(tree: SphereTree) -> SphereTree:
    """The tree of the mirrored mesh: centres reflected, everything else (face order too) unchanged."""
    return SphereTree(tree.branching, tuple(c * _MIRROR for c in tree.centers), tree.radii, tree.parents,
                      tree.leaf_of_face, tree.method)


def cached_sphere_tree(mesh, method: str = "fit", branching: int = 8, depth: int = 4, cache_dir: str | Path | None = None) -> SphereTree:
    """`build_sphere_tree` through the on-disk cache: load the tree if this mesh (or its mirror image)
    was built before with the same request."""
    check_request(method, branching, depth)
    vertices, faces = mesh_arrays(mesh)
    key = cache_key(vertices, faces, method, branching, depth)
    mirrored = mirror_mesh(vertices, faces)
    mirror_key = cache_key(*mirrored, method, branching, depth)
    flip = mirror_key < key
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = folder / f"{min(key, mirror_key)}.npz"
    tree = None
    if path.is_file():
        try:
            tree = load_tree(path)
            if len(tree.leaf_of_face) != len(faces) or tree.branching != branching or tree.depth != depth:
                tree = None
        except (OSError, ValueError, KeyError, zipfile.BadZipFile):
            tree = None  # a damaged cache entry is rebuilt and overwritten below
    if tree is None:
        tree = build_sphere_tree(mirrored if flip else (vertices, faces), method, branching, depth)
        try:
            save_tree(tree, path)
        except OSError:
            pass  # a read-only or full cache folder costs a rebuild next time, never a failure
    return mirror_tree(tree) if flip else tree

"""On-disk cache of sphere trees, keyed by the mesh's content and the build request.

A tree depends only on the mesh's vertices and faces, the method, branching, depth and the builder's
code, so the key is a SHA-256 of exactly those: the source text of the modules that build trees
(`_BUILDER_MODULES`) enters the key, so an edited builder never serves a tree an older one stored,
and `BUILDER_VERSION` is bumped as well whenever a builder changes its output on purpose. A hit
loads one small .npz in milliseconds; a miss builds and writes the file atomically, so two
processes racing on the same tree both end with a whole file. Entries carry a checksum, their key
and the entry format (`orthosim.storage.cacheentry`), and every load also checks the tree still
bounds its mesh (`damage`): a damaged entry is named in one warning and rebuilt. The folder is
`$ORTHOSIM_CACHE` if set, else `~/.cache/orthosim/spheretrees`.

Left and right teeth are mirror images (x -> -x in the local frame, see `orthosim.model.tooth`), and a
mirror maps a conservative tree to a conservative tree exactly (negating a float is exact), so a
mesh and its mirror share one entry: the tree is built and stored for whichever of the two has the
smaller key, and mirrored on the way out for the other. A full dentition costs half the builds,
and `cached_sphere_trees` spreads those builds over the machine's cores (one process each; in a
daemonic process, which may not start processes, one thread each).
"""

from __future__ import annotations

import functools
import hashlib
import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orthosim.errors import DamagedFileError
from orthosim.storage.atomic import atomic_path
from orthosim.storage.cacheentry import (ENTRY_FORMAT, HEADER, DamagedEntryWarning, damaged, read_arrays, warn_damaged,
                                        write_arrays)
from orthosim.system.firstrun import hush, preparing
from orthosim.system.lifeline import exit_with_parent
from orthosim.storage.shipped import shipped_entry
from orthosim.storage.sourcedigest import source_digest
from orthosim.spheretree.build import DEPTH, build_sphere_tree, check_request, default_branching, mesh_arrays
from orthosim.spheretree.tree import SphereTree

BUILDER_VERSION = 10
ENTRY_KIND = "spheretree"
# Modules whose code decides what a built tree holds: their source is part of the key.
_BUILDER_MODULES = ("build", "fit", "octree", "enclose", "outside_band", "inside", "measure", "tree")
_PACKAGE = Path(__file__).resolve().parent


@functools.cache
def builder_source_digest() -> str:
    """Hex SHA-256 of the source text of the tree-building modules (read once a process)."""
    return source_digest(_PACKAGE, _BUILDER_MODULES)


def default_cache_dir() -> Path:
    env = os.environ.get("ORTHOSIM_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "orthosim" / "spheretrees"


def cache_key(vertices: np.ndarray, faces: np.ndarray, method: str, branching: int, depth: int) -> str:
    """Hex SHA-256 of the mesh's bytes (float64 vertices, int64 faces), the build request and the
    builder (version and source, `builder_source_digest`) and the cache entry format."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
    h.update(f"|{method}|{branching}|{depth}|v{BUILDER_VERSION}|{builder_source_digest()}|{len(vertices)}|{len(faces)}"
             f"|entry{ENTRY_FORMAT}".encode())
    return h.hexdigest()


def _tree_arrays(tree: SphereTree) -> dict[str, np.ndarray]:
    arrays = {"branching": np.int64(tree.branching), "method": np.str_(tree.method), "leaf_of_face": tree.leaf_of_face}
    for k in range(tree.depth):
        arrays[f"c{k}"], arrays[f"r{k}"], arrays[f"p{k}"] = tree.centers[k], tree.radii[k], tree.parents[k]
    return arrays


def _tree_from(arrays) -> SphereTree:
    depth = sum(1 for name in arrays if name.startswith("c"))
    return SphereTree(
        branching=int(arrays["branching"]),
        centers=tuple(arrays[f"c{k}"] for k in range(depth)),
        radii=tuple(arrays[f"r{k}"] for k in range(depth)),
        parents=tuple(arrays[f"p{k}"] for k in range(depth)),
        leaf_of_face=arrays["leaf_of_face"],
        method=str(arrays["method"]),
    )


def save_tree(tree: SphereTree, path: str | Path) -> None:
    """Write a tree as .npz (atomically): per level c{k}, r{k}, p{k}, plus leaf_of_face (the export
    format of `orthosim spheretree build --out`; cache entries add a checksum, `store_entry`)."""
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **_tree_arrays(tree))


def load_tree(path: str | Path) -> SphereTree:
    """Read a tree written by `save_tree` (or a cache entry, unverified: see `read_entry`)."""
    with np.load(path, allow_pickle=False) as z:
        return _tree_from({name: z[name] for name in z.files if name != HEADER})


def store_entry(tree: SphereTree, path: str | Path) -> None:
    """Write a tree as a checksummed cache entry whose key is the file name's stem."""
    write_arrays(path, ENTRY_KIND, Path(path).stem, _tree_arrays(tree))


def read_entry(path: str | Path) -> SphereTree:
    """The tree of a cache entry written by `store_entry`; FileNotFoundError when absent,
    `DamagedFileError` when its header or checksum fails or its arrays are not a tree's."""
    path = Path(path)
    arrays = read_arrays(path, ENTRY_KIND, path.stem)
    try:
        return _tree_from(arrays)
    except (KeyError, TypeError, ValueError) as err:
        raise damaged(path, f"its arrays are not a sphere tree ({type(err).__name__}: {err})") from None


_MIRROR = np.array([-1.0, 1.0, 1.0])


def mirror_mesh(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh reflected in the y-z plane (x -> -x), faces re-wound to keep normals outward."""
    return vertices * _MIRROR, np.ascontiguousarray(faces[:, ::-1])


def mirror_tree(tree: SphereTree) -> SphereTree:
    """The tree of the mirrored mesh: centres reflected, everything else (face order too) unchanged."""
    return SphereTree(tree.branching, tuple(c * _MIRROR for c in tree.centers), tree.radii, tree.parents,
                      tree.leaf_of_face, tree.method)


@dataclass(frozen=True)
class _Entry:
    """Where a mesh's tree lives in the cache, and whether it is stored for the mirror image."""

    path: Path
    flip: bool
    mesh: tuple[np.ndarray, np.ndarray]  # the mesh the stored tree was (or is to be) built for


def _side_key(vertices: np.ndarray, faces: np.ndarray) -> str:
    """Which of a mesh and its mirror image a shared tree is built for: the one whose content digest
    is smaller. Content only, never the builder's version or source, so that editing the builder
    never swaps a pair's sides (a tree's mirror is not the tree its mirror image would get)."""
    h = hashlib.sha256(np.ascontiguousarray(vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
    return h.hexdigest()


def _entry(mesh, method: str, branching: int, depth: int, folder: Path) -> _Entry:
    vertices, faces = mesh_arrays(mesh)
    mirrored = mirror_mesh(vertices, faces)
    flip = _side_key(*mirrored) < _side_key(vertices, faces)
    stored = mirrored if flip else (vertices, faces)
    return _Entry(folder / f"{cache_key(*stored, method, branching, depth)}.npz", flip, stored)


class DamagedCacheWarning(DamagedEntryWarning):
    """A sphere-tree cache entry was unreadable or wrong; it is rebuilt (the message says which and why)."""


# Slack (mm) when checking that a stored tree still holds its mesh: the builder's own guarantee is
# exact, and a damaged entry misses by far more than this.
_HOLD_TOL_MM = 1e-6


def damage(tree: SphereTree, vertices: np.ndarray, faces: np.ndarray, branching: int, depth: int) -> str | None:
    """Why a loaded tree cannot be this mesh's conservative tree, or None when it can.

    The full invariant, checked on every load: the layout, finite positive numbers, and every face
    inside its leaf and every ancestor of it (`SphereTree.validate`). A tree that is wrong in any of
    these would give wrong collisions silently, and checking costs a few milliseconds a tree
    (vectorised over faces), small beside the load itself.
    """
    if tree.branching != branching or tree.depth != depth:
        return f"branching {tree.branching}, depth {tree.depth} where {branching}, {depth} was asked"
    if len(tree.leaf_of_face) != len(faces):
        return f"{len(tree.leaf_of_face)} faces where the mesh has {len(faces)}"
    for k in range(depth):
        c, r = tree.centers[k], tree.radii[k]
        if c.ndim != 2 or c.shape[1:] != (3,) or r.shape != (len(c),) or len(tree.parents[k]) != len(c):
            return f"level {k} has mismatched array shapes"
        if not (np.isfinite(c).all() and np.isfinite(r).all()):
            return f"level {k} holds non-finite centres or radii"
        if not (r > 0).all():
            return f"level {k} holds non-positive radii"
    leaf = tree.leaf_of_face
    if len(leaf) and (leaf.min() < 0 or leaf.max() >= len(tree.radii[-1])):
        return "a face names a leaf that does not exist"
    try:
        tree.validate(vertices, faces, tol=_HOLD_TOL_MM)
    except (ValueError, IndexError) as err:
        return f"its spheres do not bound the mesh ({err})"
    return None


def _load(entry: _Entry, branching: int, depth: int, shipped: bool = True) -> SphereTree | None:
    """The stored tree (the user's cache first, then, with `shipped`, the entries shipped with the
    package: orthosim.storage.shipped), or None when absent or damaged (then rebuilt and written to
    the user's cache, with a warning)."""
    path = entry.path
    if shipped and not path.is_file():
        path = shipped_entry("spheretrees", entry.path.name) or entry.path
    try:
        tree = read_entry(path)
        reason = damage(tree, *entry.mesh, branching, depth)
        if reason is not None:
            raise damaged(path, reason)
    except FileNotFoundError:
        return None
    except DamagedFileError as err:
        warn_damaged("sphere-tree", err, DamagedCacheWarning, stacklevel=4)
        return None
    return tree


def _store(tree: SphereTree, entry: _Entry) -> None:
    try:
        store_entry(tree, entry.path)
    except OSError:
        pass  # a read-only or full cache folder costs a rebuild next time, never a failure


def cached_sphere_tree(mesh, method: str = "fit", branching: int | None = None, depth: int = DEPTH,
                       cache_dir: str | Path | None = None) -> SphereTree:
    """`build_sphere_tree` through the on-disk cache: load the tree if this mesh (or its mirror image)
    was built before with the same request."""
    return cached_sphere_trees([mesh], method, branching, depth, cache_dir, workers=1)[0]


def _build(args) -> SphereTree:
    mesh, method, branching, depth = args
    return build_sphere_tree(mesh, method, branching, depth)


def _worker_start(parent_pid: int) -> None:
    """A tree-building worker: it ends with its parent if that is killed outright
    (orthosim.system.lifeline), and leaves the "preparing" line to its parent (orthosim.system.firstrun)."""
    exit_with_parent(parent_pid)
    hush()


def cached_sphere_trees(meshes: Sequence, method: str = "fit", branching: int | None = None, depth: int = DEPTH,
                        cache_dir: str | Path | None = None, workers: int | None = None,
                        progress: Callable[[int], None] | None = None, shipped: bool = True) -> list[SphereTree]:
    """The trees of many meshes through the cache: each distinct mesh (a mirror pair counts once)
    is loaded or built once, the builds spread over `workers` processes (default: one per core).
    `shipped=False` ignores the entries shipped with the package (a bench timing the build).

    `progress(n)` is called as n more meshes are done. Trees come back in the order of `meshes`.
    `branching` defaults to `default_branching(method)`.
    """
    branching = default_branching(method, branching)
    check_request(method, branching, depth)
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    entries = [_entry(m, method, branching, depth, folder) for m in meshes]
    stored: dict[Path, SphereTree] = {}
    missing: dict[Path, _Entry] = {}
    for e in entries:
        if e.path in stored or e.path in missing:
            continue
        tree = _load(e, branching, depth, shipped)
        if tree is None:
            missing[e.path] = e
        else:
            stored[e.path] = tree
    waiting = list(missing.values())
    users = {p: sum(e.path == p for e in entries) for p in missing}
    if progress is not None:
        progress(len(entries) - sum(users.values()))
    workers = min(workers or os.cpu_count() or 1, len(waiting))
    jobs = [(e.mesh, method, branching, depth) for e in waiting]

    def built():
        """(entry, tree) as each build finishes."""
        if workers <= 1:
            yield from ((e, _build(job)) for job, e in zip(jobs, waiting))
            return
        if multiprocessing.current_process().daemon:
            # a daemonic process (the simulation child of a drawn run, orthosim.runtime.background) may
            # not start processes: threads there, which run side by side in the compiled scoring (nogil)
            with ThreadPoolExecutor(max_workers=workers) as threads:
                futures = {threads.submit(_build, job): e for job, e in zip(jobs, waiting)}
                for done in as_completed(futures):
                    yield futures[done], done.result()
            return
        # fork: the children start at once with the parent's imports and compiled kernels
        # each worker ends with this process if it is killed outright (orthosim.system.lifeline)
        with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                                 initializer=_worker_start, initargs=(os.getpid(),)) as pool:
            futures = {pool.submit(_build, job): e for job, e in zip(jobs, waiting)}
            for done in as_completed(futures):
                yield futures[done], done.result()

    with preparing(f"the sphere trees of {len(waiting)} tooth shape{'s' if len(waiting) != 1 else ''}"):
        for e, tree in built():
            stored[e.path] = tree
            _store(tree, e)
            if progress is not None:
                progress(users[e.path])
    return [mirror_tree(stored[e.path]) if e.flip else stored[e.path] for e in entries]

"""Bradshaw's `.sph` text format: sphere trees in and out of the Sphere-Tree Construction Toolkit.

The paper's trees came from that toolkit, so users can bring its trees here and compare. Layout:
line 1 holds the number of levels (root included) and the branching factor B; then one line per
slot of the complete B-ary tree, breadth first, `x y z r error`; the children of slot n are the
slots n*B+1 ... n*B+B; a slot with a non-positive radius is an absent node. We write full double
precision (so a written tree reads back identical) and 0 as the error value, and absent slots as
`0 0 0 0 0`.

An imported tree knows nothing of triangles. With a mesh, `read_sph` gives each face the leaf
that, together with all its ancestors, holds the face's three vertices (the most deeply, when
several do), and -1 to faces that no such leaf holds
(Bradshaw's medial trees can leave bits of surface uncovered); without one, `leaf_of_face` is
empty. Such a tree is therefore only as conservative as the toolkit made it: check with
`SphereTree.validate` or `measure_tree`. A childless node above the last level (the toolkit stops
early where one sphere is enough) is carried down as its own single child, so every leaf sits on
the last level as `SphereTree` requires.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from orthosim.storage.atomic import write_text
from orthosim.errors import SphereTreeError
from orthosim.spheretree.tree import SphereTree


def _slots_per_level(depth: int, branching: int) -> list[int]:
    return [branching**k for k in range(depth)]


def write_sph(tree: SphereTree, path: str | Path) -> None:
    """Write `tree` as a Bradshaw .sph file (atomically)."""
    B, depth = tree.branching, tree.depth
    lines = [f"{depth} {B}"]
    slot_of_node = np.zeros(1, dtype=np.int64)  # slot index within the level
    for k in range(depth):
        n_slots = B**k
        rows = np.zeros((n_slots, 5))
        if k:
            offsets = tree.child_offsets(k)
            rank = np.arange(len(tree.parents[k])) - offsets[tree.parents[k]]  # position among siblings
            slot_of_node = slot_of_node[tree.parents[k]] * B + rank
        rows[slot_of_node, :3] = tree.centers[k]
        rows[slot_of_node, 3] = tree.radii[k]
        lines.extend(" ".join(format(v, ".17g") for v in row) for row in rows)
    write_text(path, "\n".join(lines) + "\n")


def read_sph(path: str | Path, vertices: np.ndarray | None = None, faces: np.ndarray | None = None, tol: float = 1e-6) -> SphereTree:
    """Read a Bradshaw .sph file; with the mesh ((n, 3) mm, (m, 3) int), assign faces to leaves.

    `tol` (mm) forgives the rounding of files written with few decimals when deciding whether a
    leaf holds a face's vertices.
    """
    where = str(path)
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise SphereTreeError(where, None, f"cannot be read ({exc.strerror})", "check the path") from None
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines:
        raise SphereTreeError(where, "line 1", "the file is empty", "give a .sph file written by Bradshaw's toolkit")
    head = lines[0].split()
    try:
        depth, B = int(head[0]), int(head[1])
    except (ValueError, IndexError):
        raise SphereTreeError(where, "line 1", f"expected 'levels branching', got {lines[0]!r}", "the first line must hold two integers") from None
    if not (1 <= depth <= 10 and 2 <= B <= 64):
        raise SphereTreeError(where, "line 1", f"levels {depth}, branching {B} are out of range", "levels 1-10, branching 2-64")
    total = sum(_slots_per_level(depth, B))
    if len(lines) - 1 < total:
        raise SphereTreeError(where, None, f"has {len(lines) - 1} sphere lines, a {depth}-level tree of branching {B} needs {total}", "the file is truncated: export it again")
    rows = np.zeros((total, 4))
    for i, ln in enumerate(lines[1 : total + 1]):
        parts = ln.split()
        try:
            if len(parts) < 4:
                raise ValueError
            rows[i] = [float(v) for v in parts[:4]]
        except ValueError:
            raise SphereTreeError(where, f"line {i + 2}", f"expected 'x y z r error', got {ln.strip()!r}", "each sphere line needs four numbers and an error value") from None
    if not np.all(np.isfinite(rows)):
        raise SphereTreeError(where, None, "holds a non-finite number", "export the tree again")
    centers, radii, parents = [], [], []
    start = 0
    prev_slots = np.zeros(0, dtype=np.int64)  # slot (within its level) of each node of the level above
    for k in range(depth):
        level = rows[start : start + B**k]
        start += B**k
        present = np.flatnonzero(level[:, 3] > 0)
        if k == 0:
            if len(present) != 1:
                raise SphereTreeError(where, "line 2", "the root sphere is missing", "the first sphere must have a positive radius")
            slots, par, level_rows = present, np.array([-1]), level[present]
        else:
            parent_slot = present // B
            idx = np.searchsorted(prev_slots, parent_slot)
            ok = (idx < len(prev_slots)) & (prev_slots[np.minimum(idx, len(prev_slots) - 1)] == parent_slot)
            if not ok.all():
                line = int(sum(B**j for j in range(k)) + present[~ok][0] + 2)
                raise SphereTreeError(where, f"line {line}", "a sphere's parent is absent", "the tree must be connected: export it again")
            # A childless node of the level above goes down as its own only child, in its first
            # child slot (free, since it has no children), so slots stay sorted by parent.
            has_child = np.zeros(len(prev_slots), dtype=bool)
            has_child[idx] = True
            lone = np.flatnonzero(~has_child)
            lone_rows = np.concatenate([centers[-1][lone], radii[-1][lone][:, None]], axis=1)
            slots = np.concatenate([present, prev_slots[lone] * B])
            par = np.concatenate([idx, lone])
            level_rows = np.concatenate([level[present], lone_rows])
            order = np.argsort(slots, kind="stable")
            slots, par, level_rows = slots[order], par[order], level_rows[order]
        centers.append(level_rows[:, :3].copy())
        radii.append(level_rows[:, 3].copy())
        parents.append(np.asarray(par, dtype=np.int64))
        prev_slots = np.asarray(slots, dtype=np.int64)
    tree = SphereTree(B, tuple(centers), tuple(radii), tuple(parents), np.zeros(0, dtype=np.int64), method="sph")
    if vertices is not None and faces is not None:
        leaf_of_face = assign_faces(tree, np.asarray(vertices, float), np.asarray(faces), tol)
        tree = SphereTree(B, tree.centers, tree.radii, tree.parents, leaf_of_face, method="sph")
    return tree


def assign_faces(tree: SphereTree, vertices: np.ndarray, faces: np.ndarray, tol: float = 1e-6, k: int = 64, chunk: int = 4000) -> np.ndarray:
    """(F,) leaf of each face, or -1: the leaf that, with every ancestor, holds all three vertices.

    Among such leaves the one with the most spare radius (over the leaf and its ancestors) wins.
    Candidates are the k leaves with the nearest centres and the k largest leaves.
    """
    faces = np.asarray(faces)
    centers, radii = tree.leaf_centers, tree.leaf_radii
    out = []
    for s in range(0, len(faces), chunk):
        tri = vertices[faces[s : s + chunk]]
        # Candidates: the leaves with the nearest centres, and the largest leaves (which may reach far).
        k = min(k, len(radii))
        _, near = cKDTree(centers).query(tri.mean(axis=1), k=k)
        big = np.argsort(radii)[::-1][:k]
        leaf = _assign(tree, tri, np.concatenate([near.reshape(len(tri), -1), np.broadcast_to(big, (len(tri), k))], axis=1), tol)
        # The rare face whose holder is neither near nor large: try every leaf.
        for i in np.flatnonzero(leaf < 0):
            leaf[i] = _assign(tree, tri[i : i + 1], np.arange(len(radii))[None, :], tol)[0]
        out.append(leaf)
    return np.concatenate(out)


def _assign(tree: SphereTree, tri: np.ndarray, cand: np.ndarray, tol: float) -> np.ndarray:
    """(f, 3, 3) triangles, (f, c) candidate leaves -> (f,) best candidate holding it with its ancestors, or -1."""
    spare = np.full(cand.shape, np.inf)
    node = cand
    for level in range(tree.depth - 1, -1, -1):
        c, r = tree.centers[level][node], tree.radii[level][node]
        far = np.sqrt(((tri[:, None, :, :] - c[:, :, None, :]) ** 2).sum(axis=3).max(axis=2))
        spare = np.minimum(spare, r + tol - far)
        if level:
            node = tree.parents[level][node]
    best = spare.argmax(axis=1)
    rows = np.arange(len(tri))
    return np.where(spare[rows, best] >= 0, cand[rows, best], -1)

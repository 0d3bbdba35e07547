"""Estimated roots for crown-only teeth: an intraoral scan's crown closed at its margin and given a root.

An intraoral scan shows crowns only, open where the gum hides the tooth; movement needs the root
(its length sets the centre of resistance, its surface collides with neighbouring roots). This
module builds one, in three steps, all lengths in mm:
  1. Margin frame: the crown's open boundary (the gingival margin; a closed crown is first cut
     0.3 mm above its cervical end) is fitted with a plane (SVD); its normal, signed toward the
     crown, is the estimated long axis, its centroid the point the root hangs from.
  2. Size: root length = measured crown height (highest crown point above the mean margin level)
     x the tooth type's Wheeler root / crown height ratio (`orthosim.model.anatomy`), kept within
     0.6-1.4 x the Wheeler root length; root count from Wheeler too (1 to 3 by type).
  3. Shape: the root is lofted from the margin itself (the first ring IS the margin, so crown and
     root share its vertices: no seam, no boolean), its cross-section shrinking along the
     parametric single root's taper (`orthosim.model.toothshape`: 0.70 at mid-root, 0.28 near the
     apex, rounded tip) down to a pole at the apex, straight along the long axis. A multi-rooted
     type instead lofts its root trunk (the parametric recipe's trunk length, scaled to the root)
     and is joined to the parametric model's separate roots, sized to the measured cervical widths,
     by a manifold3d union; the result is one closed, manifold mesh.
What it is good for: root collisions between neighbours and a centre of resistance at a plausible
depth (see docs/notes/intraoral-scans.md for how far it lies from real roots). What it is not: the
patient's root. Root curvature, dilaceration, resorption and real root lengths need a CBCT.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from orthosim.errors import MeshError
from orthosim.model import fdi as fdi_mod
from orthosim.model.anatomy import dimensions

ROOT_LENGTH_CLAMP = (0.6, 1.4)  # root length kept within these multiples of the Wheeler root length
CLOSED_CROWN_CUT_MM = 0.3  # a closed crown is opened this far above its cervical-most point
MAX_MARGIN_TILT_DEG = 60.0  # margin normal vs the caller's occlusal direction, when one is given
# Taper of the estimated single root: cross-section scale at fractions of the root length (the
# parametric single root's 0.68-0.72 at mid-root, 0.28-0.30 near the apex), then a rounded tip.
_TAPER = ((0.0, 1.0), (0.08, 0.97), (0.25, 0.88), (0.5, 0.70), (0.7, 0.52), (0.82, 0.40))
_TIP_START = 0.82  # fraction of the root length where the rounded tip starts
_TRUNK_SCALE = 0.85  # trunk cross-section at the furcation over the cervical one (toothshape.TRUNK)


class RootEstimatedWarning(UserWarning):
    """A crown-only tooth mesh was given an estimated root; the message names the file."""


@dataclass(frozen=True)
class MarginFrame:
    """Where a crown's root is hung from, in the crown's own frame (mm)."""

    long_axis: np.ndarray  # (3,) unit, apex -> crown: the margin plane's normal signed toward the crown
    centre: np.ndarray  # (3,) mm, centroid of the margin loop
    loop: np.ndarray  # (m,) int, the margin's vertex indices in the crown mesh, in boundary order
    crown_height_mm: float  # highest crown point above the mean margin level, along the long axis
    holes: tuple = ()  # the crown's other open loops (scan holes), each (k,) int, closed before the root is built


@dataclass(frozen=True)
class RootedCrown:
    """A crown joined to its estimated root: one closed mesh, in the crown's input frame (mm)."""

    mesh: trimesh.Trimesh  # closed, manifold, outward winding
    long_axis: np.ndarray  # (3,) unit, apex -> crown
    margin_centre: np.ndarray  # (3,) mm
    crown_height_mm: float
    root_length_mm: float  # margin level to apex, along the long axis
    roots: int


def boundary_loops(mesh: trimesh.Trimesh) -> list[np.ndarray]:
    """The mesh's open boundaries as vertex-index loops (each (k,) int), ordered as the faces run them.

    A boundary edge a -> b is taken in the direction its one face runs it, so a loop is followed in
    the sense that new faces closing it must run backwards. Raises ValueError on a boundary vertex
    shared by two loops (a pinched, non-manifold margin).
    """
    edges = mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    key = np.sort(edges, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    open_edges = edges[counts[inverse.ravel()] == 1]
    following: dict[int, int] = {}
    for a, b in open_edges:
        if int(a) in following:
            raise ValueError(f"vertex {int(a)} starts two boundary edges")
        following[int(a)] = int(b)
    loops, seen = [], set()
    for start in following:
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = following.get(v, start)
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def open_closed_crown(crown: trimesh.Trimesh, occlusal: np.ndarray) -> trimesh.Trimesh:
    """A closed crown (no boundary) cut open `CLOSED_CROWN_CUT_MM` above its cervical-most point along `occlusal` (3,)."""
    from orthosim.geometry.meshcut import keep_above_plane

    occlusal = np.asarray(occlusal, float) / np.linalg.norm(occlusal)
    low = float((crown.vertices @ occlusal).min()) + CLOSED_CROWN_CUT_MM
    return keep_above_plane(crown, occlusal, occlusal * low)


def margin_frame(crown: trimesh.Trimesh, where: str, occlusal: np.ndarray | None = None) -> MarginFrame:
    """The margin plane of an open crown (mm): long axis, centre, the loop and the crown height.

    The margin is the longest boundary loop. `occlusal` (3,), when given, is the direction the
    crown should point (e.g. -y for an upper crown in the arch frame): a margin normal more than
    `MAX_MARGIN_TILT_DEG` from it is refused.
    """
    try:
        loops = boundary_loops(crown)
    except ValueError as err:
        raise MeshError(where, "margin", f"the crown's open edge is not a simple loop ({err})",
                        "repair the crown mesh so its gingival margin is one clean boundary") from None
    if not loops:
        raise MeshError(where, "margin", "the crown has no open margin", "pass a crown open at the gum line")
    length = [np.linalg.norm(np.diff(crown.vertices[np.r_[lp, lp[:1]]], axis=0), axis=1).sum() for lp in loops]
    loop = loops[int(np.argmax(length))]
    if len(loop) < 8:
        raise MeshError(where, "margin", f"the crown's margin has only {len(loop)} vertices",
                        "use a crown mesh with a finer gingival margin")
    points = crown.vertices[loop]
    centre = points.mean(axis=0)
    _, s, vt = np.linalg.svd(points - centre, full_matrices=False)
    axis = vt[2]
    crown_centre = crown.vertices.mean(axis=0)
    if (crown_centre - centre) @ axis < 0:
        axis = -axis
    if occlusal is not None:
        tilt = np.degrees(np.arccos(np.clip(axis @ (occlusal / np.linalg.norm(occlusal)), -1.0, 1.0)))
        if tilt > MAX_MARGIN_TILT_DEG:
            raise MeshError(where, "margin", f"the crown's margin faces {tilt:.0f} degrees away from the occlusal "
                            "direction, so the crown is not upright in the arch frame",
                            "transform the crowns into the arch frame, or use frame = \"scan\"")
    height = float(((crown.vertices - centre) @ axis).max())
    if height <= 1.0:
        raise MeshError(where, "crown", f"the crown stands only {height:.2f} mm above its margin",
                        "pass a whole crown, open only at the gum line")
    others = tuple(lp for lp in loops if lp is not loop)
    return MarginFrame(axis, centre, loop, height, others)


def synthesize_root(crown: trimesh.Trimesh, fdi: int, where: str, labial: np.ndarray | None = None,
                    frame: MarginFrame | None = None) -> RootedCrown:
    """The crown (open at its margin, any frame, mm) joined to an estimated root for FDI type `fdi`.

    `labial` (3,): the tooth's labial direction in the crown's frame, which places a multi-rooted
    type's roots (buccal/lingual, mesial/distal); any direction across the long axis will do for a
    single root. `frame`: the margin frame when already measured (`margin_frame`).
    """
    frame = frame or margin_frame(crown, where)
    dims = dimensions(fdi)
    ratio = dims.root_length / dims.crown_height
    low, high = ROOT_LENGTH_CLAMP
    root_length = float(np.clip(frame.crown_height_mm * ratio, low * dims.root_length, high * dims.root_length))
    basis = _local_basis(frame.long_axis, labial)  # rows x, y, z
    local = (crown.vertices - frame.centre) @ basis.T
    local, faces = _close_holes(local, np.asarray(crown.faces, np.int64), frame.holes)
    recipe_roots, trunk = _root_recipe(fdi)
    scale = root_length / dims.root_length
    depth = root_length if not recipe_roots else (trunk * scale + 1.5)
    verts, faces = _loft_root(local, faces, frame.loop, depth, single=not recipe_roots)
    mesh = trimesh.Trimesh(verts, faces, process=False)
    if recipe_roots:
        mesh = _join_roots(mesh, fdi, local[frame.loop], recipe_roots, trunk * scale, root_length, where)
    mesh.apply_transform(_to_input(basis, frame.centre))
    if mesh.is_watertight and mesh.volume < 0:
        mesh.invert()  # the crown was wound inward: the root followed it
    if not mesh.is_watertight or mesh.volume <= 0:
        raise MeshError(where, "root", "the crown and its estimated root do not close into one solid",
                        "repair the crown mesh (one clean margin, consistent winding) and load it again")
    return RootedCrown(mesh, frame.long_axis, frame.centre, frame.crown_height_mm, root_length, max(1, len(recipe_roots)))


def _close_holes(vertices: np.ndarray, faces: np.ndarray, holes) -> tuple[np.ndarray, np.ndarray]:
    """Each hole (a boundary loop, run as its faces run it) closed by a fan from its centroid; margin indices kept."""
    if not holes:
        return vertices, faces
    extra_v, extra_f = [], []
    count = len(vertices)
    for loop in holes:
        extra_v.append(vertices[loop].mean(axis=0))
        extra_f.append(np.column_stack([np.roll(loop, -1), loop, np.full(len(loop), count)]))
        count += 1
    return np.vstack([vertices, extra_v]), np.vstack([faces, *extra_f])


def _local_basis(axis: np.ndarray, labial: np.ndarray | None) -> np.ndarray:
    """(3, 3) rows x, y, z: y the long axis, z the labial direction across it, x = y cross z."""
    y = axis / np.linalg.norm(axis)
    z = np.array([0.0, 0.0, 1.0]) if labial is None else np.asarray(labial, float)
    z = z - y * (z @ y)
    if np.linalg.norm(z) < 1e-6:
        z = np.cross(y, [1.0, 0.0, 0.0]) if abs(y[0]) < 0.9 else np.cross(y, [0.0, 1.0, 0.0])
    z /= np.linalg.norm(z)
    return np.array([np.cross(y, z), y, z])


def _to_input(basis: np.ndarray, centre: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = basis.T
    T[:3, 3] = centre
    return T


def _root_recipe(fdi: int):
    """(separate roots of the type's parametric recipe, trunk mm) or ((), 0) for a single root."""
    from orthosim.model.toothshape import RECIPES

    dims = dimensions(fdi)
    recipe = RECIPES[(fdi_mod.arch_of(fdi), fdi_mod.tooth_type(fdi))]
    if dims.roots < 2 or not recipe.roots:
        return (), 0.0
    return recipe.roots, recipe.trunk


def _taper(t: np.ndarray, single: bool) -> np.ndarray:
    """Cross-section scale at depth fractions `t` (0 margin, 1 bottom) of a single root or a trunk."""
    if not single:  # a trunk narrows to the furcation, then rounds off its floor
        s = 1.0 - (1.0 - _TRUNK_SCALE) * np.clip(t / 0.8, 0, 1)
        tip = np.clip((t - 0.8) / 0.2, 0, 1)
        return s * (0.1 + 0.9 * np.sqrt(np.maximum(1 - tip ** 2, 0.0)))
    ts, ss = zip(*_TAPER)
    s = np.interp(t, ts, ss)
    tip = np.clip((t - _TIP_START) / (1 - _TIP_START), 0, 1)
    return s * np.sqrt(np.maximum(1 - tip ** 2, 0.0))


def _loft_root(local: np.ndarray, faces: np.ndarray, loop: np.ndarray, depth: float, single: bool):
    """Crown vertices and faces (local frame) with a root lofted from the margin `loop` to `depth` mm below it.

    Ring 0 is the margin itself; deeper rings are the margin, smoothed in the plane, scaled toward
    the axis by the taper and levelled; the last ring closes on a pole at the bottom.
    """
    ring = local[loop]
    level = float(ring[:, 1].min())
    flat = ring[:, [0, 2]].copy()
    n_rings = 14 if single else 6
    t = np.linspace(0.0, 1.0, n_rings + 1)[1:-1]
    t = np.concatenate([[0.3 / depth], t[t > 0.3 / depth]])
    scale = _taper(t, single)
    verts, new_faces = [local], []
    prev = loop
    count = len(local)
    for k, (tk, sk) in enumerate(zip(t, scale)):
        flat = 0.5 * flat + 0.25 * (np.roll(flat, 1, axis=0) + np.roll(flat, -1, axis=0))  # smooth a jagged margin
        pts = np.column_stack([flat[:, 0] * sk, np.full(len(flat), level - tk * depth), flat[:, 1] * sk])
        cur = np.arange(count, count + len(pts))
        verts.append(pts)
        count += len(pts)
        new_faces += _strip(prev, cur)
        prev = cur
    apex = np.array([[0.0, level - depth, 0.0]])
    verts.append(apex)
    nxt = np.roll(prev, -1)
    new_faces.append(np.column_stack([nxt, prev, np.full(len(prev), count)]))
    return np.vstack(verts), np.vstack([faces, *new_faces])


def _strip(upper: np.ndarray, lower: np.ndarray) -> list[np.ndarray]:
    """Faces joining ring `upper` (run the way its open edges run) to the ring `lower` below it."""
    u1, l1 = np.roll(upper, -1), np.roll(lower, -1)
    return [np.column_stack([u1, upper, lower]), np.column_stack([u1, lower, l1])]


def _join_roots(trunk_mesh: trimesh.Trimesh, fdi: int, margin: np.ndarray, roots, trunk_mm: float,
                root_length: float, where: str) -> trimesh.Trimesh:
    """The crown and trunk (local frame) united with the type's separate parametric roots (manifold3d)."""
    from orthosim.model.toothshape import _root_mesh, ShapeRecipe

    cerv_a = float(np.abs(margin[:, 0]).max())  # half widths of the margin across the local x and z
    cerv_b = float(np.abs(margin[:, 2]).max())
    level = float(margin[:, 1].min())
    recipe = ShapeRecipe(1, 1, 0, 0, 1, 1, 2, (), roots=roots, trunk=trunk_mm)
    mirror = fdi_mod.quadrant(fdi) in (1, 3)  # the recipe's +x is mesial, local +x is distal there
    parts = []
    for root in roots:
        m = _root_mesh(root, recipe, cerv_a, cerv_b, root_length, 24)
        v = m.vertices.copy()
        f = m.faces
        if mirror:
            v[:, 0] *= -1
            f = f[:, ::-1]
        v[:, 1] += level
        parts.append(trimesh.Trimesh(v, f, process=False))
    if trunk_mesh.volume < 0:
        trunk_mesh.invert()  # an inward-wound crown: the union needs the solid the right way out
    try:
        joined = trimesh.boolean.union([trunk_mesh, *parts], engine="manifold")
    except Exception as err:  # manifold3d refuses a non-manifold input in several ways; all mean the same here
        raise MeshError(where, "root", f"the crown could not be joined to its estimated roots ({type(err).__name__})",
                        "repair the crown mesh (one clean margin, no self-touching edges) and load it again") from None
    if joined.volume < 0:
        joined.invert()
    return joined

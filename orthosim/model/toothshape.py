"""Parametric tooth meshes: a crown shaped like its type on one to three tapered roots.

Each tooth is built in its local frame (see `orthosim.model.tooth`) with the mesial direction along +x,
from the Wheeler dimensions of its type, as a stack of superellipse cross-sections ("rings") lofted
from the root apex up to the occlusal table, closed on top by a height field that carries the
type's incisal edge, cusp tip or cusps and fossae. Single-rooted teeth are that one closed surface;
multi-rooted teeth stop the loft at a short root trunk and gain separate roots by a boolean union
(manifold3d), which keeps the result closed and manifold. A resolution knob sets the number of
points per ring: 10 gives the paper's coarse teeth (about 125 vertices), 40 smooth ones (a few
thousand), so the same code serves replication and realistic rendering. From 40 points per ring
up, edges longer than 40 / n mm (1 mm for smooth teeth) are split at their midpoints
(`orthosim.geometry.meshrefine`): the surface stays the same, but the long triangles where roots join the
trunk and near the apex, which would force large leaf spheres on the sphere trees, are gone.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from orthosim.model.anatomy import ToothDimensions
from orthosim.model.fdi import Arch, ToothType
from orthosim.geometry.meshrefine import split_long_edges

if TYPE_CHECKING:  # imported where a shape is built: reading a case's resolution names needs neither
    import trimesh
    from scipy.interpolate import PchipInterpolator

TRUNK = 0.85  # root-trunk cross-section over the cervical one, multi-rooted teeth
RESOLUTIONS = {"coarse": 10, "medium": 20, "smooth": 40, "fine": 64}
REFINED_FROM = 40  # ring points from which long edges are split, to at most REFINED_FROM / n mm


@dataclass(frozen=True)
class Cusp:
    name: str
    x: float  # fraction of the occlusal half-width, + mesial
    z: float  # fraction of the occlusal half-depth, + buccal
    height: float  # mm above the occlusal table edge
    spread: float  # fraction of the crown half-width: the cusp's Gaussian sigma


@dataclass(frozen=True)
class Root:
    x: float  # fraction of the trunk half-width where the root leaves the trunk, + mesial
    z: float  # fraction of the trunk half-depth, + buccal
    width: float  # fraction of the trunk half-width: the root's half-width at its top
    depth: float  # fraction of the trunk half-depth: the root's half-depth at its top
    spread: float  # how far the apex lies outward, relative to the top offset


@dataclass(frozen=True)
class ShapeRecipe:
    """How one tooth type is shaped, as fractions of its Wheeler dimensions."""

    cervical_md: float  # MD width at the CEJ over the crown MD width
    cervical_bl: float  # BL width at the CEJ over the crown BL width
    contact_level: float  # height of the contact points over the crown height
    contour_level: float  # height of the BL height of contour over the crown height
    top_md: float  # MD width of the occlusal table / incisal edge over the crown MD width
    top_bl: float  # BL width of the occlusal table / incisal edge over the crown BL width
    squareness: float  # superellipse exponent of the cross-sections (2 = ellipse)
    cusps: tuple[Cusp, ...]
    fossa_depth: float = 0.0  # mm below the occlusal table edge at the centre
    roots: tuple[Root, ...] = ()  # empty: single root continuing the loft
    trunk: float = 0.0  # mm of root trunk below the CEJ before the roots split


_INCISAL_EDGE = (Cusp("incisal_edge", 0.0, 0.0, 0.35, 1.2),)

RECIPES: dict[tuple[Arch, ToothType], ShapeRecipe] = {}


def _recipe(arches, types, recipe):
    for a in arches:
        for t in types:
            RECIPES[(a, t)] = recipe


_BOTH = (Arch.UPPER, Arch.LOWER)
_T = ToothType
_recipe(_BOTH, (_T.CENTRAL_INCISOR, _T.LATERAL_INCISOR),
        ShapeRecipe(0.72, 0.85, 0.78, 0.22, 0.92, 0.16, 2.3, _INCISAL_EDGE))
_recipe(_BOTH, (_T.CANINE,),
        ShapeRecipe(0.72, 0.85, 0.68, 0.28, 0.55, 0.35, 2.2,
                    (Cusp("cusp_tip", 0.05, 0.1, 2.4, 0.55),)))
# Premolars: a buccal and a lingual cusp (the lower first premolar's lingual cusp is small).
_PM_UPPER = ShapeRecipe(0.70, 0.88, 0.72, 0.35, 0.82, 0.72, 2.6,
                        (Cusp("buccal_cusp", 0.0, 0.55, 2.0, 0.45), Cusp("lingual_cusp", 0.0, -0.55, 1.7, 0.45)),
                        fossa_depth=0.6)
_recipe((Arch.UPPER,), (_T.FIRST_PREMOLAR,),
        ShapeRecipe(**{**_PM_UPPER.__dict__, "roots": (Root(0.0, 0.5, 0.8, 0.45, 1.3), Root(0.0, -0.5, 0.8, 0.45, 1.3)),
                       "trunk": 5.0}))
_recipe((Arch.UPPER,), (_T.SECOND_PREMOLAR,), _PM_UPPER)
_recipe((Arch.LOWER,), (_T.FIRST_PREMOLAR,),
        ShapeRecipe(0.70, 0.88, 0.72, 0.35, 0.80, 0.70, 2.5,
                    (Cusp("buccal_cusp", 0.0, 0.45, 2.2, 0.5), Cusp("lingual_cusp", 0.0, -0.6, 0.9, 0.35)),
                    fossa_depth=0.4))
_recipe((Arch.LOWER,), (_T.SECOND_PREMOLAR,),
        ShapeRecipe(0.70, 0.88, 0.72, 0.35, 0.82, 0.72, 2.6,
                    (Cusp("buccal_cusp", 0.0, 0.5, 1.9, 0.45), Cusp("lingual_cusp", 0.0, -0.55, 1.5, 0.45)),
                    fossa_depth=0.6))
# Upper molars: mesiobuccal, distobuccal, mesiopalatal (largest) and distopalatal cusps; three roots.
_UPPER_MOLAR_CUSPS = (
    Cusp("mb_cusp", 0.5, 0.55, 1.8, 0.33), Cusp("db_cusp", -0.5, 0.55, 1.6, 0.33),
    Cusp("mp_cusp", 0.45, -0.5, 2.0, 0.38), Cusp("dp_cusp", -0.5, -0.55, 1.3, 0.3),
)
_UPPER_MOLAR_ROOTS = (Root(0.5, 0.45, 0.48, 0.45, 1.35), Root(-0.5, 0.45, 0.46, 0.42, 1.3), Root(0.0, -0.5, 0.6, 0.48, 1.45))
_recipe((Arch.UPPER,), (_T.FIRST_MOLAR, _T.SECOND_MOLAR, _T.THIRD_MOLAR),
        ShapeRecipe(0.78, 0.86, 0.72, 0.35, 0.84, 0.78, 2.8, _UPPER_MOLAR_CUSPS, 1.0, _UPPER_MOLAR_ROOTS, 4.0))
# Lower molars: mesiobuccal, distobuccal, distal, mesiolingual, distolingual cusps; mesial and distal roots.
_LOWER_MOLAR_CUSPS = (
    Cusp("mb_cusp", 0.55, 0.5, 1.6, 0.28), Cusp("db_cusp", -0.05, 0.55, 1.5, 0.28),
    Cusp("d_cusp", -0.62, 0.3, 1.2, 0.24), Cusp("ml_cusp", 0.5, -0.55, 1.9, 0.3),
    Cusp("dl_cusp", -0.45, -0.55, 1.7, 0.3),
)
_LOWER_MOLAR_ROOTS = (Root(0.5, 0.0, 0.46, 0.88, 1.2), Root(-0.5, 0.0, 0.44, 0.85, 1.25))
_recipe((Arch.LOWER,), (_T.FIRST_MOLAR,),
        ShapeRecipe(0.78, 0.86, 0.72, 0.35, 0.84, 0.78, 2.8, _LOWER_MOLAR_CUSPS, 1.0, _LOWER_MOLAR_ROOTS, 3.5))
_recipe((Arch.LOWER,), (_T.SECOND_MOLAR, _T.THIRD_MOLAR),
        ShapeRecipe(0.78, 0.86, 0.72, 0.35, 0.84, 0.78, 2.8,
                    (Cusp("mb_cusp", 0.5, 0.5, 1.6, 0.3), Cusp("db_cusp", -0.5, 0.5, 1.5, 0.3),
                     Cusp("ml_cusp", 0.5, -0.5, 1.8, 0.3), Cusp("dl_cusp", -0.5, -0.5, 1.7, 0.3)),
                    1.0, _LOWER_MOLAR_ROOTS, 3.5))


@dataclass(frozen=True, eq=False)
class ToothShape:
    """A parametric tooth in the canonical local frame (+x mesial), before mirroring and placement."""

    mesh: trimesh.Trimesh
    crown_height: float  # mm, CEJ to the highest cusp tip / incisal edge
    contact_level: float  # mm above the CEJ of the mesial and distal contact points
    landmarks: dict[str, np.ndarray]  # (3,) mm, canonical local frame


def _superellipse(theta: np.ndarray, exponent: float) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(theta), np.sin(theta)
    e = 2.0 / exponent
    return np.sign(c) * np.abs(c) ** e, np.sign(s) * np.abs(s) ** e


class _Occlusal:
    """The occlusal height field: mm above the table edge at (x, z), from the cusps and the fossa."""

    def __init__(self, recipe: ShapeRecipe, half_md: float, half_bl: float):
        self.half_md, self.half_bl = half_md, half_bl
        self.cusps = recipe.cusps
        self.fossa = recipe.fossa_depth

    def cusp_xz(self, cusp: Cusp) -> tuple[float, float]:
        return cusp.x * self.half_md, cusp.z * self.half_bl

    def __call__(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        h = np.zeros_like(x)
        for cusp in self.cusps:
            cx, cz = self.cusp_xz(cusp)
            sx = cusp.spread * self.half_md
            sz = cusp.spread * self.half_bl
            h = np.maximum(h, cusp.height * np.exp(-0.5 * (((x - cx) / sx) ** 2 + ((z - cz) / sz) ** 2)))
        if self.fossa:
            h = h - self.fossa * np.exp(-0.5 * ((x / (0.35 * self.half_md)) ** 2 + (z / (0.3 * self.half_bl)) ** 2))
        return h


def _loft(rings: list[np.ndarray], bottom: np.ndarray, top: np.ndarray) -> trimesh.Trimesh:
    import trimesh

    """Close a stack of rings (each (n, 3), same n, bottom to top) with a pole at each end."""
    n = len(rings[0])
    verts = np.vstack([bottom[None], *rings, top[None]])
    m = len(rings)
    faces = []
    j = np.arange(n)
    jn = (j + 1) % n
    ring0 = 1
    faces.append(np.stack([np.zeros(n, int), ring0 + jn, ring0 + j], axis=1))  # bottom fan
    for r in range(m - 1):
        a = 1 + r * n
        b = a + n
        faces.append(np.stack([a + j, a + jn, b + jn], axis=1))
        faces.append(np.stack([a + j, b + jn, b + j], axis=1))
    last = 1 + (m - 1) * n
    top_i = len(verts) - 1
    faces.append(np.stack([last + j, last + jn, np.full(n, top_i)], axis=1))  # top fan
    mesh = trimesh.Trimesh(verts, np.vstack(faces), process=False)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def _profile(points: list[tuple[float, float]]) -> PchipInterpolator:
    from scipy.interpolate import PchipInterpolator

    ys, vs = zip(*points)
    return PchipInterpolator(np.array(ys), np.array(vs))


def build_tooth_shape(dims: ToothDimensions, arch: Arch, ttype: ToothType, resolution: int | str = "smooth") -> ToothShape:
    """Build one parametric tooth (closed, outward normals) in the canonical local frame.

    `resolution`: points per cross-section ring (an even int >= 6) or a preset name from
    RESOLUTIONS. The crown's mesiodistal extent equals `dims.md_width` exactly (the contact points
    are ring vertices), so arch lengths and Bolton ratios measured on the mesh match the table.
    """
    import trimesh

    n = RESOLUTIONS[resolution] if isinstance(resolution, str) else int(resolution)
    if n < 6 or n % 2:
        raise ValueError(f"resolution must be an even number of ring points >= 6, got {n}")
    recipe = RECIPES[(arch, ttype)]
    H, L = dims.crown_height, dims.root_length
    half_md, half_bl = dims.md_width / 2, dims.bl_width / 2
    occlusal = _Occlusal(recipe, recipe.top_md * half_md, recipe.top_bl * half_bl)
    tips = [occlusal.cusp_xz(c) for c in recipe.cusps]
    max_cusp = float(occlusal(np.array([t[0] for t in tips]), np.array([t[1] for t in tips])).max())
    table = H - max_cusp  # height of the occlusal table edge above the CEJ, so the top is at H
    y_contact = min(recipe.contact_level * H, table - 0.2)
    y_contour = recipe.contour_level * H
    cerv_a, cerv_b = recipe.cervical_md * half_md, recipe.cervical_bl * half_bl

    multi = bool(recipe.roots)
    bottom = -(recipe.trunk + 1.5) if multi else -L
    a_prof = [(bottom, TRUNK * cerv_a if multi else 0.28 * cerv_a)]
    b_prof = [(bottom, TRUNK * cerv_b if multi else 0.3 * cerv_b)]
    if not multi:
        a_prof.append((-0.5 * L, 0.68 * cerv_a))
        b_prof.append((-0.5 * L, 0.72 * cerv_b))
    a_prof += [(0.0, cerv_a), (y_contact, half_md), (table, recipe.top_md * half_md)]
    b_prof += [(0.0, cerv_b), (y_contour, half_bl), (table, recipe.top_bl * half_bl)]
    a_of, b_of = _profile(a_prof), _profile(b_prof)

    # Ring heights: the CEJ and the contact level are exact rings (crown/root split, MD extent).
    n_root = max(3, n // 3 if multi else n // 2)
    n_crown = max(4, (2 * n) // 3)
    tip = 0.18 * (-bottom) if not multi else 1.2  # length of the rounded apex / trunk floor
    y_root = np.linspace(bottom, 0.0, n_root + 1)[1:-1]
    y_root = np.concatenate([bottom + tip * (1 - np.cos(np.linspace(0, np.pi / 2, 4)[1:-1])), y_root[y_root > bottom + tip]])
    y_crown = np.unique(np.concatenate([[0.0], np.linspace(0.0, y_contact, n_crown // 2 + 1),
                                        np.linspace(y_contact, table, n_crown // 2 + 1)]))
    heights = np.unique(np.concatenate([y_root, y_crown]))

    theta = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ux, uz = _superellipse(theta, recipe.squareness)

    rings = []
    for y in heights:
        a, b = float(a_of(y)), float(b_of(y))
        if y < bottom + tip:  # round the apex (or trunk floor) like a half ellipsoid
            f = np.sqrt(max(0.0, 1 - ((bottom + tip - y) / tip) ** 2))
            a, b = a * max(f, 1e-3), b * max(f, 1e-3)
        rings.append(np.column_stack([a * ux, np.full(n, y), b * uz]))
    # Occlusal cap: rings shrinking toward the centre, lifted by the cusp height field.
    n_cap = max(2, n // 4)
    a_top, b_top = float(a_of(table)), float(b_of(table))
    for rho in np.linspace(1.0, 0.0, n_cap + 1)[:-1]:
        x, z = rho * a_top * ux, rho * b_top * uz
        rings.append(np.column_stack([x, table + occlusal(x, z), z]))
    top = np.array([0.0, table + float(occlusal(np.zeros(1), np.zeros(1))[0]), 0.0])
    body = _loft(rings, np.array([0.0, bottom, 0.0]), top)

    landmarks = _landmarks(recipe, occlusal, arch, ttype, half_md, half_bl, y_contact, table)
    mesh = body
    if multi:
        parts = [body] + [_root_mesh(r, recipe, cerv_a, cerv_b, L, n) for r in recipe.roots]
        mesh = trimesh.boolean.union(parts, engine="manifold")
        if mesh.volume < 0:
            mesh.invert()
    if n >= REFINED_FROM:
        mesh = trimesh.Trimesh(*split_long_edges(mesh.vertices, mesh.faces, REFINED_FROM / n), process=False)
    landmarks["apex"] = np.array([0.0, -L, 0.0])
    crown_height = float(mesh.vertices[:, 1].max())
    return ToothShape(mesh, crown_height, y_contact, landmarks)


def _landmarks(recipe, occlusal, arch: Arch, ttype: ToothType, half_md: float, half_bl: float, y_contact: float,
               table: float) -> dict[str, np.ndarray]:
    """The crown's landmarks in the local frame (mm): contact points, cusp tips, a lower molar's
    buccal groove."""
    landmarks = {
        "mesial_contact": np.array([half_md, y_contact, 0.0]),
        "distal_contact": np.array([-half_md, y_contact, 0.0]),
    }
    for cusp in recipe.cusps:
        cx, cz = occlusal.cusp_xz(cusp)
        landmarks[cusp.name] = np.array([cx, table + float(occlusal(np.array([cx]), np.array([cz]))[0]), cz])
    if arch is Arch.LOWER and ttype.is_molar:
        # The buccal groove runs between the mesiobuccal and distobuccal cusps, on the buccal face.
        mb, db = landmarks["mb_cusp"], landmarks["db_cusp"]
        landmarks["buccal_groove"] = np.array([(mb[0] + db[0]) / 2, y_contact, half_bl])
    return landmarks


def _root_mesh(root: Root, recipe: ShapeRecipe, cerv_a: float, cerv_b: float, L: float, n: int) -> trimesh.Trimesh:
    """One tapered root of a multi-rooted tooth: from inside the trunk down to its apex at -L."""
    trunk_a, trunk_b = TRUNK * cerv_a, TRUNK * cerv_b
    top_y = -recipe.trunk + 0.8
    top_c = np.array([root.x * trunk_a, top_y, root.z * trunk_b])
    apex_c = np.array([root.x * trunk_a * root.spread, -L, root.z * trunk_b * root.spread])
    ra, rb = root.width * trunk_a, root.depth * trunk_b
    m = max(6, n // 2 + n // 2 % 2)
    theta = np.linspace(0, 2 * np.pi, m, endpoint=False)
    ux, uz = _superellipse(theta, 2.2)
    n_rings = max(3, n // 3)
    rings = []
    for s in np.linspace(0.0, 1.0, n_rings + 1)[:-1]:
        c = top_c + s * (apex_c - top_c)
        taper = 1.0 - 0.45 * s
        if s > 0.8:  # rounded tip
            taper *= np.sqrt(max(0.0, 1 - ((s - 0.8) / 0.2) ** 2)) * 0.9 + 0.1
        rings.append(np.column_stack([c[0] + ra * taper * ux, np.full(m, c[1]), c[2] + rb * taper * uz]))
    top_cap = top_c + np.array([0.0, 0.3, 0.0])
    return _loft(rings, top_cap, apex_c)

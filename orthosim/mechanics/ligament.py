"""A tooth held by its periodontal ligament: the root's 6x6 stiffness, its centre of resistance and the
instantaneous motion (and centre of rotation) of any force system, from the root's geometry alone.

The ligament is a thin elastic layer between the root and the bone, apical of the alveolar crest.
A thin layer of modulus E, Poisson's ratio nu and thickness t bonded on both faces resists a
displacement u of one face against the other with a traction k_n (u.n) n + k_s (u - (u.n) n) per
unit area, where k_n = E (1 - nu) / ((1 + nu)(1 - 2 nu) t) is the layer's confined (oedometric)
modulus over its thickness and k_s = E / (2 (1 + nu) t) its shear modulus over its thickness (the
Winkler-type thin-layer idealisation; it ignores the layer's bulging at its edges). A triangle of
area a, outward normal n and centroid r then adds K = a (k_n n n^T + k_s (I - n n^T)) to the
translational block, and the moments of these tractions about the tooth-frame origin fill the rest:

    [F]   [ sum K          -sum K [r]x      ] [t    ]
    [M] = [ sum [r]x K     -sum [r]x K [r]x ] [theta]

F in N and M in N*mm for a translation t (mm) of the origin and a small rotation theta (rad). The
ratio k_n / k_s = 2 (1 - nu) / (1 - 2 nu) alone fixes where the tooth turns; E and t only scale it.

Centre of resistance. With A the translational block and B = sum [r]x K the coupling block, a
force F through a point c turns the tooth by C_rr (H + [c]x) F with H = -B A^-1 (mm) and C_rr the
rotational compliance: it translates the tooth without turning it only if H + [c]x = 0. A root
symmetric about its axis has such a point; an asymmetric one does not. The least-squares centre
removes the skew part of H ([c]x = -skew(H)); what is left, sym(H), is the residual (its Frobenius
norm in mm, 0 for a symmetric root), and its eigenvectors are the principal axes of resistance:
a force along one of them through c makes the tooth screw about it rather than tip (Viecilli RF,
Budiman A, Burstone CJ. 2013. Axes of resistance for tooth movement: does the center of resistance
exist in 3-dimensional space? Am J Orthod Dentofacial Orthop 143(2):163-172; not read, the idea as
the issue states it).

Published values (the defaults and the ranges a case may set):
  modulus_mpa     0.68 MPa, a value common in finite-element models of the ligament; the models'
                  values span 0.01 to 68.9 MPa (Fill TS, Toogood RW, Major PW, Carey JP. 2012.
                  Analytically determined mechanical properties of, and models for the periodontal
                  ligament: critical review of literature. J Biomech 45(1):9-16; the span as quoted
                  by J Med Biol Eng 2022, doi 10.1007/s40846-022-00724-5; the review itself not read).
  poisson         0.45, within the 0.28-0.49 the same models use (not read).
  thickness_mm    0.2 mm, within the 0.15-0.38 mm of histological measurement (Coolidge ED. 1937.
                  The thickness of the human periodontal membrane. J Am Dent Assoc 24:1260-1270; not read).
  crest_below_cej_mm  1.5 mm, within the 0.4-1.9 mm (95 % limits) of sites with no attachment loss
                  (Hausmann E, Allen K, Clerehugh V. 1991. What alveolar crest level on a bite-wing
                  radiograph represents bone loss? J Periodontol 62(9):570-572; abstract read).
Where the crest sits is what moves the centre of resistance; modulus and thickness scale the
stiffness, not where the tooth turns. Units throughout: mm, N, N*mm, rad, in the tooth frame
(origin at the CEJ on the long axis, +y toward the crown, see `orthosim.model.tooth`).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from orthosim.errors import CaseError

if TYPE_CHECKING:  # a case file's [ligament] table is read without loading the meshes' libraries
    from orthosim.model.tooth import Tooth

# published ranges (see the module text): field -> (low, high)
RANGES: dict[str, tuple[float, float]] = {
    "modulus_mpa": (0.01, 68.9),
    "poisson": (0.28, 0.49),
    "thickness_mm": (0.15, 0.38),
    "crest_below_cej_mm": (0.4, 1.9),
}
# The rate law's reference root (`orthosim.mechanics.ratelaw`: 200 mm^2, a single-rooted premolar's
# whole root surface) counted the way the ligament counts a root, apical of the healthy crest: the
# parametric upper second premolar's embedded surface over its whole root surface (173.5 / 202.7 mm^2
# with the crest 1.5 mm below the CEJ; 0.855-0.868 over the parametric types; a test recomputes it).
# A rate law on embedded surfaces divides them by it, so the reference premolar keeps its rate.
EMBEDDED_SHARE_OF_REFERENCE = 0.856


@dataclass(frozen=True)
class LigamentProperties:
    """The ligament's material and where the bone starts (see the module text for sources).

    modulus_mpa: Young's modulus (MPa = N/mm^2). poisson: Poisson's ratio. thickness_mm: layer
    thickness (mm). crest_below_cej_mm: healthy alveolar crest depth below the CEJ (mm). Each must
    lie in its published range (`RANGES`), else a CaseError naming the field.
    """

    modulus_mpa: float = 0.68
    poisson: float = 0.45
    thickness_mm: float = 0.2
    crest_below_cej_mm: float = 1.5

    def __post_init__(self):
        for name, (low, high) in RANGES.items():
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and low <= value <= high):
                raise CaseError(None, f"ligament.{name}", f"{value!r} is outside the published range {low:g} to {high:g}",
                                f"set ligament.{name} between {low:g} and {high:g}")

    @property
    def normal_stiffness_n_per_mm3(self) -> float:
        """k_n (N/mm^3): the layer's normal traction per mm of normal displacement, per mm^2."""
        E, nu, t = self.modulus_mpa, self.poisson, self.thickness_mm
        return E * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu) * t)

    @property
    def shear_stiffness_n_per_mm3(self) -> float:
        """k_s (N/mm^3): the layer's shear traction per mm of tangential displacement, per mm^2."""
        return self.modulus_mpa / (2.0 * (1.0 + self.poisson) * self.thickness_mm)


DEFAULT = LigamentProperties()


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) the cross-product matrices [v]x of (..., 3) vectors."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def _unskew(S: np.ndarray) -> np.ndarray:
    """(3,) the vector of the skew part of a (3, 3) matrix: [v]x = (S - S^T) / 2."""
    return 0.5 * np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


@dataclass(frozen=True, eq=False)
class RootSupport:
    """A tooth's ligament, in the tooth frame (origin at the CEJ on the long axis, +y crown, mm).

    stiffness: (6, 6) [F; M] = stiffness @ [t; theta] about the origin; blocks N/mm, N, N*mm/rad.
    embedded_area_mm2: root surface apical of the crest (mm^2).
    center_of_resistance: (3,) mm, the least-squares centre (see the module text).
    resistance_axes: (3, 3) rows: the principal axes of resistance (unit vectors).
    resistance_residual_mm: how far the root is from having an exact centre (mm; 0 when symmetric).
    crest_below_cej_mm: the crest depth used (mm).
    """

    stiffness: np.ndarray
    embedded_area_mm2: float
    center_of_resistance: np.ndarray
    resistance_axes: np.ndarray
    resistance_residual_mm: float
    crest_below_cej_mm: float = DEFAULT.crest_below_cej_mm

    def motion(self, force_N, point_mm, couple_Nmm=0.0) -> tuple[np.ndarray, np.ndarray]:
        """The instantaneous (translation_mm (3,) of the tooth-frame origin, rotation_rad (3,)) under a
        force force_N (3,) N through point_mm (3,) mm and a couple couple_Nmm (3,) N*mm, tooth frame."""
        F = np.asarray(force_N, float).reshape(3)
        M = np.cross(np.asarray(point_mm, float).reshape(3), F) + np.broadcast_to(np.asarray(couple_Nmm, float), (3,))
        u = np.linalg.solve(self.stiffness, np.concatenate([F, M]))
        return u[:3], u[3:]

    def center_of_rotation(self, force_N, point_mm, couple_Nmm=0.0) -> np.ndarray:
        """(3,) mm, tooth frame: the point of the instantaneous rotation axis nearest the centre of
        resistance; (inf, inf, inf) when the tooth translates (the rotation is negligible)."""
        t, w = self.motion(force_N, point_mm, couple_Nmm)
        ww = float(w @ w)
        scale = float(np.sqrt(t @ t)) + 1e-300
        if ww == 0.0 or np.sqrt(ww) * 1e3 < 1e-9 * scale:  # under 1e-9 mm per mm of travel at 1 m
            return np.full(3, np.inf)
        axis_point = np.cross(w, t) / ww  # where the velocity is along the axis (zero in a plane motion)
        u = w / np.sqrt(ww)
        c = self.center_of_resistance
        return axis_point + u * float((c - axis_point) @ u)

    def center_of_rotation_on_axis(self, force_N, point_mm, couple_Nmm=0.0) -> float:
        """mm, tooth frame y: the level, on the line through the centre of resistance along the long
        axis, whose displacement along the force vanishes (the classical centre of rotation in the
        plane of the force and the long axis); inf when the tooth does not tip in that plane."""
        t, w = self.motion(force_N, point_mm, couple_Nmm)
        c = self.center_of_resistance
        d = np.asarray(force_N, float) / np.linalg.norm(force_N)
        tip = float(np.cross(w, [0.0, 1.0, 0.0]) @ d)  # mm along d per mm up the axis
        along = float((t + np.cross(w, c)) @ d)
        if abs(tip) * 1e3 <= 1e-9 * abs(along):
            return np.inf
        return float(c[1] - along / tip)

    def translation_at(self, point_mm, translation_mm, rotation_rad) -> np.ndarray:
        """(3,) mm: how far the tooth-frame point point_mm moves under a motion from `motion`."""
        return np.asarray(translation_mm, float) + np.cross(rotation_rad, np.asarray(point_mm, float))


def embedded_faces(tooth: Tooth, crest_below_cej_mm: float) -> np.ndarray:
    """(n_faces,) bool: the root's faces whose centroid lies apical of the crest plane y = -crest."""
    centers = tooth.mesh.triangles_center
    from orthosim.model.tooth import ROOT

    return (tooth.face_part == ROOT) & (centers[:, 1] < -float(crest_below_cej_mm))


def stiffness_of_faces(centers: np.ndarray, normals: np.ndarray, areas: np.ndarray,
                       props: LigamentProperties) -> np.ndarray:
    """(6, 6) the thin-layer stiffness (see the module text) of faces with centroids (n, 3) mm,
    unit normals (n, 3) and areas (n,) mm^2, about the origin."""
    kn, ks = props.normal_stiffness_n_per_mm3, props.shear_stiffness_n_per_mm3
    a = np.asarray(areas, float)
    n = np.asarray(normals, float)
    r = np.asarray(centers, float)
    # sums over faces of a n n^T, a (r x n) n^T, a (r x n)(r x n)^T and a r r^T as matrix products
    # (BLAS), without (n, 3, 3) arrays; K_i = a (ks I + (kn - ks) n n^T)
    rn = np.cross(r, n)
    an, ar = a[:, None] * n, a[:, None] * r
    nn, rnn = an.T @ n, (a[:, None] * rn).T @ n
    rr, rnrn = ar.T @ r, (a[:, None] * rn).T @ rn
    A = ks * a.sum() * np.eye(3) + (kn - ks) * nn
    B = ks * skew(ar.sum(axis=0)) + (kn - ks) * rnn
    D = ks * (np.trace(rr) * np.eye(3) - rr) + (kn - ks) * rnrn
    K = np.empty((6, 6))
    K[:3, :3], K[3:, :3], K[:3, 3:], K[3:, 3:] = A, B, B.T, D
    return K


def resistance_of(K: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(centre (3,) mm, axes (3, 3) rows, residual mm) of a (6, 6) stiffness (see the module text)."""
    A, B = K[:3, :3], K[3:, :3]
    H = -B @ np.linalg.inv(A)
    c = -_unskew(H)
    S = 0.5 * (H + H.T)
    values, vectors = np.linalg.eigh(S)
    order = np.argsort(-np.abs(values))
    return c, vectors[:, order].T.copy(), float(np.linalg.norm(S))


# tooth -> {(properties, crest mm): its RootSupport}: a tooth model never changes, so its ligament is
# worked out once per process however many movement models, evidence rows or spread runs ask
_KNOWN: "weakref.WeakKeyDictionary[Tooth, dict]" = weakref.WeakKeyDictionary()


def root_support(tooth: Tooth, props: LigamentProperties = DEFAULT, crest_below_cej_mm: float | None = None) -> RootSupport:
    """The ligament of `tooth` (its root mesh apical of the crest; see the module text), worked out
    once per tooth model and properties.

    crest_below_cej_mm: this tooth's crest depth below the CEJ (mm) where bone was lost; by default
    the properties' healthy depth. A crest at or beyond the apex, or one that leaves no root face
    embedded, is a CaseError."""
    crest = props.crest_below_cej_mm if crest_below_cej_mm is None else float(crest_below_cej_mm)
    known = _KNOWN.setdefault(tooth, {})
    if (props, crest) not in known:
        known[(props, crest)] = _root_support(tooth, props, crest)
    return known[(props, crest)]


def _root_support(tooth: Tooth, props: LigamentProperties, crest: float) -> RootSupport:
    if crest >= tooth.root_length:
        raise CaseError(None, f"ligament.bone_level_mm.{tooth.fdi}",
                        f"the crest {crest:g} mm below the CEJ is deeper than tooth {tooth.fdi}'s root ({tooth.root_length:.1f} mm)",
                        f"give a bone level shallower than {tooth.root_length:.1f} mm, or extract the tooth")
    keep = embedded_faces(tooth, crest)
    if not keep.any():
        raise CaseError(None, f"ligament.bone_level_mm.{tooth.fdi}",
                        f"tooth {tooth.fdi} has no root surface apical of a crest {crest:g} mm below the CEJ",
                        "give a shallower bone level, or a mesh with the tooth's root")
    mesh = tooth.mesh
    areas = mesh.area_faces[keep]
    K = stiffness_of_faces(mesh.triangles_center[keep], mesh.face_normals[keep], areas, props)
    c, axes, residual = resistance_of(K)
    return RootSupport(K, float(areas.sum()), c, axes, residual, crest)

"""How a tooth moves under a force system: the linear PDL model, the paper's wire models, the rate law.

Model data (`ToothMechanics`, built once per tooth, local frame, mm) is kept apart from the state
(the tooth's pose and the forces of a step). Conventions: forces in cN, moments in cN*mm, lengths in
mm, time in days, angles in radians inside the code (degrees in reports).

Rate law (`RateLaw`). A tooth moves only above a threshold force, then faster with the load until
the rate saturates; the same force moves a tooth with a large root (a molar) more slowly, because
what drives remodelling is the stress in the periodontal ligament. So the force is first scaled to
the reference root surface, F_eff = F * A_ref / A_root, and

    rate(F) = r_max * clip((F_eff - F_0) / (F_sat - F_0), 0, 1)        mm/day

with F_0 = 20 cN, F_sat = 150 cN, r_max = 1 mm per 30 days and A_ref = 200 mm^2 (a single-rooted
premolar's root surface). A premolar under 100 cN then moves 0.62 mm a month and under 150 cN
1 mm a month: the literature's 0.5 to 1 mm a month for bodily movement at 100 to 150 cN. A first
molar (about 300 mm^2 of root) under 150 cN moves 0.6 mm a month: molars are anchorage.
These are the paper's replication values (`PARAMETER_SETS["paper"]`, every case's default). The
"clinical" set is fitted to the evidence table (`orthosim/evidence/evidence.toml`; the fit is
`orthosim.analysis.calibration`, its residuals in docs/notes/clinical-evidence.md) and adds a
mandibular bone factor k: a lower tooth resists as if its root surface were k times larger
(A_root -> k A_root above), standing for the mandible's denser bone, which trials find moves
canines more slowly than the maxilla.

Force system to motion (Smith and Burstone's linear model). A force F at point P and a couple M
act on a tooth whose centre of resistance is C. The centre of resistance translates at rate(F)
along F, and the tooth turns at omega = M_C / sigma^2 * rate(F) / |F| (rad/day), M_C the net
moment about C. The centre of rotation then lies sigma^2 / (d - M/F) apical of C, d the distance
from C to the bracket and M/F the couple-to-force ratio at the bracket. sigma^2 (mm^2) is set per
tooth so that M/F = 7 mm puts the centre of rotation at the apex (controlled tipping), which gives
the classical table: M/F 0 to 5 mm uncontrolled tipping, about 7 controlled tipping, about 10
(= d) translation, 12 or more root movement (`movement_type`).

Wire models (the paper's):
  rectangular + force: the wire supplies the counter-moment (M/F = d): pure translation along F,
      in x, y and z;
  rectangular + force + couple: the user's force system as it stands (the M/F table decides);
  rectangular + couple alone: rotation about the bracket, the centre of rotation at the crown;
      a couple about the long axis turns the tooth about its long axis;
  round + force (or couple): no counter-moment, the tooth only rotates, about the point at 1/3 of
      root length from the apex (`resistance.tipping_center`), which does not translate.
A couple acting alone turns the tooth as fast as the force M / d at the bracket would move it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthosim.mechanics.vec import length

from orthosim.model.fdi import Arch
from orthosim.mechanics.ratelaw import RateLaw
from orthosim.model.tooth import ROOT, Tooth
from orthosim.mechanics.resistance import center_of_resistance, tipping_center
from orthosim.mechanics.ligament import DEFAULT as DEFAULT_LIGAMENT, EMBEDDED_SHARE_OF_REFERENCE, LigamentProperties, RootSupport, root_support

# Tooth density for masses and inertias (mean of enamel, dentine and root): 2.2 g/cm^3 = 2.2e-3 g/mm^3.
DENSITY_G_PER_MM3 = 2.2e-3
LOWER = Arch.LOWER
CONTROLLED_TIPPING_MF_MM = 7.0  # M/F (mm) that puts the centre of rotation at the apex
AXIAL_LEVER_MM = 3.0  # lever (mm) of a couple about the long axis: about half a crown's width


@dataclass(frozen=True, eq=False)
class ToothMechanics:
    """What the movement model needs of one tooth, built once (local frame, mm, g)."""

    fdi: int
    center_of_resistance: np.ndarray  # (3,) mm local
    tipping_center: np.ndarray  # (3,) mm local: round-wire centre of rotation, 1/3 root length from apex
    bracket: np.ndarray  # (3,) mm local: labial/buccal crown surface at mid-crown height
    crown_center: np.ndarray  # (3,) mm local
    apex: np.ndarray  # (3,) mm local
    root_area_mm2: float
    sigma2_mm2: float  # Smith-Burstone constant (mm^2) of the tooth
    mass_g: float
    center_of_mass: np.ndarray  # (3,) mm local
    inertia_g_mm2: np.ndarray  # (3, 3) g*mm^2 about the centre of mass, local axes
    bone_factor: float = 1.0  # the rate law's mandibular bone factor for a lower tooth, 1 for an upper one
    support: RootSupport | None = None  # the ligament (rule "ligament"): the step moves the tooth by its compliance
    # the share of the rate law's reference root its area counts (`ligament.EMBEDDED_SHARE_OF_REFERENCE`
    # for an embedded area; 1 for a whole root)
    reference_share: float = 1.0

    @property
    def resisting_area_mm2(self) -> float:
        """mm^2: the root surface the rate law scales the force by (root area times the bone factor; an
        embedded area over the reference root's embedded share, so the reference premolar keeps its rate)."""
        area = self.root_area_mm2 * self.bone_factor if self.bone_factor != 1.0 else self.root_area_mm2
        return area / self.reference_share if self.reference_share != 1.0 else area

    @property
    def bracket_lever_mm(self) -> float:
        """mm, centre of resistance to bracket along the long axis (the d of M/F)."""
        return float(self.bracket[1] - self.center_of_resistance[1])

    @property
    def cr_to_apex_mm(self) -> float:
        return float(self.center_of_resistance[1] - self.apex[1])


def bracket_point(tooth: Tooth) -> np.ndarray:
    """(3,) local mm: the labial (buccal) crown surface at mid-crown height, where a bracket sits."""
    v = tooth.mesh.vertices
    cv = tooth.crown_vertices if len(tooth.crown_vertices) else v[v[:, 1] >= 0]
    y = float(tooth.crown_center[1])
    h = max(0.15 * (cv[:, 1].max() - 0.0), 0.5)
    band = cv[np.abs(cv[:, 1] - y) <= h]
    if not len(band):
        band = cv
    w = max(0.25 * np.ptp(band[:, 0]), 0.5)
    mid = band[np.abs(band[:, 0] - tooth.crown_center[0]) <= w]
    z = float((mid if len(mid) else band)[:, 2].max())
    return np.array([float(tooth.crown_center[0]), y, z])


def build_mechanics(tooth: Tooth, rule: str = "literature", fraction: float = 0.4,
                    law: RateLaw | None = None, ligament: LigamentProperties = DEFAULT_LIGAMENT,
                    crest_below_cej_mm: float | None = None) -> ToothMechanics:
    """The tooth's mechanics (centre of resistance by `rule`, see `resistance`; rule "ligament": from
    the root's stiffness, `ligament`, with the tooth's crest `crest_below_cej_mm` below the CEJ, mm,
    the ligament's healthy one by default); mass at 2.2 g/cm^3; a lower tooth takes `law`'s
    mandibular bone factor (none without a law)."""
    bracket = bracket_point(tooth)
    support = None
    if rule == "ligament":
        support = root_support(tooth, ligament, crest_below_cej_mm)
        cr = support.center_of_resistance
        area = support.embedded_area_mm2
        sigma2 = _ligament_sigma2(support, bracket)
    else:
        cr = center_of_resistance(tooth, rule, fraction)
        d = float(bracket[1] - cr[1])
        h = float(cr[1] - tooth.apex[1])
        # sigma^2 / (d - 7) = h: M/F = 7 mm puts the centre of rotation at the apex
        sigma2 = max(d - CONTROLLED_TIPPING_MF_MM, 1.0) * max(h, 1.0)
        area = float(tooth.mesh.area_faces[tooth.face_part == ROOT].sum()) or float(tooth.mesh.area) / 2
    mesh = tooth.mesh
    if mesh.is_volume:
        mass = float(mesh.volume) * DENSITY_G_PER_MM3
        com = np.asarray(mesh.center_mass, float)
        inertia = np.asarray(mesh.moment_inertia, float) * DENSITY_G_PER_MM3  # trimesh: unit density
    else:  # open scan: a box of the bounds stands in
        ext = mesh.extents
        mass = float(np.prod(ext)) * 0.5 * DENSITY_G_PER_MM3
        com = mesh.bounds.mean(axis=0)
        inertia = np.diag([ext[1] ** 2 + ext[2] ** 2, ext[0] ** 2 + ext[2] ** 2, ext[0] ** 2 + ext[1] ** 2]) * mass / 12
    bone = law.mandibular_bone_factor if law is not None and tooth.arch == LOWER else 1.0
    return ToothMechanics(tooth.fdi, cr, tipping_center(tooth), bracket, np.asarray(tooth.crown_center, float),
                          np.asarray(tooth.apex, float), area, sigma2, mass, com, inertia, bone, support,
                          EMBEDDED_SHARE_OF_REFERENCE if support is not None else 1.0)


def _ligament_sigma2(support: RootSupport, bracket: np.ndarray) -> float:
    """mm^2: Smith and Burstone's sigma^2 the ligament gives: the lever d (bracket to centre of
    resistance along the long axis) times how far apical of the centre a lingual force at the
    bracket turns the tooth (so that `movement_type` names the ligament's motions)."""
    c = support.center_of_resistance
    d = float(bracket[1] - c[1])
    y = support.center_of_rotation_on_axis(np.array([0.0, 0.0, -1.0]), bracket)
    return max(d * float(c[1] - y), 1e-6) if np.isfinite(y) else 1e-6


def center_of_rotation_offset(mech: ToothMechanics, m_over_f_mm: float) -> float:
    """mm from the centre of resistance to the centre of rotation along the long axis, apical positive,
    for a force at the bracket with couple-to-force ratio M/F (mm) opposing its tipping; inf = translation."""
    denom = mech.bracket_lever_mm - m_over_f_mm
    return np.inf if abs(denom) < 1e-9 else mech.sigma2_mm2 / denom


def movement_type(mech: ToothMechanics, m_over_f_mm: float, apex_tolerance_mm: float = 1.5) -> str:
    """The classical name of the movement a bracket force with ratio M/F (mm) makes:
    'uncontrolled tipping' (centre of rotation between the centre of resistance and the apex),
    'controlled tipping' (at the apex, within `apex_tolerance_mm`, or beyond it), 'translation'
    (M/F within 1 mm of the bracket lever d), 'root movement' (centre of rotation on the crown side)."""
    if abs(mech.bracket_lever_mm - m_over_f_mm) <= 1.0:
        return "translation"
    x = center_of_rotation_offset(mech, m_over_f_mm)
    if x < 0:
        return "root movement"
    if x < mech.cr_to_apex_mm - apex_tolerance_mm:
        return "uncontrolled tipping"
    return "controlled tipping"


@dataclass(frozen=True)
class Motion:
    """A tooth's rigid velocity over a step (arch frame): the `pivot` (mm) moves at `velocity`
    (mm/day) while the tooth turns at `omega` (rad/day, rotation vector rate) about it."""

    pivot: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray

    @staticmethod
    def still(point=np.zeros(3)) -> "Motion":
        return Motion(np.asarray(point, float), np.zeros(3), np.zeros(3))

    @property
    def is_still(self) -> bool:
        return not (self.velocity.any() or self.omega.any())

    def displacement(self, points: np.ndarray, dt_days: float) -> np.ndarray:
        """(n, 3) mm: how far each arch-frame point (n, 3) of the tooth moves in dt_days."""
        R = self.rotation(dt_days)
        p = np.asarray(points, float).reshape(-1, 3)
        return (p - self.pivot) @ R.T + self.pivot + self.velocity * dt_days - p

    def rotation(self, dt_days: float) -> np.ndarray:
        """(3, 3) the turn made in dt_days (the last one asked is kept: a step asks for the same
        one many times; the motion is frozen, so it cannot go stale)."""
        known = self.__dict__.get("_turn")
        if known is not None and known[0] == dt_days:
            return known[1]
        R = _rotation(self.omega * dt_days)
        object.__setattr__(self, "_turn", (dt_days, R))
        return R

    def apply(self, pose: np.ndarray, dt_days: float) -> np.ndarray:
        """(4, 4) pose after dt_days of this motion, from `pose` (4, 4, local -> arch frame, mm)."""
        R = self.rotation(dt_days)
        M = np.eye(4)
        M[:3, :3] = R
        M[:3, 3] = self.pivot + self.velocity * dt_days - R @ self.pivot
        return M @ pose


def _rotation(rotvec: np.ndarray) -> np.ndarray:
    from orthosim.geometry.pose import rotation_about_axis

    a = length(rotvec)
    return np.eye(3) if a == 0.0 else rotation_about_axis(rotvec / a, a)


def tooth_motion(mech: ToothMechanics, pose: np.ndarray, force_cN: np.ndarray, point: np.ndarray,
                 couple_cNmm: np.ndarray, wire: str, translation_only: bool, law: RateLaw) -> Motion:
    """The tooth's motion under one resultant force system (see the module text).

    pose: (4, 4) local -> arch frame (mm). force_cN: (3,) arch-frame force (cN); point: (3,)
    arch-frame point of application (mm); couple_cNmm: (3,) arch-frame couple (cN*mm).
    wire: 'rectangular' or 'round'. translation_only: the movement asked is bodily (translation,
    extrusion, intrusion): a rectangular wire then cancels every moment.
    """
    R, p = pose[:3, :3], pose[:3, 3]
    C = R @ mech.center_of_resistance + p
    B = R @ mech.bracket + p
    axis = R[:, 1]
    F = np.asarray(force_cN, float)
    Mc = np.asarray(couple_cNmm, float)
    f = length(F)
    area = mech.resisting_area_mm2
    if wire == "round":
        Q = R @ mech.tipping_center + p
        M = (np.cross(np.asarray(point, float) - Q, F) if f > 0 else 0.0) + Mc
        m = length(M)
        lever = length((point if f > 0 else B) - Q) or 1.0
        if m == 0.0:
            return Motion.still(Q)
        return Motion(Q, np.zeros(3), M / m * law.rate(m / lever, area) / lever)
    if f > 0 and (translation_only or not np.any(Mc)):
        return Motion(C, F / f * law.rate(f, area), _axial_spin(Mc, axis, area, law) if not translation_only else np.zeros(3))
    if f > 0:  # force and couple: the user's force system, Smith and Burstone
        return free_motion(mech, pose, F, point, Mc, law)
    # a couple alone: the long-axis part turns the tooth about its long axis (through C), the rest
    # about the bracket (the paper's centre of rotation at the crown)
    spin = _axial_spin(Mc, axis, area, law)
    rest = Mc - axis * (Mc @ axis)
    d = length(B - C) or 1.0
    m = length(rest)
    tip = rest / m * law.rate(m / d, area) / d if m > 0 else np.zeros(3)
    if not np.any(tip):
        return Motion(C, np.zeros(3), spin)
    if not np.any(spin):
        return Motion(B, np.zeros(3), tip)
    return Motion(B, np.cross(spin, B - C), spin + tip)  # both: first order in the step's angle


def free_motion(mech: ToothMechanics, pose: np.ndarray, force_cN: np.ndarray, point: np.ndarray,
                couple_cNmm: np.ndarray, law: RateLaw) -> Motion:
    """Smith and Burstone's motion of a tooth under a force system no wire constrains: the centre of
    resistance translates at rate(|F|) along F and the tooth turns at M_C / sigma^2 * rate / |F|
    (rad/day), M_C the net moment (cN*mm) about the centre of resistance. pose (4, 4) local -> arch
    frame; force_cN (3,) cN and point (3,) mm, couple_cNmm (3,) cN*mm, all arch frame; |F| > 0."""
    R, p = pose[:3, :3], pose[:3, 3]
    C = R @ mech.center_of_resistance + p
    F = np.asarray(force_cN, float)
    f = length(F)
    M = np.cross(np.asarray(point, float) - C, F) + np.asarray(couple_cNmm, float)
    r = law.rate(f, mech.resisting_area_mm2)
    return Motion(C, F / f * r, M / mech.sigma2_mm2 * r / f)


def _axial_spin(Mc: np.ndarray, axis: np.ndarray, area: float, law: RateLaw) -> np.ndarray:
    m = float(Mc @ axis)
    if m == 0.0:
        return np.zeros(3)
    return axis * np.sign(m) * law.rate(abs(m) / AXIAL_LEVER_MM, area) / AXIAL_LEVER_MM

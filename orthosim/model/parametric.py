"""The parametric dentition: 28 (or 32) parametric teeth placed in normal occlusion.

Placement, in the arch frame (see `orthosim.model.dentition`):
  1. The lower arch follows a Braun beta curve of chosen width whose half length equals the sum of
     the lower mesiodistal widths, so the teeth fill it from the midline to the second molars.
     Each tooth's two contact points sit on the curve, its labial axis along the curve's outward
     normal, its long axis vertical (incisors inclined labially); lower crowns reach up to y = 0.
  2. Neighbours are then made to just touch: each tooth, from the midline outward, slides along
     the curve until the exact mesh distance (FCL) to its mesial neighbour lies in [0, 0.05] mm.
  3. The upper arch is a beta curve too, its width and depth solved so that the measured overjet
     is the asked one (2 mm) and the upper first molar's mesiobuccal cusp sits over the lower
     buccal groove (Angle class I). Upper incisors and canines end `overbite` mm below the lower
     incisal edges; the upper premolars and molars are lowered together until they just touch
     the lower teeth (no interpenetration).
The origin is mid-arch: x = 0 on the midline, z = 0 half way along the lower arch's depth, y = 0
the occlusal plane (lower cusp tips).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from orthosim.model import fdi as F
from orthosim.model.anatomy import dimensions
from orthosim.model.archform import BetaArch, arch_with_half_length
from orthosim.model.dentition import Dentition
from orthosim.model.occlusion import molar_relation, overjet
from orthosim.model.tooth import CROWN, Tooth, part_of_faces

if TYPE_CHECKING:  # imported where the model is built: a cached model needs neither trimesh, FCL nor numba
    import trimesh

    from orthosim.geometry.meshquery import MeshQuery

CONTACT_GAP_MAX = 0.05  # mm: the largest gap accepted between teeth that should touch


@dataclass(frozen=True)
class OcclusionSettings:
    """What the parametric model aims for (mm and degrees)."""

    lower_arch_width: float = 52.0  # W of the lower beta curve, at the distal ends of the curve
    overjet: float = 2.0
    overbite: float = 2.0
    molar_relation: float = 0.0  # 0: Angle class I
    upper_incisor_torque_deg: float = 10.0  # crown labial inclination of upper incisors
    lower_incisor_torque_deg: float = 5.0


@dataclass(frozen=True, eq=False)
class _Blank:
    """A parametric tooth in its local frame, before placement."""

    fdi: int
    mesh: trimesh.Trimesh
    landmarks: dict
    contact_level: float
    crown_vertices: np.ndarray  # (k, 3) local
    crown_center: np.ndarray  # (3,) local


def _blank(fdi: int, resolution) -> _Blank:
    from orthosim.model.toothshape import build_tooth_shape

    shape = build_tooth_shape(dimensions(fdi), F.arch_of(fdi), F.tooth_type(fdi), resolution)
    mesh, landmarks = shape.mesh, dict(shape.landmarks)
    if F.quadrant(fdi) in (1, 3):  # mirror image: local +x is distal here (see orthosim.model.tooth)
        v = mesh.vertices.copy()
        v[:, 0] *= -1
        import trimesh  # here, not at the top: a run that loads the model from the cache never imports it

        mesh = trimesh.Trimesh(v, mesh.faces[:, ::-1].copy(), process=False)
        landmarks = {k: p * np.array([-1.0, 1.0, 1.0]) for k, p in landmarks.items()}
    crown = mesh.vertices[np.unique(mesh.faces[part_of_faces(mesh) == CROWN])]
    return _Blank(fdi, mesh, landmarks, shape.contact_level, crown, _crown_center(mesh))


def _mesial_local(fdi: int) -> float:
    return 1.0 if F.quadrant(fdi) in (2, 4) else -1.0


class _ArchPlacer:
    """Poses of one arch's teeth on a beta curve, given per-tooth slides along the curve."""

    def __init__(self, arch: F.Arch, blanks: dict[int, _Blank], settings: OcclusionSettings, z_shift: float):
        self.arch = arch
        self.blanks = blanks
        self.settings = settings
        self.z_shift = z_shift
        self.occlusal = np.array([0.0, -1.0 if arch is F.Arch.UPPER else 1.0, 0.0])
        self.upper_posterior_level = 0.0  # lowest point of upper premolars/molars (y, mm)

    def sides(self) -> dict[int, list[int]]:
        """side -> teeth from the midline distally."""
        quads = (1, 2) if self.arch is F.Arch.UPPER else (4, 3)
        return {s: [10 * q + p for p in range(1, 9) if 10 * q + p in self.blanks] for s, q in zip((-1, 1), quads)}

    def _torque(self, fdi: int) -> float:
        if F.tooth_type(fdi) in (F.ToothType.CENTRAL_INCISOR, F.ToothType.LATERAL_INCISOR):
            deg = self.settings.upper_incisor_torque_deg if self.arch is F.Arch.UPPER else self.settings.lower_incisor_torque_deg
            return np.radians(deg)
        return 0.0

    def pose(self, curve: BetaArch, fdi: int, side: int, s_mesial: float) -> tuple[np.ndarray, float]:
        """(4x4 pose, arc length of the distal contact) of a tooth whose mesial contact is at s_mesial."""
        b = self.blanks[fdi]
        width = dimensions(fdi).md_width
        s_distal = curve.point_at_chord(s_mesial, width, side)
        p0, p1 = curve.point(s_mesial, side), curve.point(s_distal, side)
        m = (p0 - p1) / np.linalg.norm(p0 - p1)
        lab = side * np.array([m[1], -m[0]])
        labial = np.array([lab[0], 0.0, lab[1]])
        tau = self._torque(fdi)
        y_axis = np.cos(tau) * self.occlusal + np.sin(tau) * labial
        z_axis = np.cos(tau) * labial - np.sin(tau) * self.occlusal
        x_axis = np.cross(y_axis, z_axis)
        R = np.column_stack([x_axis, y_axis, z_axis])
        mid = 0.5 * (p0 + p1)
        target = np.array([mid[0], 0.0, mid[1] + self.z_shift])
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = target - R @ np.array([0.0, b.contact_level, 0.0])
        crown_y = (b.crown_vertices @ R.T + T[:3, 3])[:, 1]
        if self.arch is F.Arch.LOWER:
            T[1, 3] -= crown_y.max()
        elif F.tooth_type(fdi).is_anterior:
            T[1, 3] += -self.settings.overbite - crown_y.min()
        else:
            T[1, 3] += self.upper_posterior_level - crown_y.min()
        assert np.allclose(R @ np.array([_mesial_local(fdi), 0, 0]), np.array([m[0], 0, m[1]]), atol=1e-9)
        return T, s_distal

    def place(self, curve: BetaArch, slides: dict[int, float]) -> dict[int, np.ndarray]:
        poses = {}
        for side, teeth in self.sides().items():
            s = 0.0
            for fdi in teeth:
                poses[fdi], s = self.pose(curve, fdi, side, s + slides.get(fdi, 0.0))
        return poses

    def make_contacts(self, curve: BetaArch, slides: dict[int, float], query: MeshQuery,
                      midline_gap: float = 0.0) -> dict[int, float]:
        """Slides (mm along the curve) that make every pair of neighbours touch within CONTACT_GAP_MAX.

        The central incisors instead stand `midline_gap` mm apart (a diastema), within the same tolerance.
        """
        slides = dict(slides)
        sides = self.sides()
        centrals = [t[0] for t in sides.values()]

        def centrals_gap(delta):
            trial = {**slides, centrals[0]: delta, centrals[1]: delta}
            poses = self.place(curve, trial)
            d = query.distance(centrals[0], poses[centrals[0]], centrals[1], poses[centrals[1]])
            return (0.0 if d < midline_gap else d - midline_gap), trial

        slides = _slide_until_touching(centrals_gap, slides.get(centrals[0], 0.0))
        for teeth in sides.values():
            for prev, cur in zip(teeth[:-1], teeth[1:]):
                def gap(delta, prev=prev, cur=cur):
                    trial = {**slides, cur: delta}
                    poses = self.place(curve, trial)
                    return query.distance(prev, poses[prev], cur, poses[cur]), trial

                slides = _slide_until_touching(gap, slides.get(cur, 0.0))
        return slides


def _slide_until_touching(gap, delta0: float) -> dict[int, float]:
    """Find a slide delta with 0 < gap(delta) <= CONTACT_GAP_MAX; gap is 0 when the meshes intersect.

    The gap grows with the slide, so bracket the touching point and bisect: the low end always
    intersects (or touches), the high end is always apart.
    """
    d, trial = gap(delta0)
    if 0.0 < d <= CONTACT_GAP_MAX:
        return trial
    lo = hi = delta0
    if d == 0.0:  # intersecting: open up until apart
        step = 0.05
        while d == 0.0:
            lo, hi = hi, hi + step
            d, trial = gap(hi)
            step *= 2
    else:  # too far apart: close up until intersecting
        while d > 0.0:
            hi, lo = lo, lo - max(d, 0.02)
            d, trial = gap(lo)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        d, trial = gap(mid)
        if 0.0 < d <= CONTACT_GAP_MAX:
            return trial
        if d == 0.0:
            lo = mid
        else:
            hi = mid
    d, trial = gap(hi)
    return trial


def _lower_upper_posterior_until_touching(placer: _ArchPlacer, curve: BetaArch, slides, lower_poses, query: MeshQuery):
    """Set the height of the upper premolars and molars so they just touch the lower teeth."""
    posterior = [t for t in placer.blanks if not F.tooth_type(t).is_anterior]

    def min_distance(level):
        placer.upper_posterior_level = level
        poses = placer.place(curve, slides)
        best = np.inf
        for u in posterior:
            for low in lower_poses:
                if abs(F.position(low) - F.position(u)) <= 2 and F.side(low) == F.side(u):
                    best = min(best, query.distance(u, poses[u], low, lower_poses[low]))
        return best

    lo, hi = -4.0, 4.0  # lo intersects (deep), hi apart
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        d = min_distance(mid)
        if 0.0 < d <= CONTACT_GAP_MAX:
            return
        if d == 0.0:
            lo = mid
        else:
            hi = mid
    min_distance(hi)


def build_parametric_dentition(resolution: int | str = "smooth", third_molars: bool = False,
                               diastema_mm: float = 0.0,
                               settings: OcclusionSettings = OcclusionSettings()) -> Dentition:
    """Build the parametric normal-occlusion model (see the module docstring). Takes a few seconds.

    `diastema_mm` opens a space of that width between the central incisors of both arches (the
    rest of each arch moves distally with them), as in the paper's third case.
    """
    from scipy.optimize import least_squares

    from orthosim.geometry.meshquery import MeshQuery

    positions = range(1, 9) if third_molars else range(1, 8)
    fdis = [10 * q + p for q in F.QUADRANTS for p in positions]
    blanks = {n: _blank(n, resolution) for n in fdis}
    query = MeshQuery({n: b.mesh for n, b in blanks.items()})

    # Lower arch: the curve is as long as the teeth (to the second molars; third molars go beyond).
    lower_half = sum(dimensions(40 + p).md_width for p in range(1, 8)) + 0.5 * diastema_mm
    lower_curve = arch_with_half_length(settings.lower_arch_width, lower_half)
    z_shift = -0.5 * lower_curve.depth
    lower_teeth = {n: b for n, b in blanks.items() if F.arch_of(n) is F.Arch.LOWER}
    upper_teeth = {n: b for n, b in blanks.items() if F.arch_of(n) is F.Arch.UPPER}
    lower = _ArchPlacer(F.Arch.LOWER, lower_teeth, settings, z_shift)
    lower_slides = lower.make_contacts(lower_curve, {}, query, diastema_mm)
    lower_poses = lower.place(lower_curve, lower_slides)

    upper = _ArchPlacer(F.Arch.UPPER, upper_teeth, settings, z_shift)
    probe = Dentition({n: _as_tooth(b, np.eye(4)) for n, b in blanks.items()})

    def fit_upper_curve(slides, guess):
        def residual(wd):
            curve = BetaArch(wd[0], wd[1], 1500)
            poses = {**lower_poses, **upper.place(curve, slides)}
            return [overjet(probe, poses) - settings.overjet, molar_relation(probe, poses) - settings.molar_relation]

        # The upper arch is wider and deeper than the lower one (it overlaps it by about 2 mm in
        # front and at the sides); the bounds keep the solver from wandering to another root.
        lo = [lower_curve.width, lower_curve.depth]
        hi = [lower_curve.width + 15.0, lower_curve.depth + 10.0]
        sol = least_squares(residual, np.clip(guess, lo, hi), bounds=(lo, hi), diff_step=1e-3, xtol=1e-6)
        return BetaArch(*sol.x), sol.x

    guess = np.array([lower_curve.width + 6.0, lower_curve.depth + 2.0])
    upper_slides: dict[int, float] = {}
    for _ in range(2):
        upper_curve, guess = fit_upper_curve(upper_slides, guess)
        _lower_upper_posterior_until_touching(upper, upper_curve, upper_slides, lower_poses, query)
        upper_slides = upper.make_contacts(upper_curve, upper_slides, query, diastema_mm)
    _lower_upper_posterior_until_touching(upper, upper_curve, upper_slides, lower_poses, query)
    upper_slides = upper.make_contacts(upper_curve, upper_slides, query, diastema_mm)
    upper_poses = upper.place(upper_curve, upper_slides)

    poses = {**lower_poses, **upper_poses}
    teeth = {n: _as_tooth(blanks[n], poses[n]) for n in fdis}
    info = {
        "kind": "parametric",
        "resolution": resolution,
        "third_molars": third_molars,
        "diastema_mm": diastema_mm,
        "lower_arch": {"width_mm": lower_curve.width, "depth_mm": lower_curve.depth},
        "upper_arch": {"width_mm": upper_curve.width, "depth_mm": upper_curve.depth},
        "upper_posterior_level_mm": upper.upper_posterior_level,
        "settings": settings.__dict__,
    }
    what = f"diastema {diastema_mm:g} mm" if diastema_mm else "normal occlusion"
    return Dentition(teeth, f"parametric {what} ({len(teeth)} teeth, {resolution})", info)


def _crown_center(mesh: trimesh.Trimesh) -> np.ndarray:
    """Volume centroid of the part of the tooth coronal of the CEJ plane (local y >= 0)."""
    lo, hi = mesh.bounds
    import trimesh

    box = trimesh.creation.box(bounds=[[lo[0] - 1, 0.0, lo[2] - 1], [hi[0] + 1, hi[1] + 1, hi[2] + 1]])
    crown = trimesh.boolean.intersection([mesh, box], engine="manifold")
    return np.asarray(crown.center_mass, float)


def _as_tooth(blank: _Blank, pose: np.ndarray) -> Tooth:
    dims = dimensions(blank.fdi)
    return Tooth(
        fdi=blank.fdi,
        mesh=blank.mesh,
        face_part=part_of_faces(blank.mesh),
        crown_center=blank.crown_center,
        apex=np.array([0.0, -dims.root_length, 0.0]),
        rest_pose=pose,
        landmarks=blank.landmarks,
        source="parametric",
    )


@lru_cache(maxsize=8)
def parametric_dentition(resolution: int | str = "smooth", third_molars: bool = False, diastema_mm: float = 0.0) -> Dentition:
    """The parametric model, built once per process for each set of arguments (Dentition is immutable)
    and kept on disk between processes (`orthosim.model.dentition_cache`)."""
    from orthosim.model.dentition_cache import cached_dentition, parametric_parameters

    return cached_dentition(parametric_parameters(resolution, third_molars, diastema_mm), lambda: build_parametric_dentition(resolution, third_molars, diastema_mm))

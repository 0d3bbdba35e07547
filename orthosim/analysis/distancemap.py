"""The inter-arch distance map: how far every crown vertex lies from the opposing arch, exactly.

What clinicians know as an occlusal map: each crown vertex of one arch gets its signed distance
(mm) to the surface of the opposing arch's tooth meshes (not their sphere trees), negative where
the vertex lies inside an opposing tooth (interpenetration), and a class for the colour bar:
penetration (< 0), contact (< CONTACT_MM), near (up to NEAR_MM), far. The same query against a
tooth's neighbours in its own arch gives the contact areas of the paper's Figure 7.

Exactness: a distance is the minimum over triangles of the exact point-triangle distance, computed
in float64, signed by the closest feature's pseudonormal (`geometry.signeddistance`, one index per
tooth in its local frame, built once: the model). Distances beyond `cap_mm` are not resolved: they
are reported as +inf ("far"), which is what keeps a whole arch's map to a fraction of a second
(see the report bench, `report_s`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping

import numpy as np

from orthosim.geometry.signeddistance import mesh_surface
from orthosim.model.dentition import Dentition
from orthosim.model.fdi import Arch, arch_of

CONTACT_MM = 0.1  # closer than this (and not penetrating) counts as contact
NEAR_MM = 2.0  # up to this is "near"; beyond it "far"
CAP_MM = 5.0  # distances beyond this are not resolved (reported as +inf)

PENETRATION, CONTACT, NEAR, FAR = 0, 1, 2, 3
CLASS_NAMES = ("penetration", "contact", "near", "far")


@dataclass(frozen=True)
class ToothDistances:
    """One tooth's crown vertices (in `Tooth.crown_vertices` order) and their signed distances (mm)."""

    fdi: int
    distance_mm: np.ndarray  # (k,) signed, negative = inside another tooth, +inf = beyond CAP_MM
    nearest: np.ndarray  # (k,) FDI of the tooth that distance is to (0 where beyond the cap)

    @property
    def classes(self) -> np.ndarray:
        return classify(self.distance_mm)


def classify(distance_mm: np.ndarray) -> np.ndarray:
    """(n,) signed distances (mm) -> (n,) int8 classes PENETRATION, CONTACT, NEAR, FAR."""
    d = np.asarray(distance_mm, float)
    return np.select([d < 0.0, d < CONTACT_MM, d <= NEAR_MM], [PENETRATION, CONTACT, NEAR], FAR).astype(np.int8)


class DistanceMapModel:
    """The model side of distance maps: each tooth's surface index and crown vertices, built once.

        maps = DistanceMapModel(dentition)
        before = maps.inter_arch(rest_poses, absent=extracted)  # FDI -> ToothDistances
    """

    def __init__(self, dentition: Dentition):
        self.dentition = dentition
        self.surfaces = {n: mesh_surface(t.mesh) for n, t in dentition.teeth.items()}

    def distances(self, poses: Mapping[int, np.ndarray], fdi: int, others: Iterable[int],
                  cap_mm: float = CAP_MM) -> ToothDistances:
        """Signed distances (mm) of `fdi`'s crown vertices, posed, to the union of `others`' meshes, posed."""
        tooth = self.dentition.teeth[fdi]
        world = tooth.to_world(tooth.crown_vertices, poses[fdi])
        best = np.full(len(world), np.inf)
        nearest = np.zeros(len(world), np.int64)
        lo, hi = world.min(axis=0), world.max(axis=0)
        center, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2
        for other in others:
            s = self.surfaces[other]
            T = np.asarray(poses[other], float)
            s_center, s_radius = s.bounding_sphere
            if np.linalg.norm(T[:3, :3] @ s_center + T[:3, 3] - center) > radius + s_radius + cap_mm:
                continue  # no crown vertex can come within the cap of this tooth
            local = (world - T[:3, 3]) @ T[:3, :3]
            d, _ = s.signed_distance(local, cap_mm)
            better = d < best
            best[better], nearest[better] = d[better], other
        return ToothDistances(fdi, best, nearest)

    def inter_arch(self, poses: Mapping[int, np.ndarray], absent: Iterable[int] = (),
                   cap_mm: float = CAP_MM) -> dict[int, ToothDistances]:
        """FDI -> distances of its crown vertices to the opposing arch (teeth in `absent` left out)."""
        absent = set(absent)
        present = [n for n in self.dentition.fdis if n not in absent]
        return {n: self.distances(poses, n, [m for m in present if arch_of(m) != arch_of(n)], cap_mm) for n in present}

    def contacts(self, poses: Mapping[int, np.ndarray], absent: Iterable[int] = (),
                 cap_mm: float = NEAR_MM) -> dict[int, ToothDistances]:
        """FDI -> distances of its crown vertices to every other present tooth: the opposing arch and
        its neighbours in its own arch (the contact areas of the paper's Figure 7)."""
        absent = set(absent)
        present = [n for n in self.dentition.fdis if n not in absent]
        return {n: self.distances(poses, n, [m for m in present if m != n], cap_mm) for n in present}


def summarize(maps: Mapping[int, ToothDistances]) -> dict:
    """Figures of one map, ready for JSON: vertices per class, the deepest penetration and the
    closest approach (mm), per arch and overall."""
    out = {}
    for label, arch in (("upper", Arch.UPPER), ("lower", Arch.LOWER), ("both", None)):
        ds = [m.distance_mm for n, m in maps.items() if arch is None or arch_of(n) is arch]
        d = np.concatenate(ds) if ds else np.zeros(0)
        cls = classify(d)
        out[label] = {
            "vertices": int(len(d)),
            **{name: int((cls == i).sum()) for i, name in enumerate(CLASS_NAMES)},
            "min_distance_mm": float(d.min()) if len(d) and np.isfinite(d.min()) else None,
        }
    return out

"""The tooth model: one tooth's mesh in its own anatomical frame, its landmarks, and its rest pose.

A `Tooth` is model data in the MuJoCo sense: built once, never changed by a simulation. Where a
tooth is at a given step is state (a 4x4 pose, see `orthosim.geometry.pose`), kept apart from it.

Local frame, right-handed, origin at the cemento-enamel junction (CEJ) on the long axis:
  +y  long axis, from the root apex toward the incisal edge / occlusal surface
  +z  labial (buccal) direction
  +x  = y cross z; this is the mesial direction for teeth in quadrants 2 and 4 and the distal
      direction in quadrants 1 and 3 (left and right teeth are mirror images): `mesial` below
      gives the mesial unit vector either way.
All coordinates are millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from orthosim.model import fdi as fdi_mod
from orthosim.model.fdi import Arch, ToothType

if TYPE_CHECKING:  # a tooth from the cache holds a LazyMesh (orthosim.geometry.lazymesh): no trimesh import to load it
    import trimesh

CROWN = 0  # face part code: enamel crown, coronal of the CEJ
ROOT = 1  # face part code: root, apical of the CEJ


@dataclass(frozen=True, eq=False)
class Tooth:
    """One tooth's model: its closed mesh in its own frame and where it sits in the arch.

    The tooth frame (mm): origin at the cemento-enamel junction on the long axis, +y from the apex
    to the crown, +z labial/buccal (`mesial` gives the mesial direction). `mesh`: closed trimesh in
    that frame, mm; `face_part`: (n_faces,) int8, crown or root per face; `crown_center`, `apex`:
    (3,) mm in that frame; `rest_pose`: (4, 4) tooth frame -> arch frame, mm, the tooth before any
    movement; `landmarks`: name -> (3,) mm; `source`: where the mesh came from; `root_origin`:
    "scan" or "estimated" (a crown's root built by `orthosim.model.rootsynthesis`).
    """

    fdi: int
    mesh: trimesh.Trimesh  # closed, outward normals, local frame, mm (or a LazyMesh of its arrays)
    face_part: np.ndarray  # (n_faces,) int8, CROWN or ROOT per face
    crown_center: np.ndarray  # (3,) mm, local: geometric centre of the crown part
    apex: np.ndarray  # (3,) mm, local: root apex level on the long axis
    rest_pose: np.ndarray  # (4, 4) local -> arch frame, the tooth's initial placement
    landmarks: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (3,) mm, local
    source: str = "parametric"
    root_origin: str = "scan"  # "scan": the root is in the input mesh; "estimated": built for a crown (model.rootsynthesis)

    @property
    def arch(self) -> Arch:
        return fdi_mod.arch_of(self.fdi)

    @property
    def type(self) -> ToothType:
        return fdi_mod.tooth_type(self.fdi)

    @property
    def cej(self) -> np.ndarray:
        """(3,) mm, local: the CEJ centre on the long axis (the local origin)."""
        return np.zeros(3)

    @property
    def mesial(self) -> np.ndarray:
        """(3,) unit vector, local: toward the midline along the arch."""
        return np.array([1.0 if fdi_mod.quadrant(self.fdi) in (2, 4) else -1.0, 0.0, 0.0])

    @property
    def labial(self) -> np.ndarray:
        return np.array([0.0, 0.0, 1.0])

    @property
    def long_axis(self) -> np.ndarray:
        """(3,) unit vector, local: from the apex toward the crown."""
        return np.array([0.0, 1.0, 0.0])

    @property
    def root_kind(self) -> str:
        """What the root is: "scan" (from the input mesh), "estimated" (built for a crown-only tooth) or "parametric"."""
        return "parametric" if self.source == "parametric" else self.root_origin

    @property
    def root_length(self) -> float:
        """mm, CEJ to apex along the long axis."""
        return float(-self.apex[1])

    @cached_property
    def crown_vertices(self) -> np.ndarray:
        """(k, 3) mm, local: the vertices of the crown's faces (coronal of the CEJ)."""
        return self.mesh.vertices[np.unique(self.mesh.faces[self.face_part == CROWN])]

    def world_mesh(self, pose: np.ndarray | None = None) -> trimesh.Trimesh:
        """A copy of the mesh placed by `pose` (4x4 local -> arch frame; the rest pose by default)."""
        m = self.mesh.copy()
        m.apply_transform(self.rest_pose if pose is None else pose)
        return m

    def to_world(self, points_local: np.ndarray, pose: np.ndarray | None = None) -> np.ndarray:
        """(..., 3) local points -> (..., 3) arch-frame points under `pose` (rest pose by default)."""
        T = self.rest_pose if pose is None else pose
        p = np.asarray(points_local, dtype=float)
        return p @ T[:3, :3].T + T[:3, 3]


def part_of_faces(mesh: trimesh.Trimesh, cej_level: float = 0.0) -> np.ndarray:
    """Label each face crown or root by whether its centroid lies coronal of the CEJ plane (local y)."""
    return np.where(mesh.triangles_center[:, 1] >= cej_level, CROWN, ROOT).astype(np.int8)

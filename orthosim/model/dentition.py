"""A dentition: the set of tooth models of one patient (parametric or from meshes), in the arch frame.

Arch frame (the paper's): origin mid-arch, y up, the x-z plane the occlusal plane, +z anterior
(toward the lips), +x toward the patient's left. Upper crowns point down (-y), lower crowns up.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from orthosim.model.fdi import Arch, arch_order, side
from orthosim.model.tooth import Tooth


@dataclass(frozen=True, eq=False)
class Dentition:
    """A patient's teeth as the simulation sees them: `teeth` {FDI: `Tooth`} (extractions are a
    case's state, not the model's, so an extracted tooth is still here), a one-line `description`,
    `info` on how it was built (arch form, offsets, source files) and the scanned gum per arch
    (`gingiva`, drawn and exported, never collided). Arch frame, mm: +y up, +z anterior, +x to the
    patient's left; `rest_poses()` gives {FDI: (4, 4) tooth frame -> arch frame}.
    """

    teeth: dict[int, Tooth]  # FDI -> tooth model
    description: str = ""
    info: dict = field(default_factory=dict)  # how it was built (arch form, offsets, source files)
    # scanned gum per arch ("upper", "lower"): trimesh in the arch frame, mm; drawn and exported, never collided
    gingiva: dict = field(default_factory=dict)

    def __post_init__(self):
        for number, tooth in self.teeth.items():
            if number != tooth.fdi:
                raise ValueError(f"tooth keyed {number} has FDI {tooth.fdi}")

    @property
    def fdis(self) -> list[int]:
        """Present teeth, upper arch right to left, then lower arch right to left."""
        present = set(self.teeth)
        return arch_order(Arch.UPPER, present) + arch_order(Arch.LOWER, present)

    def arch(self, arch: Arch) -> list[int]:
        return arch_order(arch, set(self.teeth))

    def rest_poses(self) -> dict[int, np.ndarray]:
        return {n: self.teeth[n].rest_pose.copy() for n in self.fdis}

    def adjacent_pairs(self, absent: set[int] = frozenset()) -> list[tuple[int, int]]:
        """Neighbours along each arch, right to left, skipping teeth in `absent` (e.g. extracted)."""
        pairs = []
        for a in (Arch.UPPER, Arch.LOWER):
            order = [t for t in self.arch(a) if t not in absent]
            pairs += list(zip(order[:-1], order[1:]))
        return pairs

    def drop_mesh_caches(self) -> int:
        """Forget what trimesh has derived from the teeth's vertices and faces (triangles, edges,
        normals, adjacency ...), computed again when next asked for, the same; bytes of arrays freed.

        A model build or a scene leaves ~30 MB of these on a 28-tooth dentition that the run no
        longer reads. The meshes are made from vertices and faces only (`orthosim.exchange.meshload`, the
        dentition cache, the parametric teeth), so their caches hold nothing but derived values.
        Follow with `orthosim.runtime.background.release_freed_heap` to give the pages back.
        """
        freed = 0
        for tooth in self.teeth.values():
            if not getattr(tooth.mesh, "built", True):  # a LazyMesh whose trimesh was never made has derived nothing
                continue
            cache = tooth.mesh._cache  # trimesh keeps derived values here, keyed on the data's hash
            freed += sum(getattr(v, "nbytes", 0) for v in cache.cache.values())
            cache.clear()
        return freed

    def crown_centers(self, poses: dict[int, np.ndarray] | None = None) -> dict[int, np.ndarray]:
        """FDI -> (3,) arch-frame crown centre (mm) under `poses` (rest poses by default)."""
        out = {}
        for n in self.fdis:
            t = self.teeth[n]
            out[n] = t.to_world(t.crown_center, None if poses is None else poses[n])
        return out



def open_midline_space(dent: Dentition, space_mm: float) -> Dentition:
    """The dentition with a space (a diastema) of `space_mm` opened between the central incisors of both arches.

    Each side of the mouth moves away from the midline by half the space, rigidly and along the
    arch frame's x axis (patient's right to -x, left to +x), so each side keeps its own occlusion
    and contacts; only the teeth across the midline part. Real teeth get the parametric model's
    `diastema_mm` this way.
    """
    teeth = {}
    for n, t in dent.teeth.items():
        pose = t.rest_pose.copy()
        pose[0, 3] += side(n) * 0.5 * space_mm
        teeth[n] = replace(t, rest_pose=pose)
    info = {**dent.info, "diastema_mm": space_mm,
            "diastema_rule": "each side moved rigidly along x by half the space, away from the midline"}
    # the scanned gum cannot split at the midline with the teeth: it stays where it was scanned
    return Dentition(teeth, f"{dent.description}, {space_mm:g} mm midline space opened", info, dent.gingiva)

"""Test helpers for dental models: a two-tooth dentition of boxes with every stored field set."""

from __future__ import annotations

import numpy as np
import trimesh

from orthosim.model.dentition import Dentition
from orthosim.model.tooth import Tooth, part_of_faces


def small_dentition(size_mm: float = 8.0) -> Dentition:
    """Two box 'teeth' side by side: enough to check every stored field."""
    teeth = {}
    for n, x in ((11, -5.0), (21, 5.0)):
        mesh = trimesh.creation.box(extents=[size_mm, size_mm * 2, size_mm])
        pose = np.eye(4)
        pose[0, 3] = x
        teeth[n] = Tooth(n, mesh, part_of_faces(mesh), np.array([0.0, 4.0, 0.0]), np.array([0.0, -8.0, 0.0]), pose,
                         {"incisal_edge": np.array([0.0, 8.0, 0.5])}, source=f"box {n}")
    return Dentition(teeth, "two boxes", {"kind": "test", "arch": {"width_mm": 10.0}, "scan_to_arch": np.eye(4)})

"""What the renderer reads for one frame: where each tooth is, which are gone or moving, and the contacts.

`FrameState` is the whole interface between the simulation (and collision detection) and the
drawing code: the simulation writes one per step, the renderer only reads it. All positions are in
the arch frame of `orthosim.model.dentition`, in millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

_EMPTY3 = np.zeros((0, 3))
_EMPTY3.setflags(write=False)
_EMPTY = np.zeros((0,))
_EMPTY.setflags(write=False)


@dataclass(frozen=True, eq=False)
class FrameState:
    poses: Mapping[int, np.ndarray]  # FDI -> (4, 4) tooth local -> arch frame, mm
    extracted: frozenset[int] = frozenset()  # teeth not drawn at all
    moving: frozenset[int] = frozenset()  # teeth drawn with the moving tint
    contact_centers: np.ndarray = field(default_factory=lambda: _EMPTY3)  # (n, 3) mm, overlapping leaf spheres
    contact_radii: np.ndarray = field(default_factory=lambda: _EMPTY)  # (n,) mm
    contact_pairs: tuple[tuple[int, int], ...] = ()  # teeth in contact, for face colouring
    step: int = 0  # simulation step this frame shows (for file names and captions)

    def __post_init__(self):
        c = np.asarray(self.contact_centers, dtype=float).reshape(-1, 3)
        r = np.asarray(self.contact_radii, dtype=float).reshape(-1)
        if len(c) != len(r):
            raise ValueError(f"contact_centers has {len(c)} rows but contact_radii {len(r)}")
        object.__setattr__(self, "contact_centers", c)
        object.__setattr__(self, "contact_radii", r)
        object.__setattr__(self, "extracted", frozenset(self.extracted))
        object.__setattr__(self, "moving", frozenset(self.moving))

    @property
    def n_contacts(self) -> int:
        return len(self.contact_radii)

    @classmethod
    def from_step(cls, record, extracted=frozenset()) -> "FrameState":
        """The frame of one simulation step (`orthosim.movement.simulation.StepRecord` or anything
        with its fields: step, poses, moving, touching, contact_centers, contact_radii)."""
        return cls(poses=record.poses, extracted=frozenset(extracted), moving=frozenset(record.moving),
                   contact_centers=record.contact_centers, contact_radii=record.contact_radii,
                   contact_pairs=tuple(tuple(p) for p in record.touching), step=int(record.step))

    @classmethod
    def rest(cls, dentition, **kwargs) -> "FrameState":
        """Every tooth of `dentition` at its rest pose, nothing moving, no contacts."""
        return cls(poses=dentition.rest_poses(), **kwargs)

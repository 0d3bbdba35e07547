"""Which teeth touched during a run, from when, and with what: the contact table of a report.

From a run's steps (the touching pairs its detector reported at each step, and the poses), one
row per pair that ever touched: same arch or opposing arches, the first day and step of contact,
how many steps they stayed in contact, and which parts met at the first contact (crown or root of
each tooth), found on the exact meshes with FCL at that step's poses: the faces of the closest
points when the surfaces are apart, of the intersecting triangles when they cross.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Mapping, Sequence

import fcl
import numpy as np

from orthosim.geometry.meshquery import fcl_object, set_pose
from orthosim.model.dentition import Dentition
from orthosim.model.fdi import arch_of
from orthosim.model.tooth import CROWN


@dataclass(frozen=True)
class StepContacts:
    """What the table reads from one step of a run."""

    step: int
    time_days: float
    poses: Mapping[int, np.ndarray]  # FDI -> (4, 4), mm
    touching: Sequence[tuple[int, int]]


@dataclass(frozen=True)
class PairContact:
    pair: tuple[int, int]
    relation: str  # "same arch" | "opposing"
    first_day: float
    first_step: int
    steps_in_contact: int
    parts: tuple[str, str]  # ("crown" | "root", of pair[0] and of pair[1]) at the first contact

    def as_dict(self) -> dict:
        return {"pair": list(self.pair), "relation": self.relation, "first_day": self.first_day,
                "first_step": self.first_step, "steps_in_contact": self.steps_in_contact, "parts": list(self.parts)}


class ContactParts:
    """Which parts (crown or root) of two posed teeth meet; FCL objects built once per tooth (model)."""

    def __init__(self, dent: Dentition):
        self.dent = dent
        self._objects: dict[int, fcl.CollisionObject] = {}

    def _placed(self, n: int, pose) -> fcl.CollisionObject:
        if n not in self._objects:
            self._objects[n] = fcl_object(self.dent.teeth[n].mesh)
        obj = self._objects[n]
        set_pose(obj, pose)
        return obj

    def parts(self, a: int, b: int, poses: Mapping[int, np.ndarray]) -> tuple[str, str]:
        oa, ob = self._placed(a, poses[a]), self._placed(b, poses[b])
        res = fcl.CollisionResult()
        fcl.collide(oa, ob, fcl.CollisionRequest(num_max_contacts=64, enable_contact=True), res)
        if res.is_collision and res.contacts:
            fa = np.array([c.b1 for c in res.contacts])
            fb = np.array([c.b2 for c in res.contacts])
        else:
            dres = fcl.DistanceResult()
            fcl.distance(oa, ob, fcl.DistanceRequest(enable_nearest_points=True), dres)
            fa, fb = np.array([dres.b1]), np.array([dres.b2])
        return (self._name(a, fa), self._name(b, fb))

    def _name(self, n: int, faces: np.ndarray) -> str:
        part = self.dent.teeth[n].face_part
        faces = faces[(faces >= 0) & (faces < len(part))]
        # any root face among the meeting triangles makes it a root contact: that is what stops movement
        return "crown" if len(faces) == 0 or np.all(part[faces] == CROWN) else "root"


def contact_table(dent: Dentition, steps: Iterable[StepContacts], parts: ContactParts | None = None) -> list[PairContact]:
    """One row per pair that touched in `steps`, ordered by first contact then pair."""
    parts = parts or ContactParts(dent)
    first: dict[tuple[int, int], StepContacts] = {}
    count: dict[tuple[int, int], int] = {}
    for s in steps:
        for p in s.touching:
            pair = tuple(sorted(int(x) for x in p))
            count[pair] = count.get(pair, 0) + 1
            first.setdefault(pair, s)
    rows = []
    for pair, s in first.items():
        a, b = pair
        rows.append(PairContact(pair, "same arch" if arch_of(a) == arch_of(b) else "opposing", float(s.time_days),
                                int(s.step), count[pair], parts.parts(a, b, s.poses)))
    return sorted(rows, key=lambda r: (r.first_step, r.pair))

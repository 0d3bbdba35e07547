"""The collision detectors as objects: the paper's three, then the exact mesh reference, each with
what it can do.

The one list: the case format, the command line, the simulator and the collision package read it
from here (a module with no imports, so that parsing a case or building the CLI pulls in nothing).
Callers ask a detector's capabilities, never its name: whether it tests the motion over a step
(and so gives the time of first contact), what it bounds the teeth with, and whether the exact
meshes decide contacts it finds. `orthosim.collision.detect.detect_step` runs one.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Detector:
    """One collision detector and its capabilities.

    name: the name a case file and the command line use.
    bounds: what the teeth are bounded by: "circles" (the paper's bounding circles in the occlusal
        plane), "sphere_trees" (the leaf spheres of each tooth's tree) or "meshes" (the exact
        triangle meshes, through FCL).
    sweeps: tests each tooth's motion over the step, not only the poses it ends in; the result then
        holds the time of first contact (0-1 of the step) and the step is cut back to it.
    exact_touch: contacts are confirmed on the exact meshes (within the touch tolerance), and a
        pair touching at a step's start is judged by them (closer, or sinking deeper); otherwise by
        whether the crown centres approach.
    """

    name: str
    bounds: str
    sweeps: bool
    exact_touch: bool

    @property
    def time_of_contact(self) -> bool:
        return self.sweeps

    def __str__(self) -> str:
        return self.name


CIRCLES = Detector("circles", bounds="circles", sweeps=False, exact_touch=False)
DISCRETE = Detector("discrete", bounds="sphere_trees", sweeps=False, exact_touch=False)
CONTINUOUS = Detector("continuous", bounds="sphere_trees", sweeps=True, exact_touch=True)
EXACT = Detector("exact", bounds="meshes", sweeps=False, exact_touch=True)

BY_NAME = {d.name: d for d in (CIRCLES, DISCRETE, CONTINUOUS, EXACT)}
DETECTORS = tuple(BY_NAME)  # names, in the paper's order, then the exact reference
PAPER_DETECTORS = DETECTORS[:3]  # the paper's three (a report's default), without the exact reference


def detector_named(detector: "str | Detector") -> Detector | None:
    """The detector of that name (a Detector passes through); None for an unknown name."""
    if isinstance(detector, Detector):
        return detector
    return BY_NAME.get(detector)

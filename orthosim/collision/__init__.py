"""Collision detection between teeth: the paper's three detectors and the exact mesh reference.

    model = CollisionModel.from_dentition(dentition)          # built once: trees, circles, meshes
    result = detect_step(model, poses_start, poses_end, detector="continuous")

Modules: `contract` (request and result types), `model` (what never changes), `broadphase`
(which pairs to test), `circles` (detector 1), `discrete` (detector 2), `continuous` (detector 3),
`descent` (the shared vectorised tree descent), `time_of_contact` (Eq. 2 and step bounds),
`queries` (a run's exact answers on the meshes, through `orthosim.geometry.meshquery`), `detect`
(the entry points: `detect_step`, `contacts`), `bench` (timings), `validate` (accuracy studies),
`memory` (a process-wide allocator setting worth making at the CLI entry), `commands` (`orthosim
collide ...`). How a tooth moves within a step (the
motion every detector assumes) is `orthosim.geometry.motion`.
"""

from orthosim.geometry.motion import interpolate_pose
from orthosim.collision.broadphase import arch_neighbour_pairs, candidate_pairs, facing_pairs, sweep_and_prune
from orthosim.collision.contract import DETECTORS, CollisionError, CollisionRequest, Contacts, PairResult, StepResult
from orthosim.collision.detect import contacts, default_pairs, detect_step
from orthosim.collision.model import Body, CollisionModel
from orthosim.collision.queries import ExactQueries
from orthosim.collision.time_of_contact import first_time_of_contact

__all__ = [
    "Body", "CollisionError", "CollisionModel", "CollisionRequest", "Contacts", "DETECTORS", "ExactQueries", "PairResult",
    "StepResult", "arch_neighbour_pairs", "candidate_pairs", "contacts", "default_pairs", "detect_step", "facing_pairs",
    "first_time_of_contact", "interpolate_pose", "sweep_and_prune",
]

"""Collision detection between teeth: the paper's three detectors and the exact mesh reference.

    model = CollisionModel.from_dentition(dentition)          # built once: trees, circles, meshes
    result = detect_step(model, poses_start, poses_end, detector="continuous")

Modules: `contract` (request and result types), `detectors` (each detector as an object with its
capabilities), `model` (what never changes), `broadphase` (which pairs to test), `circles`
(detector 1), `discrete` (detector 2), `continuous` (detector 3), `descent` (the shared vectorised
tree descent) and `descent_compiled` (its numba form), `time_of_contact` (Eq. 2 and step bounds),
`queries` (a run's exact answers on the meshes, through `orthosim.geometry.meshquery`), `patchcache`
(the first step's patches kept between runs), `detect`
(the entry points: `detect_step`, `contacts`), `contact_area` (the exact contact faces inside
overlapping leaves) with `trianglepairs` (its compiled test of triangle pairs within a distance) and
`crossings_compiled` (its compiled inside test), `interpenetration` (what a model's teeth overlap at rest), `validate`
(accuracy studies). How a tooth moves within a step (the motion every detector assumes) is
`orthosim.geometry.motion`; the detector timings are `orthosim_bench.collision`.
"""

from orthosim.system.lazy import lazy_names

# The package's names, imported on first use (PEP 562): `orthosim.collision.detectors` is read by
# the case format and the command line, which must not pull FCL, numba and scipy in with it.
_FROM = {
    "interpolate_pose": "orthosim.geometry.motion",
    "arch_neighbour_pairs": "orthosim.collision.broadphase", "candidate_pairs": "orthosim.collision.broadphase",
    "facing_pairs": "orthosim.collision.broadphase", "sweep_and_prune": "orthosim.collision.broadphase",
    "DETECTORS": "orthosim.collision.detectors", "Detector": "orthosim.collision.detectors",
    "CollisionError": "orthosim.collision.contract", "CollisionRequest": "orthosim.collision.contract",
    "Contacts": "orthosim.collision.contract", "PairResult": "orthosim.collision.contract",
    "StepResult": "orthosim.collision.contract",
    "INTERSECTING": "orthosim.collision.contract", "WITHIN_TOLERANCE": "orthosim.collision.contract",
    "contacts": "orthosim.collision.detect", "default_pairs": "orthosim.collision.detect",
    "detect_step": "orthosim.collision.detect", "swept_sphere_pairs": "orthosim.collision.detect",
    "Body": "orthosim.collision.model", "CollisionModel": "orthosim.collision.model",
    "ExactQueries": "orthosim.collision.queries",
    "first_time_of_contact": "orthosim.collision.time_of_contact",
}
__all__ = sorted(_FROM)
__getattr__ = lazy_names(__name__, _FROM)


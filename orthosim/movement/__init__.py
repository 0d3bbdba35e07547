"""Tooth movement: loads, centres of resistance and rotation, wire models, force propagation through
contacts, collision response, and the step loop that ties them to the collision detectors.

Modules: `resistance` (centre of resistance rules), `biomechanics` (force system -> motion, rate
law), `propagation` (forces passed on between touching teeth), `impact` (momentum-conserving
impact response), `simulation` (model, state and the step's phases; `simulate`), `report`
(metrics.json and distances.csv).
"""

from orthosim.movement.ratelaw import RateLaw
from orthosim.movement.records import StepRecord

_FROM_SIMULATION = ("MovementModel", "MovementSettings", "StepState", "initial_state", "simulate", "step")
_FROM_BIOMECHANICS = ("Motion", "ToothMechanics", "build_mechanics", "movement_type", "tooth_motion")


def __getattr__(name: str):
    # the step loop imports the collision package (FCL, numba) and the mechanics the tooth meshes
    # (trimesh): loaded when first asked for, so that a process that only reads step records
    # (`orthosim.movement.records`) or a case file (`orthosim.movement.ratelaw`) does without
    if name in _FROM_SIMULATION:
        from orthosim.movement import simulation

        return getattr(simulation, name)
    if name in _FROM_BIOMECHANICS:
        from orthosim.movement import biomechanics

        return getattr(biomechanics, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["Motion", "MovementModel", "MovementSettings", "RateLaw", "StepRecord", "StepState", "ToothMechanics",
           "build_mechanics", "initial_state", "movement_type", "simulate", "step", "tooth_motion"]

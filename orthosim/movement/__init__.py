"""Tooth movement: loads, centres of resistance and rotation, wire models, force propagation through
contacts, collision response, and the step loop that ties them to the collision detectors.

Modules: `resistance` (centre of resistance rules), `biomechanics` (force system -> motion, rate
law), `propagation` (forces passed on between touching teeth), `impact` (momentum-conserving
impact response), `simulation` (model, state and the step's phases; `simulate`), `report`
(metrics.json and distances.csv).
"""

from orthosim.movement.biomechanics import Motion, RateLaw, ToothMechanics, build_mechanics, movement_type, tooth_motion
from orthosim.movement.records import StepRecord

_FROM_SIMULATION = ("MovementModel", "MovementSettings", "StepState", "initial_state", "simulate", "step")


def __getattr__(name: str):
    # the step loop imports the collision package (FCL, numba): loaded when first asked for, so that
    # a process that only reads step records (`orthosim.movement.records`) does without
    if name in _FROM_SIMULATION:
        from orthosim.movement import simulation

        return getattr(simulation, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["Motion", "MovementModel", "MovementSettings", "RateLaw", "StepRecord", "StepState", "ToothMechanics",
           "build_mechanics", "initial_state", "movement_type", "simulate", "step", "tooth_motion"]

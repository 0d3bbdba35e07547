"""Tooth movement: loads, centres of resistance and rotation, wire models, force propagation through
contacts, collision response, and the step loop that ties them to the collision detectors.

Modules: `resistance` (centre of resistance rules), `biomechanics` (force system -> motion, rate
law), `propagation` (forces passed on between touching teeth), `impact` (momentum-conserving
impact response), `simulation` (the step loop), `report` (metrics.json and distances.csv).
"""

from .biomechanics import Motion, RateLaw, ToothMechanics, build_mechanics, movement_type, tooth_motion
from .simulation import MovementModel, MovementSettings, StepRecord, simulate

__all__ = ["Motion", "MovementModel", "MovementSettings", "RateLaw", "StepRecord", "ToothMechanics",
           "build_mechanics", "movement_type", "simulate", "tooth_motion"]

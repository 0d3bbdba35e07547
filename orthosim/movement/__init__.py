"""Tooth movement: the step that applies each tooth's mechanics (`orthosim.mechanics`), passes forces
on between touching teeth, asks the collision detectors and answers their contacts.

Modules: `model` (`MovementModel`, what never changes, and its settings), `state` (`StepState`, what
a run carries from step to step), `simulation` (`initial_state`, `step`, `simulate`: the step made
of its phases), one module per phase: `forces` (loads at the step's start, forces passed on),
`motions` (each tooth's motion), `detection` (the cut-back loop of every detector), `response`
(contacts at the end and the impact response); and `directions` (the director vector and contact
normals), `propagation` (forces passed on between touching teeth), `impact` (momentum-conserving
impact response), `closure` (the bite closing after each step), `records` (what a step leaves:
`StepRecord`), `report` (metrics.json, steps.jsonl and distances.csv), `rootspread` (each moving
tooth's range of movement over the plausible roots where roots were estimated).
"""

from orthosim.mechanics.ratelaw import RateLaw
from orthosim.movement.records import StepRecord

_FROM = {"MovementModel": "model", "MovementSettings": "model", "StepState": "state", "initial_state": "simulation",
         "simulate": "simulation", "simulate_case": "simulation", "step": "simulation"}
_FROM_BIOMECHANICS = ("Motion", "ToothMechanics", "build_mechanics", "movement_type", "tooth_motion")


def __getattr__(name: str):
    # the step loop imports the collision package (FCL, numba) and the mechanics the tooth meshes
    # (trimesh): loaded when first asked for, so that a process that only reads step records
    # (`orthosim.movement.records`) or a case file (`orthosim.mechanics.ratelaw`) does without
    if name in _FROM:
        import importlib

        return getattr(importlib.import_module(f"orthosim.movement.{_FROM[name]}"), name)
    if name in _FROM_BIOMECHANICS:
        from orthosim.mechanics import biomechanics

        return getattr(biomechanics, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["Motion", "MovementModel", "MovementSettings", "RateLaw", "StepRecord", "StepState", "ToothMechanics",
           "build_mechanics", "initial_state", "movement_type", "simulate", "simulate_case", "step", "tooth_motion"]

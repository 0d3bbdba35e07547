"""The movement model: what never changes during a run (the case, the dentition, its collision
model, each tooth's mechanics, the settings) and the settings a case's [simulation] table gives.

`MovementModel.build(case)` makes it once; the step (`orthosim.movement.simulation`) reads it and
never changes it (MuJoCo's mjModel). Units: mm, cN, days.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Callable

from orthosim.collision import CollisionModel, candidate_pairs
from orthosim.exchange.case import Case
from orthosim.errors import CaseError
from orthosim.mechanics.biomechanics import ToothMechanics, build_mechanics
from orthosim.mechanics.ligament import DEFAULT as DEFAULT_LIGAMENT, LigamentProperties
from orthosim.mechanics.ratelaw import DAYS_PER_MONTH, PARAMETER_SETS, RateLaw
from orthosim.collision.interpenetration import default_occlusal_slide_mm
from orthosim.model import fdi as F
from orthosim.model.dentition import Dentition

if TYPE_CHECKING:
    from orthosim.movement.closure import ClosureModel


@dataclass(frozen=True)
class MovementSettings:
    """Parameters of the movement model (case file table [simulation]).

    force_share: fraction (0..1) of a push passed on to the tooth it hits.
    restitution: Newton's coefficient (0..1) of the reported impacts.
    resistance_rule / resistance_fraction: centre of resistance, see `resistance`; "ligament": the
        root's stiffness gives it and the motion (`orthosim.mechanics.ligament`, `ligamentmotion`).
    ligament: the ligament's properties; bone_level_mm: FDI -> crest depth below the CEJ (mm) of a
        tooth that lost bone (the case's [ligament] table).
    contact_tolerance_mm: continuous detector: teeth stop within this travel (mm) of touching.
    touch_tolerance_mm: exact and continuous detectors: meshes this close (mm) count as touching.
    rounds: continuous detector: detection rounds on cut motions per step.
    occlusal_slide_mm: continuous detector: teeth of the two arches in contact at a step's start may
        slide along each other; the move stops only if it leaves them interpenetrating deeper than
        at rest (step 0) by more than this (mm); by default the model's (see `from_case`). Arch
        neighbours get `contact_tolerance_mm`.
    """

    force_share: float = 0.5
    restitution: float = 0.5
    resistance_rule: str = "literature"
    resistance_fraction: float = 0.4
    rate: RateLaw = RateLaw()
    contact_tolerance_mm: float = 0.02
    touch_tolerance_mm: float = 0.05
    rounds: int = 4
    occlusal_slide_mm: float = 0.05
    ligament: LigamentProperties = DEFAULT_LIGAMENT
    bone_level_mm: tuple[tuple[int, float], ...] = ()

    @classmethod
    def from_case(cls, case: Case, dentition: Dentition | None = None) -> "MovementSettings":
        """The case's [simulation] settings; an occlusal_slide_mm the case leaves out is the model's
        (`interpenetration.default_occlusal_slide_mm` of `dentition`, the touch tolerance without one)."""
        sim = getattr(case, "simulation", None)
        slide = getattr(sim, "occlusal_slide_mm", None)
        if slide is None:
            slide = default_occlusal_slide_mm(dentition) if dentition is not None else cls.occlusal_slide_mm
        rate = rate_law(getattr(case, "biomechanics", None))
        lig = getattr(case, "ligament", None)
        ligament = {} if lig is None else {"ligament": lig.properties(), "bone_level_mm": tuple(sorted(lig.bone_level_mm.items()))}
        if sim is None:
            return cls(occlusal_slide_mm=slide, rate=rate, **ligament)
        return cls(force_share=sim.force_share, restitution=sim.restitution,
                   resistance_rule=sim.resistance_rule, resistance_fraction=sim.resistance_fraction,
                   rate=rate, occlusal_slide_mm=slide, **ligament)


def rate_law(biomechanics) -> RateLaw:
    """The rate law a case's [biomechanics] table names: its parameter set with the table's own
    numbers over it (`orthosim.exchange.case.Biomechanics`; None: the paper's set)."""
    if biomechanics is None:
        return PARAMETER_SETS["paper"]
    base = PARAMETER_SETS[biomechanics.parameters]
    changes = {k: v for k, v in biomechanics.overrides().items() if v is not None}
    if "max_rate_mm_per_month" in changes:
        changes["max_rate_mm_per_day"] = changes.pop("max_rate_mm_per_month") / DAYS_PER_MONTH
    return replace(base, **changes) if changes else base


@dataclass(frozen=True, eq=False)
class MovementModel:
    """What never changes during a run: the case, the dentition, its collision model (sphere trees),
    each tooth's mechanics, the settings, and what follows from them (present teeth, candidate pairs)."""

    case: Case
    dentition: Dentition
    collision: CollisionModel
    mechanics: dict[int, ToothMechanics]
    settings: MovementSettings
    extracted: frozenset[int] = field(default_factory=frozenset)
    present: tuple[int, ...] = ()
    pairs: tuple[tuple[int, int], ...] = ()  # broad phase: arch neighbours, then facing pairs
    facing: frozenset[tuple[int, int]] = field(default_factory=frozenset)
    total_mass_g: float = 0.0
    arch_orders: dict[F.Arch, list[int]] = field(default_factory=dict)  # present teeth, right to left
    closure: "ClosureModel | None" = None  # the bite's closure after each step (`closure`); None: the slide allowance
    # FDI -> its place along its arch among the dentition's teeth (extracted ones included), right to left
    arch_place: dict[int, int] = field(init=False, repr=False)

    def __post_init__(self):
        place = {}
        for arch in F.Arch:
            place.update((t, k) for k, t in enumerate(F.arch_order(arch, set(self.dentition.teeth))))
        object.__setattr__(self, "arch_place", place)

    @classmethod
    def build(cls, case: Case, dentition: Dentition | None = None, collision: CollisionModel | None = None,
              settings: MovementSettings | None = None, tree_builder: Callable | None = None) -> "MovementModel":
        dentition = dentition or case.build_dentition()
        settings = settings or MovementSettings.from_case(case, dentition)
        if collision is None:  # the project's cached sphere trees unless a builder is given
            collision = CollisionModel.from_dentition(dentition, tree_builder=tree_builder)
        extracted = frozenset(case.extractions)
        present = tuple(n for n in dentition.fdis if n not in extracted)
        pairs = candidate_pairs(dentition.fdis, extracted)
        neighbours = set(dentition.adjacent_pairs(set(extracted)))
        facing = frozenset(p for p in pairs if tuple(p) not in neighbours)
        mech = {n: _mechanics(case, dentition, n, settings) for n in present}
        orders = {arch: [t for t in F.arch_order(arch, set(dentition.teeth)) if t not in extracted] for arch in F.Arch}
        return cls(case, dentition, collision, mech, settings, extracted, present, tuple(map(tuple, pairs)), facing,
                   arch_orders=orders, closure=_closure_model(case, dentition, settings, facing, extracted, orders))


def _mechanics(case: Case, dentition: Dentition, fdi: int, settings: MovementSettings) -> ToothMechanics:
    """One present tooth's mechanics by the settings' rule; a bone level that leaves the tooth no
    embedded root is the case file's error."""
    try:
        return build_mechanics(dentition.teeth[fdi], settings.resistance_rule, settings.resistance_fraction, settings.rate,
                               settings.ligament, dict(settings.bone_level_mm).get(fdi))
    except CaseError as err:
        raise CaseError(getattr(case, "path", None), err.field, err.problem, err.fix) from None


def _closure_model(case: Case, dentition: Dentition, settings: MovementSettings, facing, extracted, orders):
    """The bite's closure model when the case closes the bite and both arches have teeth, else None."""
    from orthosim.movement.closure import ClosureModel, closure_settings

    chosen = closure_settings(case, settings.contact_tolerance_mm)
    if chosen.mode == "none" or not facing or min(len(orders[F.Arch.UPPER]), len(orders[F.Arch.LOWER])) < 3:
        return None
    return ClosureModel.build(chosen, dentition, sorted(facing), extracted)

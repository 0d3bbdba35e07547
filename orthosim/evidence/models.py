"""The models the evidence rows run on: the coarse parametric dentition, its collision model, the
real patient when present, each tooth's mechanics under the rate law being tested, and each tooth's
periodontal ligament (`orthosim.mechanics.ligament`: the stiffness of its embedded root, from which
the centre of resistance and the centre of rotation of any force system follow), built once."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from orthosim.mechanics.biomechanics import RateLaw, ToothMechanics, build_mechanics
from orthosim.mechanics.ligament import DEFAULT, LigamentProperties, RootSupport, root_support

EVIDENCE_RESOLUTION = "coarse"  # parametric mesh of the runs: rates do not depend on it, runs take seconds
STEP_DAYS = 30.0


class EvidenceModels:
    """The dentitions, collision model and mechanics the rows share (built once per run).

    law: the rate law under test. real: a callable giving the real patient's dentition, or None
    when the shared data is absent (rows on real teeth are then skipped). ligament: the ligament's
    material and crest depth (the published defaults: inputs, never tuned against a row).
    resistance_rule: how the simulated rows (rates, anchorage) move teeth: "ligament" (the root's
    compliance and its embedded surface), or a rule of `orthosim.mechanics.resistance`, as a case
    file on `law` gets by default (`orthosim.exchange.case.default_resistance_rule`)."""

    def __init__(self, law: RateLaw, real: Callable[[], Any] | None = None, ligament: LigamentProperties = DEFAULT,
                 resistance_rule: str = "ligament"):
        self.law = law
        self.ligament = ligament
        self.resistance_rule = resistance_rule  # how the simulated rows move teeth, as a case on `law` would
        self._real = real
        self._cache: dict[str, Any] = {}

    def dentition(self, model: str):
        if model not in self._cache:
            if model == "parametric":
                from orthosim.exchange.case import ModelSpec

                self._cache[model] = spec_case(ModelSpec(resolution=EVIDENCE_RESOLUTION)).build_dentition()
            else:
                self._cache[model] = self._real()
        return self._cache[model]

    def has(self, model: str) -> bool:
        return model == "parametric" or self._real is not None

    def mechanics(self, model: str, fdi: int) -> ToothMechanics:
        key = f"mech:{model}:{fdi}"
        if key not in self._cache:
            self._cache[key] = build_mechanics(self.dentition(model).teeth[fdi], self.resistance_rule, law=self.law,
                                               ligament=self.ligament)
        return self._cache[key]

    def support(self, model: str, fdi: int) -> RootSupport:
        """The tooth's ligament: its root's stiffness, centre of resistance and motions (tooth frame, mm)."""
        key = f"support:{model}:{fdi}"
        if key not in self._cache:
            self._cache[key] = root_support(self.dentition(model).teeth[fdi], self.ligament)
        return self._cache[key]

    def collision(self):
        if "collision" not in self._cache:
            from orthosim.collision import CollisionModel

            self._cache["collision"] = CollisionModel.from_dentition(self.dentition("parametric"))
        return self._cache["collision"]


def spec_case(model, loads=(), extractions=(), duration_days=STEP_DAYS, name="evidence"):
    from orthosim.exchange.case import Case, Wire

    return Case(Path(f"<evidence:{name}>"), name, "", model, tuple(extractions), tuple(loads), Wire("rectangular"),
                duration_days, STEP_DAYS, "continuous")



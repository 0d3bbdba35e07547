"""How each kind of evidence row is set up on orthosim's model and measured (`MEASURES`).

Rates and anchorage run the simulator itself (`orthosim.movement.simulate`, continuous detector,
monthly steps) on the coarse parametric model with the first premolar of the quadrant extracted.
Centres of resistance and the M/F rows are predicted by each tooth's periodontal ligament from its
root alone (`orthosim.evidence.centres`). Each function returns (value, one-line note, Curve).
Units: mm, cN, cN*mm, days, mm per month.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from orthosim.evidence import centres
from orthosim.evidence.models import STEP_DAYS, EvidenceModels, spec_case
from orthosim.evidence.table import Curve, EvidenceRow
from orthosim.model import fdi as F
from orthosim.mechanics.ratelaw import DAYS_PER_MONTH

RATE_DAYS = 90.0  # three monthly steps: the canine moves freely (its space is 7 mm)
MAX_CLOSING_STEPS = 24  # anchorage runs stop when the space closes, or after two years
POSTERIOR = (0.0, 0.0, -1.0)  # arch frame: +z points to the incisors


def _first_premolar(fdi: int) -> int:
    return 10 * F.quadrant(fdi) + 4


def _run(bench: EvidenceModels, loads, extractions, steps: int, stop_pair: tuple[int, int] | None = None):
    """The simulated records (step 0 first) of `loads` on the coarse parametric model, stopping at
    the step where `stop_pair` first touches."""
    from orthosim.exchange.case import ModelSpec
    from orthosim.movement import MovementModel, MovementSettings, simulate

    dent = bench.dentition("parametric")
    # the opposing arch is left out: an archwire keeps a retracted tooth on its path past the
    # opposing cusps, which the model has no wire to do (the teeth would lock on the cusps)
    arch = F.arch_of(loads[0].teeth[0])
    extractions = tuple(extractions) + tuple(t for t in dent.teeth if F.arch_of(t) != arch)
    case = spec_case(ModelSpec(resolution="coarse"), loads, extractions, steps * STEP_DAYS)
    settings = replace(MovementSettings.from_case(case, dent), rate=bench.law, resistance_rule=bench.resistance_rule,
                       ligament=bench.ligament)
    model = MovementModel.build(case, dent, bench.collision(), settings)
    records = []
    for record in simulate(model, "continuous", steps):
        records.append(record)
        if stop_pair and (stop_pair in record.touching or stop_pair[::-1] in record.touching):
            break
    return model, records


def _travel(model, records, fdi: int, direction: np.ndarray) -> np.ndarray:
    """(n,) mm the tooth's centre of resistance has moved along `direction` (arch frame) at each record."""
    c = model.mechanics[fdi].center_of_resistance
    start = records[0].poses[fdi][:3, :3] @ c + records[0].poses[fdi][:3, 3]
    return np.array([float((r.poses[fdi][:3, :3] @ c + r.poses[fdi][:3, 3] - start) @ direction) for r in records])


def _distal(model, records, fdi: int) -> np.ndarray:
    from orthosim.movement.directions import arch_direction

    return arch_direction(model, records[0].poses, fdi, "distal")


def simulated_rate(bench: EvidenceModels, tooth: int, force_cN: float) -> float:
    """mm per month the tooth's centre of resistance moves distally under `force_cN` (bodily, a
    rectangular wire), over RATE_DAYS with its first premolar extracted."""
    from orthosim.exchange.case import Load

    load = Load((tooth,), float(force_cN), "distal", "bracket", movement="translation")
    steps = int(RATE_DAYS / STEP_DAYS)
    model, records = _run(bench, (load,), (_first_premolar(tooth),), steps)
    travel = _travel(model, records, tooth, _distal(model, records, tooth))
    return float(travel[-1] / (records[-1].time_days / DAYS_PER_MONTH))


def _law_curve(bench: EvidenceModels, tooth: int) -> Curve:
    mech = bench.mechanics("parametric", tooth)
    force = np.linspace(0.0, 400.0, 161)
    rate = bench.law.rate(force, mech.resisting_area_mm2) * DAYS_PER_MONTH
    return Curve(force, rate, "force (cN)", f"tooth {tooth}: rate (mm/month)")


def measure_rate(bench: EvidenceModels, row: EvidenceRow):
    s = row.setup
    value = simulated_rate(bench, s["tooth"], s["force_cN"])
    note = f"tooth {s['tooth']} under {s['force_cN']:g} cN for {RATE_DAYS:g} days (simulated, first premolar out)"
    return value, note, _law_curve(bench, s["tooth"])


def measure_rate_ratio(bench: EvidenceModels, row: EvidenceRow):
    s = row.setup
    a = simulated_rate(bench, s["tooth"], s["force_cN"])
    b = simulated_rate(bench, s["tooth"], s["reference_force_cN"])
    note = (f"tooth {s['tooth']}: {a:.3f} mm/month at {s['force_cN']:g} cN over {b:.3f} at "
            f"{s['reference_force_cN']:g} cN (simulated)")
    return (a / b if b > 0 else float("nan")), note, _law_curve(bench, s["tooth"])


# ---------------------------------------------------------------------------------------------
# anchorage: the reaction of a retraction on the anchor teeth


def _shared(bench: EvidenceModels, teeth, force_cN: float) -> dict[int, float]:
    """force_cN shared among `teeth` by root surface (a segment tied by the wire moves as one)."""
    area = {t: bench.mechanics("parametric", t).resisting_area_mm2 for t in teeth}
    total = sum(area.values())
    return {t: force_cN * a / total for t, a in area.items()}


def anchorage_run(bench: EvidenceModels, retracted, anchors, force_cN: float, reinforced: bool):
    """(molar mesial travel (n,) mm, lead tooth distal travel (n,) mm, days (n,)) until the lead tooth
    (the canine, the last of `retracted`) meets the first anchor tooth, the first premolar out."""
    from orthosim.exchange.case import Load

    lead = retracted[-1]
    # the canine slides along the arch into the space; the incisors of an en masse segment go straight back
    loads = [Load((t,), f, "distal" if t == lead else POSTERIOR, "bracket", movement="translation")
             for t, f in _shared(bench, retracted, force_cN).items()]
    if not reinforced:
        loads += [Load((t,), f, "mesial", "bracket", movement="translation")
                  for t, f in _shared(bench, anchors, force_cN).items()]
    model, records = _run(bench, tuple(loads), (_first_premolar(lead),), MAX_CLOSING_STEPS, (lead, anchors[0]))
    molar = 10 * F.quadrant(lead) + 6
    from orthosim.movement.directions import arch_direction

    mesial = arch_direction(model, records[0].poses, molar, "mesial")
    days = np.array([r.time_days for r in records])
    return _travel(model, records, molar, mesial), _travel(model, records, lead, _distal(model, records, lead)), days


def _anchorage_curve(days, molar, lead, label_lead: str) -> Curve:
    return Curve(days, molar, "days", "mm", series={"first molar, mesial": molar, f"{label_lead}, distal": lead})


def measure_anchorage_canine(bench: EvidenceModels, row: EvidenceRow):
    s = row.setup
    molar, canine, days = anchorage_run(bench, (s["tooth"],), tuple(s["anchor_teeth"]), s["force_cN"],
                                        bool(s["reinforced"]))
    how = "mini-implant (no reaction on the molars)" if s["reinforced"] else "molar anchorage (reaction shared by root surface)"
    note = f"{how}: the canine moved {canine[-1]:.2f} mm in {days[-1]:g} days (simulated until it meets the premolar)"
    return float(molar[-1]), note, _anchorage_curve(days, molar, canine, "canine")


def measure_anchorage_en_masse(bench: EvidenceModels, row: EvidenceRow):
    s = row.setup
    front, back = tuple(s["teeth"]), tuple(s["anchor_teeth"])
    conv, lead_c, days = anchorage_run(bench, front, back, s["force_cN"], False)
    reinf, _, days_r = anchorage_run(bench, front, back, s["force_cN"], True)
    note = (f"conventional: the molar came {conv[-1]:.2f} mm forward while the canine went {lead_c[-1]:.2f} mm back "
            f"({days[-1]:g} days); mini-implant: {reinf[-1]:.2f} mm")
    difference = np.interp(days, days_r, reinf) - conv
    curve = Curve(days, difference, "days", "mm", series={
        "first molar, mesial (conventional)": conv, "canine, distal (conventional)": lead_c,
        "molar: mini-implant minus conventional": difference})
    return float(reinf[-1] - conv[-1]), note, curve


MEASURES = {
    "rate": measure_rate,
    "rate_ratio": measure_rate_ratio,
    "cr_share": centres.measure_cr_share,
    "cr_below_bracket": centres.measure_cr_below_bracket,
    "cr_lingual_of_bracket": centres.measure_cr_lingual_of_bracket,
    "mf_center": centres.measure_mf_center,
    "anchorage_canine": measure_anchorage_canine,
    "anchorage_en_masse": measure_anchorage_en_masse,
}

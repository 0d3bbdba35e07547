"""The fit behind the "clinical" rate law: four constants against the evidence table's rate and anchorage rows.

The rate law (`orthosim.mechanics.biomechanics.RateLaw`) has a threshold F_0, a saturation force
F_sat, a top rate r_max and a mandibular bone factor k (the reference root surface stays 200 mm^2:
it only scales the forces). Five rows pin them: the upper and lower canine rates under 98 cN
(Monini 2019), the plateau from 50 to 250 cN (Theodorou 2019), the molar's anchorage loss while
the canine closes a first premolar space (the 2018 Contemporary Clinical Dentistry study) and the
en masse anchorage difference (Becker 2018). Each row's quantity is written in closed form from
the rate law and the parametric model's root surfaces: a tooth moved bodily moves at
rate(F, A); a segment whose force is shared by root surface moves at rate(F * 200 / sum A); two
segments pulled together close a space S in proportion to their rates, so the anchor's share of
S is r_anchor / (r_anchor + r_retracted). S is the first premolar's mesiodistal width. The
residuals, in units of each row's half interval, are minimised by `scipy.optimize.least_squares`;
`orthosim evidence` then checks the fitted law by simulation, where contacts may change the
closed form's numbers a little.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthosim.evidence.models import EvidenceModels
from orthosim.evidence.table import EvidenceRow, load_evidence
from orthosim.mechanics.ratelaw import DAYS_PER_MONTH, PARAMETER_SETS, RateLaw

FITTED_KINDS = ("rate", "rate_ratio", "anchorage_canine", "anchorage_en_masse")
# starting points (F_0 cN, F_sat cN, r_max mm/month, k): the law is flat past saturation, so a
# start there sees no gradient; the best of a few starts is kept
STARTS = ((20.0, 60.0, 0.7, 2.5), (10.0, 100.0, 1.0, 1.5), (5.0, 40.0, 0.7, 3.0))
BOUNDS = ((0.0, 5.0, 0.1, 0.5), (60.0, 300.0, 3.0, 4.0))


@dataclass(frozen=True)
class Fit:
    """The fitted law, and per fitted row: (id, closed-form value, published mean, residual in half intervals)."""

    law: RateLaw
    residuals: tuple[tuple[str, float, float, float], ...]
    cost: float


def _law(x) -> RateLaw:
    f0, fsat, rmax, k = (float(v) for v in x)
    return RateLaw(threshold_cN=f0, saturation_cN=fsat, max_rate_mm_per_day=rmax / DAYS_PER_MONTH,
                   reference_root_area_mm2=200.0, mandibular_bone_factor=k)


def _area(bench: EvidenceModels, law: RateLaw, fdi: int) -> float:
    """mm^2 the rate law scales the tooth's force by, as the step does (`ToothMechanics.resisting_area_mm2`)
    but with `law`'s bone factor: the root surface (embedded, over the reference root's embedded
    share, when teeth move by their ligament) times the factor for a lower tooth."""
    mech = bench.mechanics("parametric", fdi)
    return mech.root_area_mm2 / mech.reference_share * (law.mandibular_bone_factor if fdi // 10 in (3, 4) else 1.0)


def closed_form(bench: EvidenceModels, law: RateLaw, row: EvidenceRow) -> float:
    """The row's quantity from the rate law alone (see the module text)."""
    s = row.setup
    per_month = lambda f, a: float(law.rate(float(f), float(a))) * DAYS_PER_MONTH  # noqa: E731
    if row.kind == "rate":
        return per_month(s["force_cN"], _area(bench, law, s["tooth"]))
    if row.kind == "rate_ratio":
        a = _area(bench, law, s["tooth"])
        top = per_month(s["reference_force_cN"], a)
        return per_month(s["force_cN"], a) / top if top > 0 else 0.0
    lead = s["tooth"] if row.kind == "anchorage_canine" else s["teeth"][-1]
    space = float(bench.dentition("parametric").teeth[10 * (lead // 10) + 4].mesh.extents[0])
    if row.kind == "anchorage_canine" and s["reinforced"]:
        return 0.0
    front = [s["tooth"]] if row.kind == "anchorage_canine" else list(s["teeth"])
    r_front = per_month(s["force_cN"] * 200.0 / sum(_area(bench, law, t) for t in front), 200.0)
    r_back = per_month(s["force_cN"] * 200.0 / sum(_area(bench, law, t) for t in s["anchor_teeth"]), 200.0)
    loss = space * r_back / max(r_front + r_back, 1e-12)
    return -loss if row.kind == "anchorage_en_masse" else loss


def fitted_rows(rows: tuple[EvidenceRow, ...]) -> tuple[EvidenceRow, ...]:
    """The rows the fit uses: those the table marks `fitted = true` (its calibration rows); every
    other row validates the fitted law without having been fitted to it."""
    out = tuple(r for r in rows if r.fitted)
    for r in out:
        if r.kind not in FITTED_KINDS or r.model != "parametric":
            raise ValueError(f"evidence row {r.id} is marked fitted but the fit has no closed form for a {r.kind} row on the {r.model} model")
    return out


def fit_clinical(bench: EvidenceModels | None = None, rows: tuple[EvidenceRow, ...] | None = None) -> Fit:
    """Least squares of the four constants against `fitted_rows` (residual: (value - mean) / half interval)."""
    from scipy.optimize import least_squares

    bench = bench or EvidenceModels(PARAMETER_SETS["clinical"])
    rows = fitted_rows(rows or load_evidence())

    def residuals(x):
        law = _law(x)
        return np.array([(closed_form(bench, law, r) - r.mean) / max(0.5 * (r.high - r.low), 1e-6) for r in rows])

    best = min((least_squares(residuals, x0, bounds=BOUNDS, x_scale=(10.0, 10.0, 0.1, 0.5)) for x0 in STARTS),
               key=lambda result: result.cost)
    law = _law(best.x)
    table = tuple((r.id, closed_form(bench, law, r), r.mean, float(e)) for r, e in zip(rows, residuals(best.x)))
    return Fit(law, table, float(best.cost))

"""Running the evidence table: each row through its kind (`kinds.MEASURES`), with its verdict."""

from __future__ import annotations

import math
from dataclasses import dataclass

from orthosim.evidence.models import EvidenceModels
from orthosim.evidence.kinds import MEASURES
from orthosim.evidence.table import EvidenceRow, RowResult, load_evidence
from orthosim.mechanics.ratelaw import PARAMETER_SETS, RateLaw


def run_rows(bench: EvidenceModels, rows: tuple[EvidenceRow, ...]) -> list[RowResult]:
    """Every row run on `bench`, in table order (rows on a model the bench lacks are skipped)."""
    out = []
    for row in rows:
        if not bench.has(row.model):
            out.append(RowResult(row, math.nan, "skipped", "the real patient's data (../shared/data) is absent"))
            continue
        value, note, curve = MEASURES[row.kind](bench, row)
        inside = row.low - 1e-9 <= value <= row.high + 1e-9
        out.append(RowResult(row, float(value), "inside" if inside else "outside", note, curve))
    return out


def evidence_models(law: RateLaw | None = None, with_real: bool = True) -> EvidenceModels:
    """A bench for `law` (default: the "clinical" set), with the real patient when `with_real` and
    its data is present (../shared/data, `orthosim.exchange.shareddata`); its teeth move as a
    parametric case on that law would by default (the paper's law: the literature rule; any other:
    the ligament)."""
    from orthosim.exchange.case import default_resistance_rule
    from orthosim.exchange.shareddata import open_full_jaw_dir

    def patient26():
        from orthosim.exchange.case import CASES_DIR, load_case

        return load_case(CASES_DIR / "open_full_jaw_patient26.toml").build_dentition()

    real = patient26 if with_real and open_full_jaw_dir("maxilla").is_dir() else None
    law = law or PARAMETER_SETS["clinical"]
    name = "paper" if law == PARAMETER_SETS["paper"] else "clinical"
    return EvidenceModels(law, real, resistance_rule=default_resistance_rule("parametric", name))


def run_evidence(law: RateLaw | None = None, with_real: bool = True,
                 rows: tuple[EvidenceRow, ...] | None = None) -> list[RowResult]:
    """The evidence table (or `rows`) run under `law` (default: the "clinical" set)."""
    return run_rows(evidence_models(law, with_real), rows or load_evidence())


@dataclass(frozen=True)
class Counts:
    """How many rows of a role ('validation' or 'calibration') ran, and where they fell."""

    role: str
    rows: int
    inside: int
    outside: int
    skipped: int

    def line(self) -> str:
        """'9 of 11 validation rows inside (1 skipped)'."""
        ran = self.rows - self.skipped
        skipped = f" ({self.skipped} skipped)" if self.skipped else ""
        return f"{self.inside} of {ran} {self.role} rows inside{skipped}"


def counts(results: list[RowResult], role: str) -> Counts:
    """The counts of the rows of `role`: validation (not fitted, the headline) or calibration (fitted)."""
    mine = [r for r in results if r.row.role == role]
    return Counts(role, len(mine), sum(r.status == "inside" for r in mine), sum(r.status == "outside" for r in mine),
                  sum(r.status == "skipped" for r in mine))

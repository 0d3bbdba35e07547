"""The clinical evidence table set up again on orthosim's model: published value, simulated value, verdict.

`orthosim/movement/evidence.toml` holds what trials, reviews and bench studies measured (source,
quantity, force system, published mean and interval). `run_evidence` sets each row up on the
parametric model (coarse mesh, a few monthly steps: seconds) or on the real Open-Full-Jaw patient
when the row is about real teeth (skipped when ../shared is absent), measures the same quantity
with the movement model's own functions (`simulate` for rates and anchorage, `free_motion` for
centres of resistance and rotation), and says whether it falls inside the published interval.
Each kind of row is one function of `kinds` (`kinds.MEASURES`); `calibration` fits the
"clinical" rate law to the rate and anchorage rows. Units: mm, cN, cN*mm, days, mm per month
(365.25/12 days).
"""

from orthosim.analysis.evidence.run import run_evidence, run_rows
from orthosim.analysis.evidence.table import EVIDENCE_TABLE, EvidenceRow, RowResult, load_evidence

__all__ = ["EVIDENCE_TABLE", "EvidenceRow", "RowResult", "load_evidence", "run_evidence", "run_rows"]

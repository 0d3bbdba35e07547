"""The clinical evidence table set up again on orthosim's model: published value, simulated value, verdict.

`orthosim/evidence/evidence.toml` holds what trials, reviews and bench studies measured (source,
quantity, force system, published mean and interval). `run_evidence` sets each row up on the
parametric model (coarse mesh, a few monthly steps: seconds) or on the real Open-Full-Jaw patient
when the row is about real teeth (skipped when ../shared is absent), measures the same quantity
with the movement model's own functions (`simulate` for rates and anchorage, `free_motion` for
centres of resistance and rotation), and says whether it falls inside the published interval.
Modules: `table` (the table read and checked; what a run of a row gives), `kinds` (each kind of
row as one function, `kinds.MEASURES`), `models` (the dentitions and mechanics the rows run on,
built once), `run` (`run_evidence`, `run_rows`), `matching` (a row's teeth matched to the model's),
`calibration` (the "clinical" rate law fitted to the rate and anchorage rows). Units: mm, cN, cN*mm, days, mm per month
(365.25/12 days).
"""

from orthosim.evidence.run import run_evidence, run_rows
from orthosim.evidence.table import EVIDENCE_TABLE, EvidenceRow, RowResult, load_evidence

__all__ = ["EVIDENCE_TABLE", "EvidenceRow", "RowResult", "load_evidence", "run_evidence", "run_rows"]

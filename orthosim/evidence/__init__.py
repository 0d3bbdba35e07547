"""The clinical evidence table set up again on orthosim's model: published value, simulated value, verdict.

`orthosim/evidence/evidence.toml` holds what trials, reviews and bench studies measured (source,
quantity, force system, published mean and interval, and whether the value was used to fit a
constant: calibration rows are inside by construction, validation rows test the model). `run_evidence`
sets each row up on the parametric model (coarse mesh, a few monthly steps: seconds) or on the real
Open-Full-Jaw patient when the row is about real teeth (skipped when ../shared is absent), measures
the same quantity with the model's own functions (`simulate` for rates and anchorage; each tooth's
periodontal ligament, `orthosim.mechanics.ligament`, for centres of resistance and rotation), and
says whether it falls inside the published interval. Modules: `table` (the table read and checked;
what a run of a row gives), `kinds` (each kind of row as one function, `kinds.MEASURES`), `centres`
(the centre-of-resistance and M/F rows, predicted from the ligament), `models` (the dentitions,
mechanics and ligaments the rows run on, built once), `run` (`run_evidence`, `run_rows`, the
counts), `matching` (a row's teeth matched to the model's), `calibration` (the "clinical" rate law
fitted to the calibration rows). Units: mm, cN, cN*mm, days, mm per month (365.25/12 days).
"""

from orthosim.evidence.run import Counts, counts, run_evidence, run_rows
from orthosim.evidence.table import EVIDENCE_TABLE, EvidenceRow, RowResult, load_evidence

__all__ = ["EVIDENCE_TABLE", "Counts", "EvidenceRow", "RowResult", "counts", "load_evidence", "run_evidence", "run_rows"]

"""The batch table: one row per run in `DIR/batch.json` and `DIR/batch.csv`, rewritten as runs end.

A row names the run (its id, source case, detector and swept values), how it went (status `ok`,
`failed` or `pending` when the batch stopped before it, the error line, whether the run was
finished by an earlier invocation and reused) and what it measured: steps, collisions, the largest
interpenetration (mm), the total tooth-to-tooth distance at the start and the end (mm), frames
drawn, frames per second and wall seconds. Both files are written atomically, so an interrupted
batch leaves a whole table of the runs so far.
"""

from __future__ import annotations

import csv
import io
import json
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Sequence

from orthosim import __version__
from orthosim.storage.atomic import write_json, write_text
from orthosim.runtime.runfolder import RUN_FILE, RunFolderError, read_finished_run
from orthosim.batch.plan import Variant

OK, FAILED, PENDING = "ok", "failed", "pending"


class DamagedRunWarning(UserWarning):
    """A run folder a batch finished earlier is damaged or foreign; the batch runs it again."""
MEASURES = ("steps", "collisions", "max_penetration_mm", "total_distance_initial_mm", "total_distance_final_mm",
            "frames", "fps", "wall_s")


@dataclass
class RunRow:
    run_id: str
    case: str  # the source case file
    case_name: str
    detector: str
    settings: dict[str, str]  # --set KEY -> value as written
    status: str = PENDING
    error: str | None = None
    reused: bool = False  # finished by an earlier invocation of the same batch, not run again
    attempts: int = 0
    steps: int | None = None
    collisions: int | None = None
    max_penetration_mm: float | None = None
    total_distance_initial_mm: float | None = None
    total_distance_final_mm: float | None = None
    frames: int | None = None
    fps: float | None = None  # frames drawn per second of the run's own drawing loop
    wall_s: float | None = None
    extra: dict = field(default_factory=dict)

    @classmethod
    def of(cls, variant: Variant) -> "RunRow":
        return cls(variant.run_id, str(variant.source), variant.case_name, variant.detector, dict(variant.settings))

    def record(self, summary: dict) -> None:
        """Fill the measures from a run's summary (metrics.json and run.json fields, merged)."""
        distance = summary.get("total_distance_mm") or {}
        self.steps = summary.get("steps")
        self.collisions = summary.get("collisions")
        self.max_penetration_mm = summary.get("max_penetration_mm")
        self.total_distance_initial_mm = distance.get("initial")
        self.total_distance_final_mm = distance.get("final")
        self.frames = summary.get("frames")
        self.fps = summary.get("fps")
        self.wall_s = summary.get("wall_s")


def run_summary(summary: dict) -> dict:
    """The part of a run's metrics the batch keeps (what crosses a process or network boundary)."""
    keep = ("steps", "collisions", "max_penetration_mm", "total_distance_mm", "frames", "fps", "wall_s", "case",
            "detector")
    # run.json keeps the drawing's figures under "render" and the run's wall time under "timings_s"
    drawn = summary.get("render") or {}
    found = {"frames": drawn.get("frames"), "fps": drawn.get("fps"),
             "wall_s": (summary.get("timings_s") or {}).get("total"), **summary}
    return {k: found[k] for k in keep if k in found}


def finished_summary(run_dir: Path, variant: Variant) -> dict | None:
    """The summary of a run folder finished earlier for exactly this variant, else None (to be run).

    Finished means `read_finished_run` accepts it (run.json and the checksums of the run's files) and
    its run.json names this variant's case text (SHA-256) and detector: a folder left by a different
    sweep under the same id is run again; one that finished but is damaged since, with a warning.
    """
    try:
        record = read_finished_run(run_dir)
    except RunFolderError as err:
        if (run_dir / RUN_FILE).is_file():  # finished once, damaged since: say so (an unfinished run is simply run)
            warnings.warn(f"batch: {err}; running {run_dir.name} again", DamagedRunWarning, stacklevel=2)
        return None
    if record.get("case_sha256") != variant.case_sha256 or record.get("detector") != variant.detector:
        return None
    try:
        metrics = json.loads((run_dir / "metrics.json").read_text())
    except (OSError, ValueError):
        return None
    return run_summary({**metrics, **{k: v for k, v in record.items() if k != RUN_FILE}})


def write_table(out_dir: Path, rows: Sequence[RunRow], sweep_keys: Sequence[str], extra: dict | None = None) -> None:
    """DIR/batch.json (rows and totals) and DIR/batch.csv (one line per run, a column per --set KEY)."""
    counts = {s: sum(r.status == s for r in rows) for s in (OK, FAILED, PENDING)}
    write_json(out_dir / "batch.json", {
        "orthosim_version": __version__,
        "runs_total": len(rows),
        **{f"runs_{k}": v for k, v in counts.items()},
        "sweeps": list(sweep_keys),
        **(extra or {}),
        "runs": [{k: v for k, v in asdict(r).items() if k != "extra"} | r.extra for r in rows],
    })
    columns = ["run_id", "case", "detector", *sweep_keys, "status", "error", "reused", "attempts", *MEASURES]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for r in rows:
        values = asdict(r)
        writer.writerow([r.settings.get(c, "") if c in sweep_keys else _cell(values.get(c)) for c in columns])
    write_text(out_dir / "batch.csv", buf.getvalue())


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)

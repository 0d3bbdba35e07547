"""What a report reads from a finished run folder: the one place that knows the run's file layout.

A folder counts only if `orthosim.runtime.runfolder.read_finished_run` accepts it (run.json written last,
this orthosim version); then metrics.json gives the figures. Everything the report needs from a
run is copied here into a `RunData`, so a change in what `orthosim run` writes is met here alone.
The case file named in run.json must still be the one the run used (same SHA-256): the report
rebuilds the teeth from it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orthosim.movement.report import STEPS_FILE, read_steps
from orthosim.runtime.runfolder import RunFolderError, read_finished_run
from orthosim.storage.checksums import file_sha256


@dataclass(frozen=True, eq=False)
class RunData:
    run_dir: Path
    case_file: Path
    case_sha256: str
    detector: str
    case_name: str
    step_days: float
    duration_days: float
    extracted: tuple[int, ...]
    steps: tuple[dict, ...]  # per step: step, time_days, poses {FDI: (4, 4)}, touching [(a, b)], total_distance_mm
    metrics: dict  # the figures the report shows, as metrics.json has them (see FIGURES)
    throughput: dict  # {"fps": end-to-end frames/s or None, "render_fps", "frames", "wall_s", "steps_per_s"}

    @property
    def initial_poses(self) -> dict[int, np.ndarray]:
        return self.steps[0]["poses"]

    @property
    def final_poses(self) -> dict[int, np.ndarray]:
        return self.steps[-1]["poses"]


FIGURES = ("steps", "total_distance_mm", "max_penetration_mm", "initial_penetration_mm", "collisions", "distances",
           "teeth")



def _poses(raw: dict) -> dict[int, np.ndarray]:
    return {int(k): np.asarray(v, float) for k, v in raw.items()}


def read_run(run_dir: str | Path) -> RunData:
    """The RunData of a finished run, or a one-line RunFolderError naming the fix."""
    run_dir = Path(run_dir)
    record = read_finished_run(run_dir)
    path = run_dir / "metrics.json"
    rerun = f"run it again: orthosim run CASE --out {run_dir}"
    try:
        m = json.loads(path.read_text())
        steps = tuple({"step": int(s["step"]), "time_days": float(s["time_days"]), "poses": _poses(s["poses"]),
                       "touching": [tuple(int(x) for x in p) for p in s["touching"]],
                       "total_distance_mm": float(s["total_distance_mm"])} for s in read_steps(run_dir))
        figures = {k: m[k] for k in FIGURES}
        figures["bite"] = m.get("bite")  # runs that close the bite (orthosim.movement.closure) only
        case_name, step_days, duration = str(m["case"]), float(m["step_days"]), float(m["duration_days"])
        extracted = tuple(int(n) for n in m["extracted"])
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise RunFolderError(path, None, f"is unreadable ({err.__class__.__name__})", rerun) from None
    except (KeyError, TypeError, ValueError) as err:
        raise RunFolderError(path, str(err).strip("'\""), "is missing or malformed", rerun) from None
    if not steps:
        raise RunFolderError(run_dir / STEPS_FILE, None, "holds no step", rerun)
    case_file = Path(record["case_file"])
    if not case_file.is_file():
        raise RunFolderError(run_dir / "run.json", "case_file", f"names {case_file}, which does not exist here",
                             "run the report from the folder the run was started in, or run the case again")
    if file_sha256(case_file) != record.get("case_sha256"):
        raise RunFolderError(run_dir / "run.json", "case_sha256", f"{case_file} has changed since the run",
                             f"run it again: orthosim run {case_file} --out {run_dir}")
    # machine-dependent figures live in run.json: the drawing's under "render", the run's wall time
    # under "timings_s" (older runs kept some in metrics.json)
    drawn = record.get("render") or {}

    def figure(key):
        return record.get(key, drawn.get(key, m.get(key)))

    wall = record.get("wall_s", (record.get("timings_s") or {}).get("total", m.get("wall_s")))
    throughput = {"fps": figure("fps"), "render_fps": figure("render_fps"), "frames": figure("frames"),
                  "wall_s": wall, "steps_per_s": (len(steps) - 1) / wall if wall else None}
    return RunData(run_dir, case_file, str(record["case_sha256"]), str(record["detector"]), case_name, step_days,
                   duration, extracted, steps, figures, throughput)

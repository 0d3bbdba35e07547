"""What a run writes: metrics.json (the issue's output contract), steps.jsonl (per-step detail) and distances.csv.

    report = RunReport(model, detector, steps_file=out_dir / STEPS_FILE,
                       distances_file=out_dir / DISTANCES_PER_STEP_FILE)
    for record in simulate(model, detector):
        report.add(record)
    report.write(out_dir)

metrics.json: `case`, `detector`, `steps`, `teeth` {FDI: `moved_mm` (crown centre displacement),
`rotated_deg`, `final_pose` (4x4, mm), `extracted`; for loaded teeth also their centre of
resistance, the loads' moment-to-force ratio (mm) and the movement it makes}, `total_distance_mm`
{`initial`, `final`}, `max_penetration_mm` (exact meshes, over the run: the deepest
interpenetration the movement added to any pair; `initial_penetration_mm` is the model's own, and
`initial_interpenetration` lists the pairs that start interpenetrating beyond the touch tolerance,
deepest first, as {`pair`, `mm`}), `collisions` (count), `distances` (per adjacent pair: `pair`,
`initial_mm`, `final_mm`), and `per_step_file`: the name of the per-step detail beside it. A run that
closes the bite after every step (`orthosim.movement.closure`) adds `bite` (the change in vertical
dimension over the treatment, the opening at the molars, the condylar axis) and each lower tooth's
`moved_in_mandible_mm`, and each line of steps.jsonl its step's `bite` (hinge angle, opening at the
incisors and the molars in mm, the facing pairs in contact at closure and their count). A run on
crowns with estimated roots adds each moving tooth's `moved_mm_range` [low, high] (mm, over the
plausible roots: `orthosim.movement.rootspread`) and `root_spread` (the ratio's ends and source).
steps.jsonl: one JSON object per line, one line per step (step 0, the initial state, first): its
time (days), the pose of every tooth, the touching pairs, the tooth-to-tooth distances and their
total, the largest interpenetration, the collisions (with the impact response) and the propagated
forces (cN); `read_steps(out_dir)` yields them. Why a separate file, streamed: a run of 10,000
steps holds some 100 MB of per-step detail, which kept in memory (and in metrics.json) grew the
process past a gigabyte; streamed to disk step by step, memory stays flat in the run's length.
distances.csv: one row per adjacent pair: pair, initial_mm, final_mm. distances_per_step.csv: one
row per step: step, time_days, total_distance_mm and each pair's distance (mm), the distance series
of steps.jsonl as a table, also streamed. metrics.json and distances.csv are written atomically;
steps.jsonl and distances_per_step.csv are written as the run goes (`orthosim run` writes
its whole run folder in private and swaps it in at the end, `orthosim.runtime.outputfolder`).
"""

from __future__ import annotations

import io
import json
import shutil
import tempfile
import warnings
from pathlib import Path
from typing import IO, Iterable, Iterator

import numpy as np

from orthosim.model.fdi import Arch, arch_of
from orthosim.storage.atomic import atomic_path, to_jsonable, write_json, write_text
from orthosim.geometry.motion import rotation_angle
from orthosim.collision.interpenetration import start_depths
from orthosim.mechanics.biomechanics import movement_type
from orthosim.movement.rootspread import ROOT_CROWN_SPREAD, moved_ranges
from orthosim.movement.simulation import MovementModel, StepRecord


STEPS_FILE = "steps.jsonl"
DISTANCES_PER_STEP_FILE = "distances_per_step.csv"


class InitialInterpenetrationWarning(UserWarning):
    """The model starts with teeth interpenetrating beyond the touch tolerance (pairs and depths named)."""


def read_steps(out_dir: str | Path) -> Iterator[dict]:
    """The per-step records of a run folder, in order, one at a time (see the module doc)."""
    with open(Path(out_dir) / STEPS_FILE) as fh:
        for line in fh:
            yield json.loads(line)


class RunReport:
    """Collects StepRecords of one run and builds the metrics (mm, degrees, cN, days).

    Only the first and the last record and running totals stay in memory; each step's detail goes
    to `steps_file` as it comes (to a temporary file, copied into the run folder by `write`, when
    no steps_file is given).
    """

    def __init__(self, model: MovementModel, detector: str, steps_file: str | Path | None = None,
                 distances_file: str | Path | None = None):
        self.model = model
        self.detector = detector
        self.first: StepRecord | None = None
        self._start: list | None = None  # ((a, b), mm) interpenetrating at the start, deepest first
        self.last: StepRecord | None = None
        self.max_penetration_mm = 0.0
        self.widest_bite_mm = 0.0  # the bite's largest opening at the incisors over the run (mm)
        self.collisions = 0
        self._spread: dict | None = None  # FDI -> (low, high) mm over the root spread, once worked out
        self.steps_file = Path(steps_file) if steps_file is not None else None
        self._steps: IO[str] | None = None
        self.distances_file = Path(distances_file) if distances_file is not None else None
        self._distances: IO[str] | None = None

    def collect(self, records: Iterable[StepRecord]) -> Iterator[StepRecord]:
        """Pass the records through, adding each (so a renderer can draw them as they come)."""
        for rec in records:
            self.add(rec)
            yield rec

    def add(self, rec: StepRecord) -> None:
        if self.first is None:
            self.first = rec
            self._warn_initial_interpenetration(rec)
        self.last = rec
        self.max_penetration_mm = max(self.max_penetration_mm, rec.max_penetration_mm)
        if rec.bite is not None:
            self.widest_bite_mm = max(self.widest_bite_mm, rec.bite.opening_incisors_mm)
        self.collisions += len(rec.collisions)
        present = self.model.present
        forces = {}
        if rec.forces is not None:
            forces = {
                "applied_cN": {str(n): f for n, f in rec.forces.applied.items() if np.any(f)},
                "propagated_cN": {str(n): f for n, f in rec.forces.received.items() if np.any(f)},
                "passed": [{"from": a, "to": b, "force_cN": f} for (a, b), f in rec.forces.passed.items()],
            }
        self._write_step({
            "step": rec.step,
            "time_days": rec.time_days,
            "poses": {str(n): rec.poses[n] for n in present},
            "moving": sorted(rec.moving),
            "touching": [list(p) for p in rec.touching],
            "distances_mm": [{"pair": list(d.pair), "mm": d.distance_mm} for d in rec.distances],
            "total_distance_mm": rec.total_distance_mm,
            "max_penetration_mm": rec.max_penetration_mm,
            "collisions": [{"pair": list(e.pair), "time": e.time, **e.impact} for e in rec.collisions],
            **forces,
            **({"bite": rec.bite.summary()} if rec.bite is not None else {}),
        })

    def _write_step(self, step: dict) -> None:
        if self._steps is None:
            self._steps = _spool(self.steps_file)
            self._distances = _spool(self.distances_file)
            pairs = [d["pair"] for d in step["distances_mm"]]
            self._distances.write(",".join(["step", "time_days", "total_distance_mm",
                                            *(f"{a}-{b}_mm" for a, b in pairs)]) + "\n")
        self._steps.write(json.dumps(step, separators=(",", ":"), default=to_jsonable))
        self._steps.write("\n")
        values = [f"{d['mm']:.4f}" for d in step["distances_mm"]]
        self._distances.write(",".join([str(step["step"]), f"{step['time_days']:g}",
                                        f"{step['total_distance_mm']:.4f}", *values]) + "\n")

    def initial_interpenetration(self) -> list[dict]:
        """Pairs interpenetrating at the start beyond the touch tolerance: [{pair, mm}], deepest first."""
        tol = self.model.settings.touch_tolerance_mm
        return [{"pair": list(p), "mm": d} for p, d in self._start_depths() if d > tol]

    def _start_depths(self) -> list:
        if self.first is None:
            return []
        if self._start is None:
            self._start = start_depths(self.model.dentition, self.first.penetrating, self.first.poses)
        return self._start

    def _warn_initial_interpenetration(self, first: StepRecord) -> None:
        deep = [(p, d) for p, d in self._start_depths() if d > self.model.settings.touch_tolerance_mm]
        if not deep:
            return
        shown = ", ".join(f"{a} and {b} by {d:.3f} mm" for (a, b), d in deep[:5])
        more = f" and {len(deep) - 5} more pairs" if len(deep) > 5 else ""
        warnings.warn(f"{self.model.case.path}: teeth interpenetrate at the start, beyond the "
                      f"{self.model.settings.touch_tolerance_mm:g} mm touch tolerance: {shown}{more}; penetration "
                      "during the run is measured from these depths (fix: check the model's tooth positions and "
                      "mesh scale)", InitialInterpenetrationWarning, stacklevel=3)

    def metrics(self) -> dict:
        if self.first is None:
            raise ValueError("no step recorded")
        m, first, last = self.model, self.first, self.last
        teeth = {}
        for n in m.dentition.fdis:
            t = m.dentition.teeth[n]
            c0 = t.to_world(t.crown_center, first.poses[n])
            c1 = t.to_world(t.crown_center, last.poses[n])
            teeth[str(n)] = {
                "moved_mm": float(np.linalg.norm(c1 - c0)),
                "rotated_deg": float(np.degrees(rotation_angle(first.poses[n], last.poses[n]))),
                "final_pose": last.poses[n],
                "extracted": n in m.extracted,
                "root": t.root_kind,
            }
        for n, info in self._load_movements().items():
            teeth[str(n)].update(info)
        spread = self._root_spread(teeth)
        bite = self._bite(teeth)
        s = m.settings
        return {
            "case": m.case.name,
            "detector": self.detector,
            "steps": last.step,
            "step_days": m.case.step_days,
            "duration_days": last.time_days,
            "wire": m.case.wire.type,
            "extracted": sorted(m.extracted),
            "settings": {"force_share": s.force_share, "restitution": s.restitution,
                         "resistance_rule": s.resistance_rule, "resistance_fraction": s.resistance_fraction,
                         "contact_tolerance_mm": s.contact_tolerance_mm, "touch_tolerance_mm": s.touch_tolerance_mm,
                         "occlusal_slide_mm": s.occlusal_slide_mm,
                         "rate": {"threshold_cN": s.rate.threshold_cN, "saturation_cN": s.rate.saturation_cN,
                                  "max_rate_mm_per_day": s.rate.max_rate_mm_per_day,
                                  "reference_root_area_mm2": s.rate.reference_root_area_mm2}},
            "teeth": teeth,
            "total_distance_mm": {"initial": first.total_distance_mm, "final": last.total_distance_mm},
            "max_penetration_mm": self.max_penetration_mm,
            "initial_penetration_mm": first.raw_penetration_mm,
            "initial_interpenetration": self.initial_interpenetration(),
            "collisions": self.collisions,
            "distances": [{"pair": list(a.pair), "initial_mm": a.distance_mm, "final_mm": b.distance_mm}
                          for a, b in zip(first.distances, last.distances)],
            "per_step_file": STEPS_FILE,
            **spread,
            **bite,
        }

    def _root_spread(self, teeth: dict) -> dict:
        """With estimated roots: each moving tooth's `moved_mm_range` over the plausible roots
        (`orthosim.movement.rootspread`, which simulates the spread's two ends: worked out once) and
        metrics.json's "root_spread"; {} when every root was seen."""
        if self._spread is None:
            self._spread = moved_ranges(self.model, self.detector, self.last.step, self.first, self.last)
        if not self._spread:
            return {}
        for n, (low, high) in self._spread.items():
            teeth[str(n)]["moved_mm_range"] = [low, high]
        return {"root_spread": {"root_crown_ratio_factors": list(ROOT_CROWN_SPREAD),
                                "source": "Hoelttae et al. 2004, Eur J Orthod 26(5):491-497 (see orthosim.movement.rootspread)"}}

    def _bite(self, teeth: dict) -> dict:
        """metrics.json's "bite" when the run closes the bite (and each lower tooth's `moved_in_mandible_mm`,
        its crown centre's displacement in the mandible, the jaw's turn taken out); {} otherwise."""
        cm, last = self.model.closure, self.last
        if cm is None or last.bite is None:
            return {}
        undo = cm.axis.transform(-last.bite.angle_deg)
        for n in self.model.dentition.fdis:
            if arch_of(n) is Arch.LOWER:
                t = self.model.dentition.teeth[n]
                c0 = t.to_world(t.crown_center, self.first.poses[n])
                teeth[str(n)]["moved_in_mandible_mm"] = float(np.linalg.norm(t.to_world(t.crown_center, undo @ last.poses[n]) - c0))
        return {"bite": {
            "closure": cm.settings.mode,
            "condylar_axis_mm": {"right": cm.axis.right_mm, "left": cm.axis.left_mm, "method": cm.axis.method},
            "angle_deg": last.bite.angle_deg,
            "vertical_dimension_change_mm": last.bite.opening_incisors_mm,
            "opening_molars_mm": last.bite.opening_molars_mm,
            "widest_opening_incisors_mm": self.widest_bite_mm,
            "contacts": [list(p) for p in last.bite.contacts],
        }}

    def _load_movements(self) -> dict[int, dict]:
        """Per loaded tooth: its centre of resistance (local mm), the couple-to-force ratio of its
        loads at the bracket (mm) and the movement that ratio and the wire make."""
        m = self.model
        out: dict[int, dict] = {}
        for load in m.case.loads:
            for n in load.teeth:
                if n not in m.mechanics:
                    continue
                mech = m.mechanics[n]
                if m.case.wire.type == "round":
                    kind, ratio = "tipping about 1/3 of the root (round wire)", 0.0
                elif load.force_cN == 0.0:
                    kind, ratio = ("rotation about the long axis" if load.moment_axis == "long_axis"
                                   else "rotation about the crown (torque)"), float("inf")
                elif load.movement in ("translation", "extrusion", "intrusion") or load.moment_cNmm == 0.0:
                    kind, ratio = load.movement if load.movement != "auto" else "translation", mech.bracket_lever_mm
                else:
                    ratio = abs(load.moment_cNmm) / load.force_cN
                    kind = movement_type(mech, ratio)
                out[n] = {"center_of_resistance_local_mm": mech.center_of_resistance,
                          "moment_to_force_mm": ratio if np.isfinite(ratio) else None, "movement": kind}
        return out

    def distances_csv(self) -> str:
        out = io.StringIO()
        out.write("pair,initial_mm,final_mm\n")
        for a, b in zip(self.first.distances, self.last.distances):
            out.write(f"{a.pair[0]}-{a.pair[1]},{a.distance_mm:.4f},{b.distance_mm:.4f}\n")
        return out.getvalue()

    def write(self, out_dir: str | Path, extra: dict | None = None) -> dict:
        """Write out_dir/metrics.json, steps.jsonl, distances.csv and distances_per_step.csv; returns the metrics."""
        out_dir = Path(out_dir)
        metrics = {**self.metrics(), **(extra or {})}
        self.finish_streams(out_dir)
        write_json(out_dir / "metrics.json", metrics)
        write_text(out_dir / "distances.csv", self.distances_csv())
        return metrics

    def finish_streams(self, out_dir: str | Path) -> None:
        """Close the streamed per-step files, putting those spooled elsewhere into out_dir."""
        out_dir = Path(out_dir)
        _finish(self._steps, self.steps_file, out_dir / STEPS_FILE)
        _finish(self._distances, self.distances_file, out_dir / DISTANCES_PER_STEP_FILE)
        self._steps = self._distances = None


def _spool(path: Path | None) -> IO[str]:
    """The file a stream is written to: `path`, or an anonymous temporary file when None."""
    if path is None:
        return tempfile.TemporaryFile("w+")
    path.parent.mkdir(parents=True, exist_ok=True)
    return open(path, "w")


def _finish(fh: IO[str] | None, path: Path | None, target: Path) -> None:
    """Close a stream; copy it to `target` (atomically) unless it was written there already."""
    if fh is None:
        return
    if path is not None and path.resolve() == target.resolve():
        fh.close()
        return
    fh.flush()
    fh.seek(0)
    with atomic_path(target) as tmp, open(tmp, "w") as out:
        shutil.copyfileobj(fh, out)
    fh.close()

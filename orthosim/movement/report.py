"""What a run writes: metrics.json (the issue's output contract, plus per-step detail) and distances.csv.

    report = RunReport(model, detector)
    for record in simulate(model, detector):
        report.add(record)
    report.write(out_dir)

metrics.json: `case`, `detector`, `steps`, `teeth` {FDI: `moved_mm` (crown centre displacement),
`rotated_deg`, `final_pose` (4x4, mm), `extracted`; for loaded teeth also their centre of
resistance, the loads' moment-to-force ratio (mm) and the movement it makes}, `total_distance_mm` {`initial`, `final`},
`max_penetration_mm` (exact meshes, over the run: the deepest
interpenetration the movement added to any pair; `initial_penetration_mm` is the model's own), `collisions` (count), `distances` (per adjacent
pair: `pair`, `initial_mm`, `final_mm`), and `per_step`: for every step its time (days), the pose of
every tooth, the touching pairs, the tooth-to-tooth distances and their total, the largest
interpenetration, the collisions (with the impact response) and the propagated forces (cN).
distances.csv: one row per adjacent pair: pair, initial_mm, final_mm. distances_per_step.csv: one
row per step: step, time_days, total_distance_mm and each pair's distance (mm), the series of
`per_step` in a table. Files are written atomically.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from ..atomic import write_json, write_text
from ..collision.motion import rotation_angle
from .biomechanics import movement_type
from .simulation import MovementModel, StepRecord


class RunReport:
    """Collects StepRecords of one run and builds the metrics (mm, degrees, cN, days)."""

    def __init__(self, model: MovementModel, detector: str):
        self.model = model
        self.detector = detector
        self.first: StepRecord | None = None
        self.last: StepRecord | None = None
        self.max_penetration_mm = 0.0
        self.collisions = 0
        self.per_step: list[dict] = []

    def collect(self, records: Iterable[StepRecord]) -> Iterator[StepRecord]:
        """Pass the records through, adding each (so a renderer can draw them as they come)."""
        for rec in records:
            self.add(rec)
            yield rec

    def add(self, rec: StepRecord) -> None:
        if self.first is None:
            self.first = rec
        self.last = rec
        self.max_penetration_mm = max(self.max_penetration_mm, rec.max_penetration_mm)
        self.collisions += len(rec.collisions)
        present = self.model.present
        forces = {}
        if rec.forces is not None:
            forces = {
                "applied_cN": {str(n): f for n, f in rec.forces.applied.items() if np.any(f)},
                "propagated_cN": {str(n): f for n, f in rec.forces.received.items() if np.any(f)},
                "passed": [{"from": a, "to": b, "force_cN": f} for (a, b), f in rec.forces.passed.items()],
            }
        self.per_step.append({
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
        })

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
            }
        for n, info in self._load_movements().items():
            teeth[str(n)].update(info)
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
                         "rate": {"threshold_cN": s.rate.threshold_cN, "saturation_cN": s.rate.saturation_cN,
                                  "max_rate_mm_per_day": s.rate.max_rate_mm_per_day,
                                  "reference_root_area_mm2": s.rate.reference_root_area_mm2}},
            "teeth": teeth,
            "total_distance_mm": {"initial": first.total_distance_mm, "final": last.total_distance_mm},
            "max_penetration_mm": self.max_penetration_mm,
            "initial_penetration_mm": first.raw_penetration_mm,
            "collisions": self.collisions,
            "distances": [{"pair": list(a.pair), "initial_mm": a.distance_mm, "final_mm": b.distance_mm}
                          for a, b in zip(first.distances, last.distances)],
            "per_step": self.per_step,
        }

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

    def distances_per_step_csv(self) -> str:
        """One row per step: step, time_days, total_distance_mm, then each adjacent pair's distance (mm)."""
        out = io.StringIO()
        pairs = [d["pair"] for d in self.per_step[0]["distances_mm"]] if self.per_step else []
        out.write(",".join(["step", "time_days", "total_distance_mm", *(f"{a}-{b}_mm" for a, b in pairs)]) + "\n")
        for row in self.per_step:
            values = [f"{d['mm']:.4f}" for d in row["distances_mm"]]
            out.write(",".join([str(row["step"]), f"{row['time_days']:g}", f"{row['total_distance_mm']:.4f}", *values]) + "\n")
        return out.getvalue()

    def write(self, out_dir: str | Path, extra: dict | None = None) -> dict:
        """Write out_dir/metrics.json, distances.csv and distances_per_step.csv; returns the metrics."""
        out_dir = Path(out_dir)
        metrics = {**self.metrics(), **(extra or {})}
        write_json(out_dir / "metrics.json", metrics)
        write_text(out_dir / "distances.csv", self.distances_csv())
        write_text(out_dir / "distances_per_step.csv", self.distances_per_step_csv())
        return metrics

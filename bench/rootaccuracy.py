"""How far an estimated root lies from the real one: whole teeth cut to crowns, rebuilt, compared.

Each tooth of a dentition with real roots (Open-Full-Jaw: CBCT) is cut at its estimated CEJ plane
(`orthosim.exchange.meshload.CEJ_RULE`, across its long axis), given an estimated root
(`orthosim.model.rootsynthesis`) and placed as a crown-only import would place it; the result is
compared with the real tooth in the arch frame (mm, degrees):
  apex_mm              distance between the two apex points (on each tooth's long axis, at its root length)
  root_length_mm       estimated minus real root length (CEJ to apex along the long axis)
  axis_deg             angle between the two meshes' principal axes (`meshload.principal_long_axis`),
                       so a root bent away from the crown's axis counts, whatever frame was used
  resistance_mm        distance between the centres of resistance (`orthosim.mechanics.resistance`, literature rule)
Measurement, not product: the CLI's bench and the tests call it, the product never does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from orthosim.exchange.meshload import ToothAxes, principal_long_axis, tooth_from_mesh
from orthosim.model import fdi as fdi_mod
from orthosim.model.rootsynthesis import synthesize_root
from orthosim.mechanics.resistance import center_of_resistance
from orthosim_bench.scanarch import crown_at_cej


@dataclass(frozen=True)
class RootError:
    fdi: int
    tooth_type: str  # e.g. "upper canine"
    apex_mm: float
    root_length_mm: float  # estimated - real
    axis_deg: float
    resistance_mm: float


def root_errors(dentition) -> list[RootError]:
    """One `RootError` per tooth of `dentition` (teeth with real roots, arch frame)."""
    out = []
    for n in dentition.fdis:
        real = dentition.teeth[n]
        labial = real.rest_pose[:3, 2]
        rooted = synthesize_root(crown_at_cej(real), n, f"tooth {n}", labial=labial)
        est = tooth_from_mesh(n, rooted.mesh, ToothAxes(rooted.long_axis, labial, rooted.margin_centre), f"tooth {n}")
        a_real, _ = principal_long_axis(real.world_mesh())
        a_est, _ = principal_long_axis(rooted.mesh)
        angle = float(np.degrees(np.arccos(min(1.0, abs(float(a_real @ a_est))))))
        cr_real = real.to_world(center_of_resistance(real))
        cr_est = est.to_world(center_of_resistance(est))
        arch = "upper" if fdi_mod.arch_of(n) is fdi_mod.Arch.UPPER else "lower"
        out.append(RootError(n, f"{arch} {fdi_mod.tooth_type(n).name.lower().replace('_', ' ')}",
                             float(np.linalg.norm(est.to_world(est.apex) - real.to_world(real.apex))),
                             est.root_length - real.root_length, angle,
                             float(np.linalg.norm(cr_est - cr_real))))
    return out


def table_by_type(errors: list[RootError]) -> str:
    """A Markdown table: per tooth type, the teeth and the median of each error (mm, degrees)."""
    rows = ["| tooth type | teeth | apex (mm) | root length est. - real (mm) | long axis (deg) | centre of resistance (mm) |",
            "|---|---|---|---|---|---|"]
    by_type: dict[str, list[RootError]] = {}
    for e in errors:
        by_type.setdefault(e.tooth_type, []).append(e)
    for name, group in by_type.items():
        med = [float(np.median([getattr(e, f) for e in group])) for f in ("apex_mm", "root_length_mm", "axis_deg",
                                                                          "resistance_mm")]
        rows.append(f"| {name} | {', '.join(str(e.fdi) for e in group)} | {med[0]:.1f} | {med[1]:+.1f} | "
                    f"{med[2]:.1f} | {med[3]:.2f} |")
    med = [float(np.median([getattr(e, f) for e in errors])) for f in ("apex_mm", "root_length_mm", "axis_deg",
                                                                       "resistance_mm")]
    rows.append(f"| **all {len(errors)}** | | {med[0]:.1f} | {med[1]:+.1f} | {med[2]:.1f} | {med[3]:.2f} |")
    return "\n".join(rows)

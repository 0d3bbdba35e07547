"""The rate law of tooth movement and its named parameter sets (see `orthosim.mechanics.biomechanics`).

Apart from the rest of the movement model so that reading a case file (its [biomechanics] table
names a set) needs numpy alone. Units: cN, mm/day, mm^2; a month is 365.25/12 days.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DAYS_PER_MONTH = 365.25 / 12.0  # the trials' "per month"


@dataclass(frozen=True)
class RateLaw:
    """Tooth movement rate as a function of force (see the module text). Units: cN, mm/day, mm^2."""

    threshold_cN: float = 20.0
    saturation_cN: float = 150.0
    max_rate_mm_per_day: float = 1.0 / 30.0
    reference_root_area_mm2: float = 200.0
    mandibular_bone_factor: float = 1.0  # a lower tooth's root resists as if k times larger (see the module text)

    def rate(self, force_cN, root_area_mm2) -> np.ndarray:
        """mm/day for a force magnitude (cN, scalar or array) on a root of `root_area_mm2` (mm^2)
        (a float for a float force and area: the same IEEE operations without numpy's per-call cost)."""
        if isinstance(force_cN, float) and isinstance(root_area_mm2, float):
            x = (force_cN * self.reference_root_area_mm2 / root_area_mm2 - self.threshold_cN) / (
                self.saturation_cN - self.threshold_cN)
            if x != x:
                return math.nan
            return self.max_rate_mm_per_day * (0.0 if x < 0.0 else 1.0 if x > 1.0 else x)
        f_eff = np.asarray(force_cN, float) * self.reference_root_area_mm2 / np.asarray(root_area_mm2, float)
        s = np.clip((f_eff - self.threshold_cN) / (self.saturation_cN - self.threshold_cN), 0.0, 1.0)
        return self.max_rate_mm_per_day * s

    def moves(self, force_cN, root_area_mm2) -> bool:
        """Whether the force is above the threshold for this root (scalar)."""
        return bool(self.rate(force_cN, root_area_mm2) > 0.0)


# Named parameter sets of the rate law. "paper": the replication values the paper's cases keep (the
# step guard and golden images hold them). "clinical": least-squares fit to the evidence table's
# rate and anchorage rows (`orthosim.evidence.calibration.fit_clinical`; a test refits and compares).
PARAMETER_SETS: dict[str, RateLaw] = {
    "paper": RateLaw(),
    "clinical": RateLaw(threshold_cN=21.1, saturation_cN=46.1, max_rate_mm_per_day=0.715 / DAYS_PER_MONTH,
                        reference_root_area_mm2=200.0, mandibular_bone_factor=2.49),
}

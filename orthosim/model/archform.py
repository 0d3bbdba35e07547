"""Dental arch forms in the occlusal (x-z) plane, parametrised by arc length.

The default is the beta function of Braun et al. (1998): z = 3.0314 D [(1/2 + x/W)(1/2 - x/W)]^0.8,
with W the arch width and D the arch depth (mm): z = D at the midline, z = 0 at the distal ends
x = +-W/2. Past the ends the curve continues straight back (-z) along its end tangent, so a long
row of teeth never runs off the curve.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_BETA_K = 3.0314  # makes z(0) = D exactly: 3.0314 * (1/4)^0.8 = 1.0000
EXTENSION = 40.0  # mm of straight continuation past each distal end


@dataclass(frozen=True, eq=False)
class BetaArch:
    width: float  # W, mm
    depth: float  # D, mm
    samples: int = 4000
    _table: tuple = field(init=False, repr=False)
    _half_length: float = field(init=False, repr=False)

    def __post_init__(self):
        # Sample by angle so that points crowd toward the ends, where the slope becomes vertical,
        # then append the straight continuation (EXTENSION mm) so every query is one interpolation.
        phi = np.linspace(0.0, np.pi / 2, self.samples)
        x = 0.5 * self.width * np.sin(phi)
        z = self.z(x)
        s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(z)))])
        ext = np.linspace(0.0, EXTENSION, 801)[1:]
        table = (np.concatenate([s, s[-1] + ext]), np.concatenate([x, np.full_like(ext, x[-1])]),
                 np.concatenate([z, -ext]))
        object.__setattr__(self, "_table", table)
        object.__setattr__(self, "_half_length", float(s[-1]))

    def z(self, x: np.ndarray) -> np.ndarray:
        u = np.clip((0.5 + x / self.width) * (0.5 - x / self.width), 0.0, None)
        return _BETA_K * self.depth * u**0.8

    @property
    def half_length(self) -> float:
        """mm of curve from the midline to one distal end."""
        return self._half_length

    def point(self, s: np.ndarray | float, side: int) -> np.ndarray:
        """(..., 2) x-z points at arc length `s` (mm) from the midline, side -1 (right) or +1 (left)."""
        s_tab, x_tab, z_tab = self._table
        s = np.asarray(s, float)
        return np.stack([side * np.interp(s, s_tab, x_tab), np.interp(s, s_tab, z_tab)], axis=-1)

    def point_at_chord(self, s0: float, chord: float, side: int) -> float:
        """Arc length s1 > s0 whose point lies `chord` mm (straight line) from the point at s0."""
        s_tab, x_tab, z_tab = self._table
        p0 = self.point(s0, side)
        i0 = int(np.searchsorted(s_tab, s0))
        d = np.hypot(side * x_tab[i0:] - p0[0], z_tab[i0:] - p0[1])
        k = int(np.argmax(d >= chord))  # the chord grows monotonically along an arch this convex
        if d[k] < chord:
            raise ValueError(f"chord of {chord} mm from s={s0} runs past the end of the arch table")
        lo = s_tab[i0 + k - 1] if k else s0
        hi = s_tab[i0 + k]
        for _ in range(30):  # bisection inside one table interval: exact to float precision
            mid = 0.5 * (lo + hi)
            if np.linalg.norm(self.point(mid, side) - p0) < chord:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)


def arch_with_half_length(width: float, half_length: float) -> BetaArch:
    """The beta arch of width `width` whose midline-to-end arc length is `half_length` (mm)."""
    lo, hi = 1.0, 3.0 * half_length
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if BetaArch(width, mid, 800).half_length < half_length:
            lo = mid
        else:
            hi = mid
    return BetaArch(width, 0.5 * (lo + hi))

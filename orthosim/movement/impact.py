"""Collision response between two teeth: a rigid-body impact with restitution, as the paper reports it.

The paper computes, for each collision, the velocities after impact from conservation of linear and
angular momentum and the kinetic energy lost. Here each tooth is a free rigid body of its mesh's
mass (density 2.2 g/cm^3, see `biomechanics`) and inertia tensor; its velocities are those of the
step that led to the contact (displacement / step duration). An impulse J n along the contact
normal n, with Newton's restitution coefficient e on the normal approach speed, gives

    J = (1 + e) u.n / (1/m_a + 1/m_b + n.((I_a^-1 (r_a x n)) x r_a) + n.((I_b^-1 (r_b x n)) x r_b))

(u the approach velocity of a's contact point relative to b's, r the contact point from each
centre of mass). Linear momentum and angular momentum (about any fixed point) are conserved; the
kinetic energy lost is zero for e = 1 and grows as e falls. Orthodontic movement is quasi-static
(the periodontal ligament damps it completely), so the simulator reports this response and, as the
paper does, stops the moving tooth at the contact; it does not move teeth by it.

Units: g, mm, days (velocities mm/day, angular velocities rad/day); energies also in joules.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# 1 g * mm^2 / day^2 in joules: 1e-3 kg * 1e-6 m^2 / 86400^2 s^2
G_MM2_PER_DAY2_IN_J = 1e-9 / 86400.0**2


@dataclass(frozen=True)
class Body:
    """A rigid body at the instant of impact (arch frame): mass (g), centre of mass (mm), inertia
    tensor about the centre of mass (g*mm^2), velocity of the centre of mass (mm/day), angular
    velocity (rad/day)."""

    mass_g: float
    center_of_mass: np.ndarray
    inertia_g_mm2: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray

    def kinetic_energy(self) -> float:
        """g*mm^2/day^2."""
        v, w = self.velocity, self.omega
        return 0.5 * self.mass_g * float(v @ v) + 0.5 * float(w @ self.inertia_g_mm2 @ w)

    def linear_momentum(self) -> np.ndarray:
        return self.mass_g * self.velocity

    def angular_momentum(self, about: np.ndarray = np.zeros(3)) -> np.ndarray:
        """g*mm^2/day about a fixed point (mm)."""
        return np.cross(self.center_of_mass - about, self.linear_momentum()) + self.inertia_g_mm2 @ self.omega


@dataclass(frozen=True)
class Impact:
    """One collision's response: bodies before and after, the impulse (g*mm/day), energy lost."""

    before: tuple[Body, Body]
    after: tuple[Body, Body]
    impulse: float
    normal: np.ndarray
    point: np.ndarray
    restitution: float

    @property
    def kinetic_energy_lost(self) -> float:
        """g*mm^2/day^2 (>= 0)."""
        return sum(b.kinetic_energy() for b in self.before) - sum(b.kinetic_energy() for b in self.after)

    @property
    def kinetic_energy_lost_J(self) -> float:
        return self.kinetic_energy_lost * G_MM2_PER_DAY2_IN_J

    def summary(self) -> dict:
        ke0 = sum(b.kinetic_energy() for b in self.before)
        return {
            "restitution": self.restitution,
            "impulse_g_mm_per_day": self.impulse,
            "velocity_after_mm_per_day": [b.velocity for b in self.after],
            "omega_after_rad_per_day": [b.omega for b in self.after],
            "kinetic_energy_before_J": ke0 * G_MM2_PER_DAY2_IN_J,
            "kinetic_energy_lost_J": self.kinetic_energy_lost_J,
            "kinetic_energy_lost_fraction": self.kinetic_energy_lost / ke0 if ke0 > 0 else 0.0,
        }


def impact(a: Body, b: Body, point: np.ndarray, normal: np.ndarray, restitution: float) -> Impact:
    """Impact of body a on body b at `point` (mm) with contact normal `normal` (unit, from a toward b).

    restitution e in [0, 1]. Bodies that are not approaching at the point are returned unchanged.
    """
    if not 0.0 <= restitution <= 1.0:
        raise ValueError("restitution must be in [0, 1]")
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    p = np.asarray(point, float)
    ra, rb = p - a.center_of_mass, p - b.center_of_mass
    Ia_inv, Ib_inv = np.linalg.inv(a.inertia_g_mm2), np.linalg.inv(b.inertia_g_mm2)
    u = (a.velocity + np.cross(a.omega, ra)) - (b.velocity + np.cross(b.omega, rb))
    approach = float(u @ n)
    if approach <= 0.0:
        return Impact((a, b), (a, b), 0.0, n, p, restitution)
    k = 1.0 / a.mass_g + 1.0 / b.mass_g + float(n @ np.cross(Ia_inv @ np.cross(ra, n), ra)) \
        + float(n @ np.cross(Ib_inv @ np.cross(rb, n), rb))
    J = (1.0 + restitution) * approach / k
    a2 = Body(a.mass_g, a.center_of_mass, a.inertia_g_mm2, a.velocity - J * n / a.mass_g, a.omega - Ia_inv @ np.cross(ra, J * n))
    b2 = Body(b.mass_g, b.center_of_mass, b.inertia_g_mm2, b.velocity + J * n / b.mass_g, b.omega + Ib_inv @ np.cross(rb, J * n))
    return Impact((a, b), (a2, b2), J, n, p, restitution)

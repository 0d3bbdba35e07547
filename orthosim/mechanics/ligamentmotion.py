"""A tooth's motion over a step from its ligament's compliance (`resistance_rule = "ligament"`): the
direction of the motion comes from the root's stiffness (`orthosim.mechanics.ligament`), its speed
from the rate law on the embedded root surface.

The ligament gives the instantaneous motion (translation of the centre of resistance t_c, rotation
theta) the force system would make elastically; remodelling is taken to follow it at the rate law's
speed: the motion is scaled so that a force of the same size through the centre of resistance would
move that centre at rate(|F|, embedded area) along F (`orthosim.mechanics.ratelaw`). So the classical
M/F table is not written in anywhere: where the tooth turns follows from the root's geometry.

Wires (the paper's set-up, with the ligament in place of the rules):
  rectangular + a bodily load: the wire in the slot holds the tooth's rotation and every
      translation but the one along F (sliding mechanics); the tooth translates along F at the rate
      law's speed on its embedded root surface (the ligament's compliance across F is taken by the wire);
  rectangular + force with a couple, and round + force (or couple): the force system as it stands,
      free of the wire's moment;
  rectangular + a couple alone: the wire holds the bracket, the tooth turns about it with the
      rotational compliance about the bracket, as fast as the force M / d at the bracket would move
      it (d: bracket to centre of resistance).
Forces in cN and couples in cN*mm (arch frame) as everywhere in the step; the ligament's own units
(N, N*mm) cancel in the directions. Rates in mm/day and rad/day.
"""

from __future__ import annotations

import numpy as np

from orthosim.mechanics.biomechanics import Motion, ToothMechanics
from orthosim.mechanics.ligament import skew
from orthosim.mechanics.ratelaw import RateLaw
from orthosim.mechanics.vec import length


def ligament_motion(mech: ToothMechanics, pose: np.ndarray, force_cN: np.ndarray, point: np.ndarray,
                    couple_cNmm: np.ndarray, wire: str, translation_only: bool, law: RateLaw) -> Motion:
    """The tooth's motion under one resultant force system (see the module text); the arguments as
    `orthosim.mechanics.biomechanics.tooth_motion`'s: pose (4, 4) local -> arch frame, force_cN (3,)
    cN at point (3,) mm, couple_cNmm (3,) cN*mm, all arch frame; wire 'rectangular' or 'round'."""
    support = mech.support
    R, p = pose[:3, :3], pose[:3, 3]
    F = R.T @ np.asarray(force_cN, float)
    M = R.T @ np.asarray(couple_cNmm, float)
    c = support.center_of_resistance
    C = R @ c + p
    f = length(F)
    area = mech.resisting_area_mm2
    if f > 0:
        rate = law.rate(f, area)
        if wire == "rectangular" and translation_only:
            return Motion(C, np.asarray(force_cN, float) * (rate / f), np.zeros(3))
        t0, w0 = support.motion(F, c)  # the same force through the centre of resistance
        along = float((t0 + np.cross(w0, c)) @ F) / f
        scale = rate / along if along > 0 else 0.0
        t, w = support.motion(F, R.T @ (np.asarray(point, float) - p), M)
        return Motion(C, R @ ((t + np.cross(w, c)) * scale), R @ (w * scale))
    m = length(M)
    if m == 0.0:
        return Motion.still(C)
    b = mech.bracket
    d = length(b - c) or 1.0
    if wire == "rectangular":  # the bracket held: the rotational stiffness about it
        G = np.vstack([skew(b), np.eye(3)])
        w = np.linalg.solve(G.T @ support.stiffness @ G, M)
        pivot = R @ b + p
        return Motion(pivot, np.zeros(3), R @ (w * (law.rate(m / d, area) / d / length(w))))
    t, w = support.motion(np.zeros(3), np.zeros(3), M)
    s = law.rate(m / d, area) / d / length(w)
    return Motion(C, R @ ((t + np.cross(w, c)) * s), R @ (w * s))

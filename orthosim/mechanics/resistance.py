"""Centre of resistance of a tooth: the point on its long axis where a force translates it without turning.

Two rules, both on the long axis in the tooth's local frame (origin at the CEJ, +y toward the
crown, mm):

  "paper"       the paper's value: 1/3 of the root length from the apex, y = -2L/3.
  "literature"  (default) the orthodontic literature's: a fraction f (1/3 to 1/2, default 0.4) of the
                embedded root length below the alveolar crest. The crest sits 1.5 mm apical of the CEJ
                in health, so y = -(1.5 + f (L - 1.5)).

Multi-rooted molars resist near the furcation, not along one root: with the literature rule their
centre sits 1 mm apical of the furcation, which we place at the end of the root trunk, 4 mm below
the CEJ for upper molars (trifurcation) and 3 mm for lower ones (bifurcation): y = -5 mm and -4 mm.
The paper's rule makes no such exception and is kept as the paper gives it.

The round-wire tipping centre (the paper's "1/3 of root length") is `tipping_center` below: the
paper puts it at the same place as its centre of resistance, whatever rule is used for the latter.
"""

from __future__ import annotations

import numpy as np

from orthosim.model import fdi as F
from orthosim.errors import CaseError
from orthosim.model.tooth import Tooth

RULES = ("literature", "paper")
CREST_BELOW_CEJ_MM = 1.5  # alveolar crest, mm apical of the CEJ (healthy periodontium)
FURCATION_BELOW_CEJ_MM = {F.Arch.UPPER: 4.0, F.Arch.LOWER: 3.0}  # root trunk length of molars, mm
BELOW_FURCATION_MM = 1.0  # molar centre of resistance, mm apical of the furcation
FRACTION_RANGE = (1.0 / 3.0, 0.5)


def center_of_resistance(tooth: Tooth, rule: str = "literature", fraction: float = 0.4) -> np.ndarray:
    """(3,) local point (mm) of the tooth's centre of resistance on its long axis, by `rule`.

    fraction: literature rule only, share of the embedded root length (crest to apex) below the
    crest, between 1/3 and 1/2.
    """
    if rule not in RULES:
        raise CaseError(None, "simulation.resistance_rule", f"unknown rule {rule!r}", f"use one of: {', '.join(RULES)}")
    if not (FRACTION_RANGE[0] - 1e-9 <= fraction <= FRACTION_RANGE[1] + 1e-9):
        raise CaseError(None, "simulation.resistance_fraction", f"{fraction:g} is outside 1/3 to 1/2",
                        "use a fraction of the embedded root length between 0.333 and 0.5")
    L = tooth.root_length
    if rule == "paper":
        y = -2.0 * L / 3.0
    elif tooth.type.is_molar:
        y = -(FURCATION_BELOW_CEJ_MM[tooth.arch] + BELOW_FURCATION_MM)
    else:
        y = -(CREST_BELOW_CEJ_MM + fraction * max(L - CREST_BELOW_CEJ_MM, 0.0))
    return np.array([0.0, y, 0.0])


def tipping_center(tooth: Tooth) -> np.ndarray:
    """(3,) local point (mm): the paper's centre of rotation under a round wire, 1/3 of root length from the apex."""
    return np.array([0.0, -2.0 * tooth.root_length / 3.0, 0.0])

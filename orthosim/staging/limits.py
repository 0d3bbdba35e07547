"""Per-stage movement limits: how far one aligner may move one tooth, component by component.

Defaults are the common clinical ones (ArchForm's defaults, for instance): mesiodistal and
buccolingual 0.25 mm, extrusion/intrusion 0.15 mm, tip 2 degrees, torque 1 degree, rotation 2
degrees per stage. A stage's components are measured as in `orthosim.exchange.target`
(`movement_components`): translation of the tooth's local origin, angles as rotation-vector
components in the tooth's start frame; each must stay within its limit in absolute value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from orthosim.errors import OrthosimError
from orthosim.exchange.target import COMPONENTS, UNITS


class LimitsError(OrthosimError):
    """A `--limits` value that cannot be used."""


@dataclass(frozen=True)
class StageLimits:
    """The most one aligner stage may move a tooth, per component: mesial/distal, buccal/lingual
    and extrusion/intrusion in mm; tip, torque and rotation in degrees."""

    mesial: float = 0.25  # mm per stage, mesial or distal
    buccal: float = 0.25  # mm per stage, buccal or lingual
    extrusion: float = 0.15  # mm per stage, extrusion or intrusion
    tip: float = 2.0  # degrees per stage
    torque: float = 1.0  # degrees per stage
    rotation: float = 2.0  # degrees per stage

    def array(self) -> np.ndarray:
        """(6,) in COMPONENTS order: mm, mm, mm, deg, deg, deg."""
        return np.array([getattr(self, c) for c in COMPONENTS])

    def text(self) -> str:
        return ",".join(f"{c}={getattr(self, c):g}" for c in COMPONENTS)

    @classmethod
    def parse(cls, text: str | None, where: str = "--limits") -> "StageLimits":
        """`mesial=0.25,buccal=0.25,...` (any subset; the rest keep their defaults). LimitsError on
        an unknown name, a repeated one, or a value that is not a positive finite number."""
        if text is None or not text.strip():
            return cls()
        values: dict[str, float] = {}
        names = [f.name for f in fields(cls)]
        for item in text.split(","):
            name, sep, value = item.partition("=")
            name = name.strip()
            if not sep:
                raise LimitsError(where, item.strip() or "(empty)", "is not name=value",
                                  f"write e.g. {cls().text()}")
            if name not in names:
                raise LimitsError(where, name, "unknown limit", f"use any of: {', '.join(names)}")
            if name in values:
                raise LimitsError(where, name, "given twice", "give each limit once")
            try:
                v = float(value)
            except ValueError:
                v = math.nan
            if not math.isfinite(v) or v <= 0:
                raise LimitsError(where, name, f"must be a positive number ({UNITS[name]} per stage), got {value.strip()!r}",
                                  f"e.g. {name}={getattr(cls(), name):g}")
            values[name] = v
        return cls(**values)

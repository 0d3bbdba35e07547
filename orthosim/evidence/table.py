"""The evidence table (`orthosim/evidence/evidence.toml`) read and checked, and what a run of a row gives.

A row is either calibration (`fitted = true`: its published value was used to fit a constant, so it
is inside by construction) or validation (`fitted = false`: the model meets it, or not, without
having seen it). Every row can fail: its published value is a number, and its interval is finite
and no wider than that value's magnitude (or than 1 unit where the value is near zero); a source
that gives a class and no number is no row.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from orthosim.errors import CaseError
from orthosim.exchange.casefields import FieldReader

EVIDENCE_TABLE = Path(__file__).resolve().with_name("evidence.toml")
TOPICS = ("rate", "rate vs force", "centre of resistance", "M/F", "anchorage")
MODELS = ("parametric", "real")
# each kind of row (how orthosim sets it up, `kinds.MEASURES`) and the set-up keys it needs
KIND_KEYS: dict[str, tuple[str, ...]] = {
    "rate": ("tooth", "force_cN"),
    "rate_ratio": ("tooth", "force_cN", "reference_force_cN"),
    "cr_share": ("teeth",),
    "cr_below_bracket": ("teeth",),
    "cr_lingual_of_bracket": ("teeth",),
    "mf_center": ("tooth", "center"),
    "anchorage_canine": ("tooth", "anchor_teeth", "force_cN", "reinforced"),
    "anchorage_en_masse": ("teeth", "anchor_teeth", "force_cN"),
}
# set-up keys a kind may leave out (then the model's own value is used)
OPTIONAL_KEYS: dict[str, tuple[str, ...]] = {"mf_center": ("bracket_above_cr_mm",)}
_ROW = ("id", "topic", "source", "figure", "measured", "force_system", "unit", "mean", "low", "high", "interval",
        "kind", "model", "fitted", "outside")
NEAR_ZERO_WIDTH = 1.0  # the widest interval (in the row's unit) allowed around a published value under 1 unit
# (so a share is given in %, not as a fraction of 1)


@dataclass(frozen=True)
class EvidenceRow:
    """One measured figure of the table; `setup` holds its kind's keys (FDI numbers, cN, mm)."""

    id: str
    topic: str
    source: str
    figure: str
    measured: str
    force_system: str
    unit: str
    mean: float
    low: float
    high: float
    interval: str
    kind: str
    model: str
    fitted: bool  # True: a calibration row (its value fitted a constant); False: a validation row
    outside: str = ""
    setup: Mapping[str, Any] = field(default_factory=dict)

    @property
    def role(self) -> str:
        """'calibration' or 'validation'."""
        return "calibration" if self.fitted else "validation"


@dataclass(frozen=True)
class Curve:
    """What a row's plot shows: x (n,) and y (n,) with their labels (y may hold NaN: gaps)."""

    x: np.ndarray
    y: np.ndarray
    x_label: str
    y_label: str
    style: str = "line"  # "line" or "bars" (x then holds positions, `ticks` their names)
    ticks: tuple[str, ...] = ()
    series: Mapping[str, np.ndarray] = field(default_factory=dict)  # more y arrays over the same x
    marks: Mapping[str, float] = field(default_factory=dict)  # named levels of y (drawn as horizontal lines)


@dataclass(frozen=True)
class RowResult:
    """A row run: the simulated value (nan when skipped), its verdict and the curve behind it."""

    row: EvidenceRow
    value: float
    status: str  # "inside", "outside" or "skipped"
    note: str  # how the value was found (one line); for a skipped row, why
    curve: Curve | None = None

    @property
    def inside(self) -> bool:
        return self.status == "inside"

    @property
    def reason(self) -> str:
        """The one-line reason shown for a row outside its interval ('' when inside or skipped)."""
        if self.status != "outside":
            return ""
        return self.row.outside or "no reason recorded: the model misses this figure"


def load_evidence(path: str | Path = EVIDENCE_TABLE) -> tuple[EvidenceRow, ...]:
    """The evidence table, every row checked (CaseError naming the file, the field and the fix)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise CaseError(path, None, f"cannot be read as TOML: {err}", "restore the file from the package") from None
    top = FieldReader(path, "", data, ("rows",))
    raw = top.get("rows")
    if not isinstance(raw, list) or not raw:
        top.fail("rows", "missing or empty", "add [[rows]] tables")
    rows = tuple(_read_row(path, i, r) for i, r in enumerate(raw))
    ids = [r.id for r in rows]
    if len(set(ids)) != len(ids):
        top.fail("rows", "two rows share an id", "give each row its own id")
    return rows


def _read_row(path: Path, i: int, raw: Any) -> EvidenceRow:
    if not isinstance(raw, dict):
        FieldReader(path, f"rows[{i}]", {}, ()).fail(None, "must be a table", "write it as [[rows]]")
    kind = raw.get("kind")
    if kind not in KIND_KEYS:
        FieldReader(path, f"rows[{i}]", {}, ()).fail("kind", f"unknown kind {kind!r}", f"use one of: {', '.join(KIND_KEYS)}")
    keys, optional = KIND_KEYS[kind], OPTIONAL_KEYS.get(kind, ())
    r = FieldReader(path, f"rows[{i}]", raw, _ROW + keys + optional)
    text = {k: r.string(k) for k in ("id", "source", "figure", "measured", "force_system", "unit", "interval")}
    mean, low, high = _interval(r, raw)
    if not isinstance(raw.get("fitted"), bool):
        r.fail("fitted", "missing, or not true or false",
               "write fitted = true when the value was used to fit a constant, false when it validates the model")
    setup = {}
    for k in keys:
        if k not in raw:
            r.fail(k, "missing", f"a {kind} row needs {', '.join(keys)}")
        setup[k] = raw[k]
    setup.update({k: raw[k] for k in optional if k in raw})
    return EvidenceRow(text["id"], r.string("topic", choices=TOPICS), text["source"], text["figure"], text["measured"],
                       text["force_system"], text["unit"], mean, low, high, text["interval"], kind,
                       r.string("model", choices=MODELS), raw["fitted"], r.string("outside", ""), setup)


def _interval(r: FieldReader, raw: Any) -> tuple[float, float, float]:
    """(mean, low, high) of a row, checked so that the row can fail: a published number, inside a
    finite interval no wider than its magnitude (or than NEAR_ZERO_WIDTH near zero)."""
    if "mean" not in raw:
        r.fail("mean", "missing: a row needs the published number",
               "give the source's number; a source that gives a class and no number is no row")
    mean, low, high = (r.number(k, minimum=None) for k in ("mean", "low", "high"))
    if not low <= high:
        r.fail("high", f"the interval [{low:g}, {high:g}] is empty", "write low <= high")
    if not low <= mean <= high:
        r.fail("mean", f"{mean:g} lies outside its interval [{low:g}, {high:g}]", "write an interval around the published value")
    widest = max(abs(mean), NEAR_ZERO_WIDTH)
    if high - low > widest + 1e-12:
        r.fail("high", f"the interval [{low:g}, {high:g}] is wider than {widest:g}, so the row could hardly fail",
               f"narrow it to a full width of at most |mean| (or {NEAR_ZERO_WIDTH:g} near zero), or leave the row out")
    return mean, low, high

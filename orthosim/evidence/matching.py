"""Which evidence rows a case's force systems fall under: the line the contact-area report prints per case.

A row "covers" a case when the case loads the same kind of tooth (same arch, same place in the
quadrant) with a force system of the row's kind: a distal retraction within a quarter of the
row's force for a rate row; a distal force between the two forces of a rate-against-force row; a
canine retraction whose reaction does (molar anchorage) or does not (mini-implant) load the anchor
teeth for an anchorage row; a bodily load on one of the row's teeth for a centre-of-resistance
row (bodily movement is defined by the force through the centre of resistance); a force with a
couple whose M/F (mm) lies in the row's interval, or a bodily load on a rectangular wire (which
supplies the translation ratio), for an M/F row. Rows on the real patient cover cases on real
teeth, rows on the parametric model cases on it.
"""

from __future__ import annotations

from dataclasses import dataclass

from orthosim.evidence.table import EvidenceRow, load_evidence
from orthosim.model import fdi as F

BODILY = ("translation", "extrusion", "intrusion")


@dataclass(frozen=True)
class EvidenceMatch:
    """A row a case falls under, and why (one short phrase)."""

    row_id: str
    topic: str
    why: str


def _kind(fdi: int) -> tuple:
    return F.arch_of(fdi), fdi % 10


def _retracting(load) -> bool:
    d = load.direction
    return d == "distal" or (not isinstance(d, str) and d[2] < 0)


def _loads_on(case, fdi_kind, test) -> list:
    return [(load, t) for load in case.loads for t in load.teeth if _kind(t) == fdi_kind and test(load)]


def _covers(case, row: EvidenceRow) -> str:
    """Why the row covers the case, or '' when it does not."""
    s = row.setup
    if row.kind in ("rate", "rate_ratio"):
        forces = (s["force_cN"],) if row.kind == "rate" else (s["force_cN"], s["reference_force_cN"])
        lo, hi = (0.75 * forces[0], 1.25 * forces[0]) if row.kind == "rate" else (min(forces), max(forces))
        hits = _loads_on(case, _kind(s["tooth"]), lambda ld: _retracting(ld) and lo <= ld.force_cN <= hi)
        return f"{hits[0][1]} retracted with {hits[0][0].force_cN:g} cN" if hits else ""
    if row.kind in ("anchorage_canine", "anchorage_en_masse"):
        front = (s["tooth"],) if row.kind == "anchorage_canine" else tuple(s["teeth"])
        if not all(_loads_on(case, _kind(t), _retracting) for t in front):
            return ""
        anchored = any(_loads_on(case, _kind(t), lambda ld: ld.direction == "mesial") for t in s["anchor_teeth"])
        reinforced = bool(s.get("reinforced", False))
        if anchored == reinforced:
            return ""
        return "retraction on " + ("mini-implants" if reinforced else "molar anchorage, the reaction on the posterior teeth")
    if row.kind in ("cr_share", "cr_below_bracket", "cr_lingual_of_bracket"):
        kinds = {_kind(t) for t in s["teeth"]}
        hits = [t for ld in case.loads for t in ld.teeth if _kind(t) in kinds and ld.movement in BODILY]
        return f"bodily load on {hits[0]}" if hits else ""
    return _covers_mf(case, row)


def _covers_mf(case, row: EvidenceRow) -> str:
    for ld in case.loads:
        if ld.force_cN > 0 and ld.moment_cNmm and ld.movement not in BODILY:
            mf = abs(ld.moment_cNmm) / ld.force_cN
            if row.low <= mf <= row.high:
                return f"M/F {mf:.1f} mm on {ld.teeth[0]}"
        if (row.kind == "mf_center" and row.setup["center"] == "infinity" and ld.movement in BODILY
                and case.wire.type == "rectangular" and ld.force_cN > 0):
            return "bodily load on a rectangular wire, which supplies the translation M/F"
    return ""


def evidence_for_case(case, rows: tuple[EvidenceRow, ...] | None = None) -> list[EvidenceMatch]:
    """The evidence rows (table order) whose force systems the case's loads fall under."""
    real = case.model.kind != "parametric"
    out = []
    for row in rows or load_evidence():
        if (row.model == "real") != real:
            continue
        why = _covers(case, row)
        if why:
            out.append(EvidenceMatch(row.id, row.topic, why))
    return out

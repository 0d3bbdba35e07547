"""The case file's `[ligament]` table (the periodontal ligament's material and the bone level per
tooth) and its `[[anchorage]]` tables (where the reactions of the active teeth's loads go).

[ligament]: modulus_mpa, poisson, thickness_mm, crest_below_cej_mm, each within its published range
(`orthosim.mechanics.ligament.RANGES`, sources in that module); bone_level_mm = { "16" = 4.0 }: the
alveolar crest's depth below the CEJ (mm) of a tooth that lost bone (deeper than the healthy crest).
Whether a level leaves the tooth any embedded root is known only with its mesh, so the movement
model checks it when it builds (`orthosim.movement.model`).

[[anchorage]]: kind = "teeth" (the anchor unit: `teeth`, tied by the wire, share the reaction of
the loads on the `active` teeth by their stiffness along it) or kind = "mini-implant" (a
temporary anchorage device takes the reaction: nothing is added to any tooth). A reaction goes to
the unit's teeth of the active tooth's own quadrant (its arch when the quadrant has none).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from orthosim.errors import CaseError
from orthosim.exchange.casefields import FieldReader
from orthosim.model import fdi as F

_LIGAMENT = ("modulus_mpa", "poisson", "thickness_mm", "crest_below_cej_mm", "bone_level_mm")
_ANCHORAGE = ("kind", "active", "teeth")
ANCHORAGE_KINDS = ("teeth", "mini-implant")
DEEPEST_BONE_LEVEL_MM = 25.0  # no root is longer (a canine's is about 17 mm, Wheeler)


@dataclass(frozen=True)
class CaseLigament:
    """The [ligament] table: the properties the case sets (None: the published default) and the bone
    level (mm below the CEJ) of each tooth that lost bone."""

    modulus_mpa: float | None = None
    poisson: float | None = None
    thickness_mm: float | None = None
    crest_below_cej_mm: float | None = None
    bone_level_mm: dict[int, float] = field(default_factory=dict)

    def properties(self):
        """The `LigamentProperties` of the table (published defaults where it is silent)."""
        from orthosim.mechanics.ligament import LigamentProperties

        given = {k: getattr(self, k) for k in _LIGAMENT[:4] if getattr(self, k) is not None}
        return LigamentProperties(**given)


@dataclass(frozen=True)
class Anchorage:
    """One [[anchorage]] table: the reactions of the loads on `active` go to `teeth` (kind "teeth",
    shared by stiffness) or to a mini-implant (kind "mini-implant", `teeth` empty)."""

    kind: str
    active: tuple[int, ...]
    teeth: tuple[int, ...] = ()


def read_ligament(path: Path, raw: Any, present: set[int]) -> CaseLigament:
    """The [ligament] table of a case (one-line CaseError naming the field and its published range)."""
    from orthosim.mechanics.ligament import RANGES

    r = FieldReader(path, "ligament", raw, _LIGAMENT)
    values = {}
    for key in _LIGAMENT[:4]:
        if key in r.table:
            low, high = RANGES[key]
            values[key] = r.number(key, minimum=low, maximum=high, why="the published range (orthosim.mechanics.ligament)")
    levels = r.get("bone_level_mm", {})
    if not isinstance(levels, dict):
        r.fail("bone_level_mm", f"must be a table of FDI number = mm, got {levels!r}", 'write e.g. { "16" = 4.0 }')
    bone = {}
    for key, value in levels.items():
        fdi = int(key) if str(key).isdigit() else key
        r.tooth(f"bone_level_mm.{key}", fdi, present)
        sub = FieldReader(path, "ligament.bone_level_mm", {str(key): value}, (str(key),))
        bone[fdi] = sub.number(str(key), positive=True, maximum=DEEPEST_BONE_LEVEL_MM, unit="mm",
                               why="the crest's depth below the CEJ; no root is longer")
    try:
        lig = CaseLigament(**values, bone_level_mm=bone)
        lig.properties()
    except CaseError as err:  # the properties' own check, with the file named
        raise CaseError(path, err.field, err.problem, err.fix) from None
    return lig


def read_anchorage(path: Path, raw: Any, present: set[int], extracted: set[int]) -> tuple[Anchorage, ...]:
    """The case's [[anchorage]] tables (one-line CaseError naming the field)."""
    if not isinstance(raw, list):
        FieldReader(path, "", {}, ()).fail("anchorage", "must be an array of tables", "write each as [[anchorage]]")
    out = []
    taken: set[int] = set()
    for i, table in enumerate(raw):
        r = FieldReader(path, f"anchorage[{i}]", table, _ANCHORAGE)
        kind = r.string("kind", None, ANCHORAGE_KINDS)
        active = _teeth(r, "active", present - extracted)
        if taken & set(active):
            r.fail("active", f"tooth {sorted(taken & set(active))[0]} already has an anchorage", "name each active tooth once")
        taken |= set(active)
        teeth: tuple[int, ...] = ()
        if kind == "teeth":
            teeth = _teeth(r, "teeth", present - extracted)
            if set(teeth) & set(active):
                r.fail("teeth", "an anchor tooth is also active", "list the anchor unit apart from the teeth it anchors")
        elif "teeth" in r.table:
            r.fail("teeth", "a mini-implant takes the reaction itself", 'remove teeth, or use kind = "teeth"')
        out.append(Anchorage(kind, active, teeth))
    return tuple(out)


def _teeth(r: FieldReader, key: str, present: set[int]) -> tuple[int, ...]:
    raw = r.get(key)
    if not isinstance(raw, list) or not raw:
        r.fail(key, f"must be a non-empty list of FDI numbers, got {raw!r}", "write e.g. [15, 16, 17]")
    teeth = tuple(r.tooth(f"{key}[{j}]", t, present) for j, t in enumerate(raw))
    if len(set(teeth)) != len(teeth):
        r.fail(key, "lists a tooth twice", "list each tooth once")
    return teeth


def same_side(active: int, unit: tuple[int, ...]) -> tuple[int, ...]:
    """The teeth of `unit` in the quadrant of `active`, else those of its arch, else all of them."""
    side = tuple(t for t in unit if F.quadrant(t) == F.quadrant(active))
    if side:
        return side
    arch = tuple(t for t in unit if F.arch_of(t) == F.arch_of(active))
    return arch or unit

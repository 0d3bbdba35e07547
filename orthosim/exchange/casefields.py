"""Typed reading of one TOML table of a case file: every problem names the file, the dotted field and the fix.

Shared by the case file's sections (`orthosim.exchange.case`) and the staging set-up's
(`orthosim.exchange.target`), so every field of a case reads and fails the same way.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from orthosim.errors import CaseError
from orthosim.model import fdi as F


class FieldReader:
    """Typed access to one TOML table, naming the file and the dotted field in every error.

    problems: where the table's unknown keys go, each its own CaseError, so that a linter lists
    them all (`orthosim.exchange.case.case_problems`); None: the first unknown key raises."""

    def __init__(self, path: Path, prefix: str, table: Any, allowed: tuple[str, ...],
                 problems: list[CaseError] | None = None):
        self.path, self.prefix = path, prefix
        if not isinstance(table, dict):
            self.fail(None, f"must be a table, got {type(table).__name__}", f"write it as [{prefix}]")
        self.table = table
        for key in table:
            if key not in allowed:
                error = CaseError(self.path, self.name(key), "unknown key", f"expected one of: {', '.join(allowed)}")
                if problems is None:
                    raise error
                problems.append(error)

    def name(self, key: str | None) -> str:
        return self.prefix if key is None else (f"{self.prefix}.{key}" if self.prefix else key)

    def fail(self, key: str | None, problem: str, fix: str) -> None:
        raise CaseError(self.path, self.name(key), problem, fix)

    def get(self, key: str, default: Any = None) -> Any:
        return self.table.get(key, default)

    def string(self, key: str, default: str | None = None, choices: tuple[str, ...] | None = None) -> str:
        value = self.table.get(key, default)
        if value is None:
            self.fail(key, "missing", "add it" + (f" (one of: {', '.join(choices)})" if choices else ""))
        if not isinstance(value, str):
            self.fail(key, f"must be text, got {value!r}", "quote it")
        if choices and value not in choices:
            self.fail(key, f"unknown value {value!r}", f"use one of: {', '.join(choices)}")
        return value

    def number(self, key: str, default: float | None = None, positive: bool = False, minimum: float | None = 0.0,
               maximum: float | None = None, unit: str = "", why: str = "") -> float:
        """A finite number within [minimum, maximum] (above 0 when `positive`); `unit` and `why` (the
        reason for the range) go into the one-line error of a value outside it."""
        value = self.table.get(key, default)
        if value is None:
            self.fail(key, "missing", "add a number")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(key, f"must be a number, got {value!r}", "write a plain number")
        value = float(value)
        if not math.isfinite(value):
            self.fail(key, f"must be finite, got {value}", "write a finite number (no nan or inf)")
        allowed = _range_text(0.0 if positive and minimum is None else minimum, maximum, unit, positive)
        reason = f"; {why}" if why else ""
        if positive and value <= 0:
            self.fail(key, f"must be positive, got {value:g}", f"use a value above 0{allowed and ': ' + allowed}{reason}")
        if minimum is not None and value < minimum:
            self.fail(key, f"must be at least {minimum:g}, got {value:g}",
                      (f"use {allowed}" if maximum is not None else f"use a value of {minimum:g} or more") + reason)
        if maximum is not None and value > maximum:
            self.fail(key, f"must be at most {maximum:g}{unit and ' ' + unit}, got {value:g}", f"use {allowed}{reason}")
        return value

    def boolean(self, key: str, default: bool) -> bool:
        value = self.table.get(key, default)
        if not isinstance(value, bool):
            self.fail(key, f"must be true or false, got {value!r}", "write true or false")
        return value

    def vector(self, key: str, value: Any) -> tuple[float, float, float]:
        if not (isinstance(value, list) and len(value) == 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
            self.fail(key, f"must be a list of three numbers, got {value!r}", "write [x, y, z]")
        v = tuple(float(x) for x in value)
        if not all(math.isfinite(x) for x in v):
            self.fail(key, f"must be finite, got {list(v)}", "write finite numbers (no nan or inf)")
        return v

    def tooth(self, key: str, value: Any, present: set[int]) -> int:
        if not F.is_fdi(value):
            self.fail(key, f"unknown tooth {value!r}", "use an FDI number: 11-18, 21-28, 31-38 or 41-48")
        if value not in present:
            self.fail(key, f"tooth {value} ({F.name(value)}) is not in the model",
                      f"use one of the model's teeth ({teeth_list(present)}) or add it to the model")
        return value


def _range_text(minimum: float | None, maximum: float | None, unit: str, open_low: bool) -> str:
    """'a value from 0 to 10 mm', 'a value above 0 and at most 365 days', '' without a maximum."""
    if maximum is None:
        return ""
    unit = f" {unit}" if unit else ""
    if minimum is None:
        return f"a value of at most {maximum:g}{unit}"
    if open_low:
        return f"a value above {minimum:g} and at most {maximum:g}{unit}"
    return f"a value from {minimum:g} to {maximum:g}{unit}"


def teeth_list(teeth: set[int]) -> str:
    return ", ".join(str(t) for t in sorted(teeth))
